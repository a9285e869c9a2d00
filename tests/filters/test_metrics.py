"""measure_mesh: Euler characteristic, genus, watertightness, manifoldness, area and volume."""

from __future__ import annotations

import json

import numpy as np
import pytest

from surfgen.filters import meshlab
from surfgen.filters.metrics import Metrics, _edge_counts, measure_mesh
from surfgen.generator.errors import MeshError
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import Mesh, extract_mesh
from tests.support.commands import CHECK_KEYS

KEYS = CHECK_KEYS

# A unit right tetrahedron, outward winding.
TET_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
TET_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def tetrahedron() -> Mesh:
    return Mesh(TET_V, TET_F)


def bowtie() -> Mesh:
    """Two tetrahedra sharing vertex 0 only: a non-manifold vertex."""
    v = np.vstack([TET_V, -TET_V[1:]])
    f = np.vstack([TET_F, np.where(TET_F == 0, 0, TET_F + 3)[:, ::-1]])
    return Mesh(v, f)


@pytest.mark.parametrize("name", ["sphere", "torus", "genus2", "two_spheres"])
def test_canonical_shapes(name, shapes, shape_mesh):
    shape = shapes[name]
    m = measure_mesh(shape_mesh(name))
    assert m.genus == shape.genus
    assert m.components == shape.components
    assert m.euler == 2 * shape.components - 2 * shape.genus
    assert m.watertight and m.closed
    assert (m.boundary_edges, m.nonmanifold_edges, m.nonmanifold_vertices) == (0, 0, 0)
    assert m.volume > 0
    if shape.volume is not None:
        assert m.volume == pytest.approx(shape.volume, rel=0.03)
        assert m.area == pytest.approx(shape.area, rel=0.03)


def test_tetrahedron_exact():
    m = measure_mesh(tetrahedron())
    assert (m.vertices, m.faces, m.components, m.euler, m.genus) == (4, 4, 1, 2, 0)
    assert m.volume == pytest.approx(1 / 6)
    assert m.area == pytest.approx(1.5 + np.sqrt(3) / 2)
    assert m.bbox == (0.0, 1.0, 0.0, 1.0, 0.0, 1.0)


def test_capped_cut_sphere_is_closed():
    field = evaluate_reference(parse("x^2+y^2+z^2-1"), Grid(Box.cube(0.8), (24, 24, 24)))
    capped = measure_mesh(extract_mesh(field, cap=True))
    assert capped.watertight and capped.genus == 0 and capped.volume > 0
    assert capped.bbox == (-0.8, 0.8, -0.8, 0.8, -0.8, 0.8)
    cut = measure_mesh(extract_mesh(field))
    assert not cut.watertight and cut.boundary_edges > 0
    assert cut.genus is None and cut.volume is None
    assert cut.euler == 2 - 6  # a sphere with six holes


def test_inverted_mesh_has_negative_volume(sphere_mesh):
    m = measure_mesh(Mesh(sphere_mesh.vertices, sphere_mesh.faces[:, ::-1]))
    assert m.genus == 0 and m.volume < 0


def test_inconsistent_winding_is_not_closed(sphere_mesh):
    faces = np.array(sphere_mesh.faces)
    faces[:10] = faces[:10, ::-1]
    m = measure_mesh(Mesh(sphere_mesh.vertices, faces))
    assert m.watertight and m.genus is None and m.volume is None


def test_nonmanifold_vertex():
    m = measure_mesh(bowtie())
    assert m.watertight and m.nonmanifold_vertices == 1 and m.nonmanifold_edges == 0
    assert m.genus is None


def test_nonmanifold_edge():
    v = np.vstack([TET_V, [[1, 1, 1]]])
    f = np.vstack([TET_F, [[1, 2, 4]]])  # a fin on edge 1-2: three faces there
    m = measure_mesh(Mesh(v, f))
    assert m.nonmanifold_edges == 1 and m.boundary_edges == 2
    assert not m.watertight and m.genus is None


def test_unreferenced_vertices_do_not_change_euler():
    m = measure_mesh(Mesh(np.vstack([TET_V, [[9, 9, 9]]]), TET_F))
    assert m.vertices == 5 and m.euler == 2 and m.genus == 0
    assert m.bbox == (0.0, 1.0, 0.0, 1.0, 0.0, 1.0)


def test_to_dict_is_plain_json(torus_mesh):
    m = measure_mesh(torus_mesh)
    d = m.to_dict()
    assert list(d) == KEYS
    assert json.loads(json.dumps(d)) == d
    plain = (int, float, bool, list, type(None))
    assert all(type(v) in plain for v in d.values())
    assert all(type(v) is float for v in d["bbox"]) and len(d["bbox"]) == 6
    assert isinstance(m, Metrics)


