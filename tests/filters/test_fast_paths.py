"""The fast paths of the filters and pictures give bit for bit what the plain numpy ones gave.

Speed changes must not change a catalogue (keys, specs, metrics): each fast kernel is checked
against the straightforward version it replaced, on real marching-cubes meshes.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from surfgen.filters import verdict
from surfgen.filters.meshlab import face_components
from surfgen.generator.elementary.trig import acos_array
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import Mesh, extract_mesh, face_areas
from surfgen.pipelines.pictures import raster as pictures


@pytest.fixture(scope="module")
def meshes() -> list[tuple[Mesh, tuple[float, ...]]]:
    """Capped and open meshes, several components, box caps, and one with junk vertices."""
    out = []
    for formula, half, cap in (
        (
            "min(min((x-0.8)^2+y^2+z^2-0.25, (x+0.8)^2+y^2+z^2-0.25), (z-1)^2+y^2+x^2-0.1)",
            1.5,
            True,
        ),
        ("sin(3*x)*cos(3*y)+sin(3*y)*cos(3*z)+sin(3*z)*cos(3*x)", 1.3, True),
        ("x^2+y^2-z^2-0.2", 1.0, False),
    ):
        grid = Grid(Box.cube(half), (28, 28, 28))
        out.append((extract_mesh(evaluate_reference(parse(formula), grid), cap=cap), grid))
    m = out[0][0]
    rng = np.random.default_rng(1)
    junk = rng.normal(size=(7, 3))  # unreferenced vertices, and vertex order shuffled
    order = rng.permutation(m.n_vertices + 7)
    vertices = np.concatenate([m.vertices, junk])[order]
    inverse = np.argsort(order)
    out.append((Mesh(vertices, inverse[m.faces]), out[0][1]))
    return [(mesh, grid.box.bounds()) for mesh, grid in out]


def scipy_face_components(mesh: Mesh) -> np.ndarray:
    f, n = mesh.faces, mesh.n_vertices
    rows = np.concatenate([f[:, 0], f[:, 1]])
    cols = np.concatenate([f[:, 1], f[:, 2]])
    graph = coo_matrix((np.ones(len(rows), dtype=np.int8), (rows, cols)), shape=(n, n))
    _, vertex_label = connected_components(graph, directed=False)
    _, labels = np.unique(vertex_label[f[:, 0]], return_inverse=True)
    return labels.reshape(-1)


def numpy_on_box_faces(mesh: Mesh, box: tuple[float, ...]) -> np.ndarray:
    tri = mesh.vertices[mesh.faces]
    lo, hi = np.array(box[0::2]), np.array(box[1::2])
    tol = 1e-9 * float(np.max(hi - lo))
    on_face = np.zeros(mesh.n_faces, dtype=bool)
    for k in range(3):
        c = tri[:, :, k]
        on_face |= np.all(np.abs(c - lo[k]) <= tol, axis=1) | np.all(
            np.abs(c - hi[k]) <= tol, axis=1
        )
    return on_face


def numpy_curvature(v: np.ndarray, f: np.ndarray) -> float:
    angles = np.empty(f.shape)
    for k in range(3):
        a = v[f[:, (k + 1) % 3]] - v[f[:, k]]
        b = v[f[:, (k + 2) % 3]] - v[f[:, k]]
        cos = np.einsum("ij,ij->i", a, b) / (
            np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1) + 1e-300
        )
        angles[:, k] = acos_array(np.clip(cos, -1.0, 1.0))  # surfgen's: the same on every CPU
    angle_sum = np.bincount(f.ravel(), weights=angles.ravel(), minlength=len(v))
    used = np.bincount(f.ravel(), minlength=len(v)) > 0
    return float(np.abs(2 * math.pi - angle_sum[used]).sum())


def test_components_match_scipy_label_for_label(meshes) -> None:
    counts = []
    for mesh, _ in meshes:
        labels = face_components(mesh)
        assert np.array_equal(labels, scipy_face_components(mesh))
        counts.append(labels.max() + 1)
    assert counts[0] == 3 and counts[3] == 3  # three balls, junk vertices or not


def test_box_faces_areas_and_curvature_are_bit_identical(meshes) -> None:
    boxed = 0
    for mesh, box in meshes:
        lo, hi = np.array(box[0::2]), np.array(box[1::2])
        tol = 1e-9 * float(np.max(hi - lo))
        fast = verdict._on_box_faces(mesh.vertices, mesh.faces, lo, hi, tol)
        assert np.array_equal(fast, numpy_on_box_faces(mesh, box))
        boxed += int(fast.sum())
        tri = mesh.vertices[mesh.faces]
        c = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # numpy, whole columns
        numpy_areas = 0.5 * np.sqrt(c[:, 0] * c[:, 0] + c[:, 1] * c[:, 1] + c[:, 2] * c[:, 2])
        assert np.array_equal(face_areas(mesh), numpy_areas)
        assert verdict._total_abs_curvature(mesh.vertices, mesh.faces) == numpy_curvature(
            mesh.vertices, mesh.faces
        )
    assert boxed > 0  # the capped gyroid has caps: the test sees both answers


def test_shape_metrics_reuse_the_quick_ones(meshes) -> None:
    mesh, box = meshes[1]
    quick = verdict.quick_metrics(mesh, box)
    assert verdict.shape_metrics(mesh, box, quick=quick) == verdict.shape_metrics(mesh, box)


def test_edge_darkening_matches_numpy() -> None:
    rng = np.random.default_rng(3)
    n = 64
    covered = rng.random((n, n)) < 0.7
    inv_depth = np.where(covered, 1.0 / rng.uniform(3.0, 5.0, (n, n)), 0.0)
    inv_depth[20:40, 20:40] = 1.0 / 3.1  # a flat patch: no edge inside it
    colour = rng.random((n, n, 3))
    expected = colour.copy()
    depth = np.where(covered, 1.0 / np.where(covered, inv_depth, 1.0), 5.0)
    pad = np.pad(depth, 1, mode="edge")
    lap_x = np.abs(pad[1:-1, :-2] + pad[1:-1, 2:] - 2.0 * depth)
    lap_y = np.abs(pad[:-2, 1:-1] + pad[2:, 1:-1] - 2.0 * depth)
    edge = covered & (np.maximum(lap_x, lap_y) > 0.04)
    expected[edge] *= 0.45
    pictures._darken_edges(colour, inv_depth, covered)
    assert np.array_equal(colour, expected)
    assert 0 < edge.sum() < covered.sum()
