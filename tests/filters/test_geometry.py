"""The one-pass kernels behind the per-shape checks give the numbers the plain numpy did, bit for
bit: each is compared with the straightforward numpy expression it replaced, on random rows and
on small meshes (open, closed, with a non-manifold edge and a degenerate face)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from surfgen.filters import geometry, shape
from surfgen.filters.descriptor import _cell_sums, _centres, _cross_products, _pair_distances
from surfgen.filters.descriptor import descriptor as fast_descriptor
from surfgen.filters.metrics import _edge_counts
from surfgen.filters.verdict import _total_abs_curvature
from surfgen.generator.elementary.trig import acos_array
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import Mesh, extract_mesh


def mesh_of(formula: str, half: float = 1.6, n: int = 24, cap: bool = True) -> Mesh:
    field = evaluate(parse(formula), Grid(Box.cube(half), (n,) * 3), evaluator="reference")
    return extract_mesh(field, cap=cap)


@pytest.fixture(scope="module")
def meshes() -> list[Mesh]:
    lumpy = mesh_of("x^2+y^2+z^2-1+0.4*sin(3*x)*cos(2*y)")
    gyroid = mesh_of("sin(3*x)*cos(3*y)+sin(3*y)*cos(3*z)+sin(3*z)*cos(3*x)", cap=False)
    # two triangles glued on three faces along one edge (non-manifold) plus a repeated vertex
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [2, 0, 0.5]], float)
    f = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [2, 1, 5], [3, 3, 4]])
    return [lumpy, gyroid, Mesh(v, f)]


@pytest.fixture(scope="module")
def rows() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(5)
    a = rng.standard_normal((21000, 3)) * np.exp(rng.uniform(-6, 6, (21000, 3)))
    b = rng.standard_normal((21000, 3))
    return a, b


def test_the_kernels_sum_in_numpys_order(rows: tuple[np.ndarray, np.ndarray]) -> None:
    a, b = rows
    # np.einsum pairs the first and last products; left to right differs in ~25 % of rows
    dots = np.array([geometry._dot(*x, *y) for x, y in zip(a[:3000], b[:3000], strict=True)])
    assert np.array_equal(dots, np.einsum("ij,ij->i", a[:3000], b[:3000]))
    v = np.concatenate([a, b])
    f = np.arange(len(v)).reshape(-1, 3)
    assert np.array_equal(
        geometry.first_edge_lengths(v, f), np.linalg.norm(v[f[:, 1]] - v[f[:, 0]], axis=1)
    )
    cross, norm = _cross_products(v, f)
    want = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    assert np.array_equal(cross, want) and np.array_equal(norm, np.linalg.norm(want, axis=1))
    i, j = np.arange(len(v) - 1), np.arange(1, len(v))
    assert np.array_equal(_pair_distances(v, i, j), np.linalg.norm(v[i] - v[j], axis=1))


def test_face_terms_match_numpy(meshes: list[Mesh]) -> None:
    for m in meshes:
        v, f = m.vertices, m.faces
        tri = v[f]
        areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        assert np.array_equal(
            geometry.weighted_centres(v, f, areas), areas[:, None] * tri.mean(axis=1)
        )
        o = 0.5 * (v.min(axis=0) + v.max(axis=0))
        a, b, c = tri[:, 0] - o, tri[:, 1] - o, tri[:, 2] - o
        assert np.array_equal(
            geometry.volume_terms(v, f, o), np.einsum("ij,ij->i", a, np.cross(b, c))
        )
        centroid, radius = np.array([0.1, -0.2, 0.3]), 0.7
        assert np.array_equal(
            _centres(v, f, centroid, radius), (tri.mean(axis=1) - centroid) / radius
        )
        assert np.array_equal(
            geometry.used_mask(f, len(v)), np.isin(np.arange(len(v)), np.unique(f))
        )


def _edges_numpy(faces: np.ndarray, n: int) -> tuple[int, int, int, bool]:
    """The sort-based count the kernel replaced."""
    start = faces.reshape(-1)
    end = faces[:, [1, 2, 0]].reshape(-1)
    key = np.minimum(start, end) * np.int64(n) + np.maximum(start, end)
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    forward = np.bincount(inverse.reshape(-1), weights=start < end, minlength=len(counts))
    return (
        len(counts),
        int(np.count_nonzero(counts == 1)),
        int(np.count_nonzero(counts > 2)),
        bool(np.all(forward[counts == 2] == 1)),
    )


def test_edge_counts_match_the_sort(meshes: list[Mesh]) -> None:
    for m in meshes:
        e = _edge_counts(m.faces, m.n_vertices)
        assert (e.count, e.boundary, e.nonmanifold, e.oriented) == _edges_numpy(
            m.faces, m.n_vertices
        )
    # only the small mesh repeats a vertex in a face ([3, 3, 4])
    assert [_edge_counts(m.faces, m.n_vertices).degenerate for m in meshes] == [False, False, True]
    faces = meshes[0].faces.copy()
    faces[0] = faces[0, ::-1]
    flipped = Mesh(meshes[0].vertices, faces)
    assert _edge_counts(flipped.faces, flipped.n_vertices).oriented is False
    assert _edges_numpy(flipped.faces, flipped.n_vertices)[3] is False


def test_curvature_matches_numpy(meshes: list[Mesh]) -> None:
    for m in meshes:
        v, f = m.vertices, m.faces
        edges = [v[f[:, (k + 1) % 3]] - v[f[:, k]] for k in range(3)]
        lengths = [np.linalg.norm(e, axis=1) for e in edges]
        cos = np.empty(f.shape)
        for k in range(3):
            j = (k + 2) % 3
            cos[:, k] = -np.einsum("ij,ij->i", edges[k], edges[j]) / (
                lengths[k] * lengths[j] + 1e-300
            )
        cos = np.clip(cos, -1.0, 1.0)
        # Bit for bit with surfgen's acos (the same on every CPU) ...
        assert _total_abs_curvature(v, f) == _curvature_of(acos_array(cos), f, len(v))
        # ... and within rounding of numpy's arccos (SIMD code of its own on AVX-512 CPUs).
        plain = _curvature_of(np.arccos(cos), f, len(v))
        assert _total_abs_curvature(v, f) == pytest.approx(plain, rel=1e-12)


def _curvature_of(angles: np.ndarray, f: np.ndarray, n_vertices: int) -> float:
    angle_sum = np.bincount(f.ravel(), weights=angles.ravel(), minlength=n_vertices)
    used = np.bincount(f.ravel(), minlength=n_vertices) > 0
    return float(np.abs(2 * math.pi - angle_sum[used]).sum())


def test_relief_cells_match_unique_and_bincount() -> None:
    rng = np.random.default_rng(3)
    cells = rng.integers(0, 6, size=(500, 3))
    dims = cells.max(axis=0) + 1
    normals, areas = rng.standard_normal((500, 3)), rng.uniform(0, 1, 500)
    total, summed = _cell_sums(cells, dims, normals, areas)
    _, cell = np.unique(np.ravel_multi_index(cells.T, tuple(dims)), return_inverse=True)
    assert np.array_equal(total, np.bincount(cell, weights=areas))
    want = np.stack([np.bincount(cell, weights=normals[:, k]) for k in range(3)], axis=1)
    assert np.array_equal(summed, want)


def _symmetries_kdtree(mesh: Mesh) -> list[str]:
    """The k-d tree version the cell grid replaced (scipy's strict ``< limit`` test)."""
    pts, centroid = shape._surface_points(mesh, shape.SYMMETRY_POINTS)
    used = np.unique(mesh.faces)
    tree = cKDTree(mesh.vertices[used] - centroid)
    v, f = mesh.vertices, mesh.faces
    limit = shape.SYMMETRY_TOLERANCE * float(np.linalg.norm(v[f[:, 1]] - v[f[:, 0]], axis=1).mean())
    pts = pts - centroid
    allowed = int((1.0 - shape.SYMMETRY_SHARE) * len(pts))
    found = []
    for perm, signs in shape.SIGNED_PERMUTATIONS:
        dist, _ = tree.query(pts[:, perm] * np.array(signs, float), distance_upper_bound=limit)
        if np.count_nonzero(~np.isfinite(dist)) <= allowed:
            found.append(shape.element_label(perm, signs))
    return found


def test_symmetry_cell_grid_agrees_with_the_kdtree(meshes: list[Mesh]) -> None:
    cyclic = mesh_of("x^2+y^2+z^2-1+0.6*(x*y^2+y*z^2+z*x^2)")
    for m in [*meshes[:2], cyclic]:
        assert shape.mesh_symmetries(m) == _symmetries_kdtree(m)
    # per point, near or not, against the tree (a tolerance putting many points at the edge)
    m = meshes[0]
    cloud = np.ascontiguousarray(m.vertices[np.unique(m.faces)])
    rng = np.random.default_rng(9)
    queries = cloud[rng.integers(0, len(cloud), 400)] + rng.normal(0, 0.05, (400, 3))
    for limit in (0.02, 0.06, 0.3):
        start, order, lo, cell, dims = shape._cell_index(cloud, limit)
        near = [
            shape._near(*q, cloud, start, order, lo, cell, dims, limit * limit) for q in queries
        ]
        dist, _ = cKDTree(cloud).query(queries, distance_upper_bound=limit)
        assert near == list(np.isfinite(dist))


def _descriptor_numpy(m: Mesh) -> np.ndarray:
    """The descriptor as plain numpy computed it (whole triangles, np.unique cells)."""
    from surfgen.filters import descriptor as d

    tri = m.vertices[m.faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    doubled = np.linalg.norm(cross, axis=1)
    areas = 0.5 * doubled
    total = float(areas.sum())
    rng = np.random.default_rng(d.SEED)
    points = geometry.surface_samples(m.vertices, m.faces, areas, total, rng, d.POINTS)[0]
    centroid = (areas[:, None] * tri.mean(axis=1)).sum(axis=0) / total
    i, j = rng.integers(0, d.POINTS, size=(2, d.PAIRS))
    d1 = np.linalg.norm(points - centroid, axis=1)
    normals = cross / np.maximum(doubled, np.finfo(np.float64).tiny)[:, None]
    parts = [
        d._histogram(np.linalg.norm(points[i] - points[j], axis=1), d.D2_BINS),
        d._histogram(d1, d.D1_BINS),
    ]
    for k in range(3):
        counts, _ = np.histogram(
            np.abs(normals[:, k]), bins=d.NORMAL_BINS, range=(0.0, 1.0), weights=areas
        )
        parts.append(counts / total)
    radius = float(np.sqrt(np.mean(d1**2)))
    dist, _ = cKDTree((points - centroid) / radius).query(d._placement_nodes())
    parts.append(d._quantise(np.minimum(dist, d.PLACE_CLIP)))
    cells = np.floor((tri.mean(axis=1) - centroid) / radius / d.RELIEF_CELL).astype(np.int64)
    cells -= cells.min(axis=0)
    flat = np.ravel_multi_index(cells.T, tuple(int(x) for x in cells.max(axis=0) + 1))
    _, cell = np.unique(flat, return_inverse=True)
    tot = np.bincount(cell, weights=areas)
    summed = np.stack([np.bincount(cell, weights=0.5 * cross[:, k]) for k in range(3)], axis=1)
    spread = 1.0 - np.linalg.norm(summed, axis=1) / tot
    counts, _ = np.histogram(
        np.sqrt(np.clip(spread, 0.0, 1.0)), bins=d.RELIEF_BINS, range=(0, 1), weights=tot
    )
    parts.append(counts / counts.sum())
    return np.concatenate(parts)


def test_descriptor_matches_the_numpy_version(meshes: list[Mesh]) -> None:
    for m in meshes[:2]:
        assert np.array_equal(fast_descriptor(m), _descriptor_numpy(m))


def test_column_bounds_and_lattice_cells_match_numpy(meshes: list[Mesh]) -> None:
    from surfgen.filters.descriptor import _lattice_cells

    v = meshes[0].vertices
    mask = np.arange(len(v)) % 3 != 0
    lo, hi = geometry.column_bounds(v, mask)
    assert np.array_equal(lo, v[mask].min(axis=0)) and np.array_equal(hi, v[mask].max(axis=0))
    bad = v.copy()
    bad[5, 1] = np.nan
    lo, hi = geometry.column_bounds(bad, np.ones(len(v), dtype=bool))
    assert np.array_equal(lo, bad.min(axis=0), equal_nan=True)
    assert np.array_equal(hi, bad.max(axis=0), equal_nan=True)
    centres = np.random.default_rng(4).normal(0, 1, (3000, 3))
    cells, dims = _lattice_cells(centres, 0.2)
    want = np.floor(centres / 0.2).astype(np.int64)
    want -= want.min(axis=0)
    assert np.array_equal(cells, want) and np.array_equal(dims, want.max(axis=0) + 1)


def test_faces_picked_by_area_are_numpy_s_searchsorted_clamped() -> None:
    rng = np.random.default_rng(8)
    areas = rng.random(5000)
    areas[[10, 11, 12]] = 0.0  # empty faces: a run of equal cumulative areas
    cumulative = np.cumsum(areas)
    keys = rng.random(3000) * areas.sum()
    # keys on the cumulative areas themselves, repeated, past the end, NaN
    keys[:20] = cumulative[[0, 9, 10, 11, 12, 13, 4999] * 2 + [0] * 6]
    keys[20:23] = [cumulative[-1] * 1.5, np.inf, np.nan]
    want = np.minimum(np.searchsorted(cumulative, keys, side="right"), len(areas) - 1)
    got = geometry.pick_faces(cumulative, keys)
    assert got.dtype == want.dtype and np.array_equal(got, want)
    assert geometry.pick_faces(cumulative, keys[:0]).shape == (0,)


def test_surface_samples_lie_on_their_faces_picked_by_area() -> None:
    mesh = extract_mesh(evaluate(parse("x^2 + y^2/2 + z^2/3 - 1"), Grid(Box.cube(2.0), (14,) * 3)))
    v, f = mesh.vertices, mesh.faces
    tri = v[f]
    doubled = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    points, faces = geometry.surface_samples(
        v, f, doubled, doubled.sum(), np.random.default_rng(3), 5000
    )
    # the faces: the first draw, picked by area; any multiple of the areas picks the same
    keys = np.random.default_rng(3).random(5000) * doubled.sum()
    assert np.array_equal(faces, geometry.pick_faces(np.cumsum(doubled), keys))
    half = geometry.surface_samples(
        v, f, doubled / 2, doubled.sum() / 2, np.random.default_rng(3), 5000
    )
    assert np.array_equal(half[0], points) and np.array_equal(half[1], faces)
    # each point inside its face: barycentric coordinates in [0, 1] summing to 1
    a, b, c = tri[faces, 0], tri[faces, 1], tri[faces, 2]
    e1, e2, d = b - a, c - a, points - a
    d11, d12, d22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    p1, p2 = (d * e1).sum(1), (d * e2).sum(1)
    det = d11 * d22 - d12 * d12
    u, w = (d22 * p1 - d12 * p2) / det, (d11 * p2 - d12 * p1) / det
    assert np.all(u >= -1e-9) and np.all(w >= -1e-9) and np.all(u + w <= 1 + 1e-9)
    np.testing.assert_allclose(a + u[:, None] * e1 + w[:, None] * e2, points, atol=1e-12)
    # uniform by area: each face's share of the points near its share of the area
    big = doubled > np.quantile(doubled, 0.5)
    assert abs(big[faces].mean() - doubled[big].sum() / doubled.sum()) < 0.03