def test_empty_mesh_raises():
    with pytest.raises(MeshError, match="empty"):
        measure_mesh(Mesh(np.zeros((0, 3)), np.zeros((0, 3))))


# --- components and non-manifold vertices: the edge pass against pymeshlab ---------------------


def _moebius(n: int = 12) -> Mesh:
    """A Möbius strip of 2n triangles: one piece, no consistent orientation."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    v = []
    for s in (-0.3, 0.3):
        v.append(
            np.c_[
                (1 + s * np.cos(t / 2)) * np.cos(t),
                (1 + s * np.cos(t / 2)) * np.sin(t),
                s * np.sin(t / 2),
            ]
        )
    v = np.vstack(v)
    f = []
    for i in range(n):
        j = (i + 1) % n
        a, b = i, i + n
        c, d = (j, j + n) if j else (j + n, j)  # the half twist swaps the rows once round
        f += [[a, c, b], [b, c, d]]
    return Mesh(v, np.array(f))


def _pymeshlab(mesh: Mesh) -> tuple[int, int]:
    topo = meshlab.topology(mesh)
    return int(topo["components"]), int(topo["nonmanifold_vertices"])


def _edge_pass(mesh: Mesh) -> tuple[int, int]:
    e = _edge_counts(mesh.faces, mesh.n_vertices)
    assert e.nonmanifold == 0 and not e.degenerate  # where the pass's numbers are pymeshlab's
    return e.components, e.pinched


def _holed(mesh: Mesh, seed: int, share: float) -> Mesh:
    """``mesh`` with a random ``share`` of its faces dropped: pinched vertices, pieces, flips."""
    rng = np.random.default_rng(seed)
    faces = mesh.faces[rng.random(mesh.n_faces) >= share].copy()
    flip = rng.random(len(faces)) < 0.1
    faces[flip] = faces[flip, ::-1]
    return Mesh(mesh.vertices, faces)


@pytest.mark.parametrize("name", ["sphere", "torus", "genus2", "two_spheres"])
def test_edge_pass_gives_pymeshlabs_numbers_on_shapes(name, shapes, shape_mesh):
    mesh = shape_mesh(name)
    assert _edge_pass(mesh) == _pymeshlab(mesh)
    for seed in range(4):  # holes and flipped faces: pinched vertices, many pieces
        holed = _holed(mesh, seed, 0.35)
        assert _edge_pass(holed) == _pymeshlab(holed)


def test_edge_pass_counts_fans_and_pieces():
    # two tetrahedra on one vertex: two pieces (joined through edges, as vcg joins faces) and
    # one vertex with two fans
    assert _edge_pass(bowtie()) == _pymeshlab(bowtie()) == (2, 1)
    assert _edge_pass(tetrahedron()) == (1, 0)
    strip = _moebius()
    assert _edge_pass(strip) == _pymeshlab(strip) == (1, 0)
    assert not _edge_counts(strip.faces, strip.n_vertices).oriented
    # two triangles touching at one vertex, each a fan with a border: the same
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
    touching = Mesh(v, np.array([[0, 1, 2], [0, 3, 4]]))
    assert _edge_pass(touching) == _pymeshlab(touching) == (2, 1)


def test_pymeshlab_answers_where_the_edge_pass_cannot():
    v = np.vstack([TET_V, [[1, 1, 1]]])
    fin = Mesh(v, np.vstack([TET_F, [[1, 2, 4]]]))  # three faces on edge 1-2
    repeated = Mesh(v, np.vstack([TET_F, [[4, 4, 1]]]))  # a face repeating a vertex
    for mesh in (fin, repeated):
        e = _edge_counts(mesh.faces, mesh.n_vertices)
        assert e.nonmanifold or e.degenerate
        m = measure_mesh(mesh)
        assert (m.components, m.nonmanifold_vertices) == _pymeshlab(mesh)


def test_measure_mesh_does_not_ask_pymeshlab_on_a_manifold_mesh(monkeypatch, sphere_mesh):
    def refuse(mesh):
        raise AssertionError("pymeshlab asked")

    monkeypatch.setattr(meshlab, "topology", refuse)
    m = measure_mesh(sphere_mesh)
    assert m.components == 1 and m.nonmanifold_vertices == 0 and m.genus == 0
    assert measure_mesh(bowtie()).nonmanifold_vertices == 1
