"""The resolution check: resolved surfaces stay put on the nested grid twice as fine, aliased
ones move; the band evaluation agrees with the dense reference where it evaluates."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.ndimage import binary_dilation

from surfgen.filters import fine_band as fb
from surfgen.filters import resolution as res
from surfgen.filters.geometry import bucket_points
from surfgen.filters.resolution import (
    Resolution,
    compare_meshes,
    fine_field,
    fine_grid,
    measure_resolution,
)
from surfgen.filters.verdict import FilterConfig, judge, unresolved
from surfgen.generator.errors import SpecError
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import extract_mesh

CFG = FilterConfig()
GYROID = "sin(x)*cos(y)+sin(y)*cos(z)+sin(z)*cos(x)"
# A ball with stripes 0.063 wide on a grid of 0.097 cells: aliased.
STRIPES = "x^2+y^2+z^2-1+0.8*sin(50*x)"
# A ball with a saw-tooth relief whose teeth (jumps of 0.3) are 0.1 apart, about a cell.
SAW = "x^2+y^2+z^2-1+0.3*(10*x-floor(10*x))"


def _measure(formula: str, half: float, n: int, method: str = "band") -> Resolution:
    tree = parse(formula)
    coarse = evaluate(tree, Grid(Box.cube(half), (n,) * 3), threads=1)
    mesh = extract_mesh(coarse, 0.0, cap=True)
    return measure_resolution(tree, coarse, mesh, 0.0, cap=True, method=method)


def _is_unresolved(r: Resolution) -> bool:
    return unresolved(r.to_metrics(), CFG)


@pytest.mark.parametrize(
    ("formula", "half", "n"),
    [
        ("x^2+y^2+z^2-1", 1.5, 32),
        ("(sqrt(x^2+y^2)-1)^2+z^2-0.16", 1.6, 40),
        (GYROID, 2 * math.pi, 40),
    ],
    ids=["sphere", "torus", "gyroid"],
)
def test_resolved_shapes_pass(formula: str, half: float, n: int) -> None:
    r = _measure(formula, half, n)
    assert r.shift < 0.6 and 0.97 < r.area < 1.06, r
    assert not _is_unresolved(r)


@pytest.mark.parametrize("formula", [STRIPES, SAW], ids=["stripes", "saw"])
def test_aliased_shapes_are_unresolved(formula: str) -> None:
    r = _measure(formula, 1.5, 32)
    assert _is_unresolved(r), r
    reasons = judge(
        {
            "faces": 1000,
            "components": 1,
            "largest_component_fraction": 1.0,
            "box_fraction": 0.0,
            **r.to_metrics(),
        },
        CFG,
        capped=True,
    ).reasons
    assert reasons == ("unresolved",)


def test_the_fine_grid_nests_the_coarse_one() -> None:
    coarse = Grid(Box((-1.3, -0.7, 0.1), (2.9, 0.35, 3.3)), (17, 23, 30))
    fine = fine_grid(coarse)
    assert fine.shape == (33, 45, 59)
    for a, b in zip(coarse.axes(), fine.axes(), strict=True):
        assert np.array_equal(a, b[::2])  # bit for bit


@pytest.mark.parametrize("formula", ["(sqrt(x^2+y^2)-1)^2+z^2-0.16", STRIPES])
def test_the_band_evaluates_what_the_dense_reference_does(formula: str) -> None:
    tree = parse(formula)
    coarse = evaluate(tree, Grid(Box.cube(1.6), (24,) * 3), threads=1)
    dense, n_dense, _ = fine_field(tree, coarse, 0.0, method="dense")
    band, n_band, _ = fine_field(tree, coarse, 0.0, method="band", band=1, via_grid=False)
    assert n_dense == 47**3 and 0 < n_band < n_dense
    # the band evaluated through the whole grid: the same field, bit for bit
    via_grid, n_via, _ = fine_field(tree, coarse, 0.0, method="band", band=1, via_grid=True)
    assert n_via == n_band and np.array_equal(via_grid.values, band.values, equal_nan=True)
    # Same bits on every point of a crossed cell (and its neighbours)...
    crossed = fb._crossed_cells(coarse.values, 0.0)
    i, j, k = np.nonzero(crossed)
    for di in range(3):
        for dj in range(3):
            for dk in range(3):
                at = (2 * i + di, 2 * j + dj, 2 * k + dk)
                assert np.array_equal(band.values[at], dense.values[at])
    # ...and every other fine point on the side of the dense field (a smooth field: no
    # surface hides between coarse samples outside the band).
    assert np.array_equal(band.values < 0, dense.values < 0) or formula == STRIPES


def test_band_and_dense_agree_on_a_resolved_shape() -> None:
    band = _measure("(sqrt(x^2+y^2)-1)^2+z^2-0.16", 1.6, 32, "band")
    dense = _measure("(sqrt(x^2+y^2)-1)^2+z^2-0.16", 1.6, 32, "dense")
    assert (band.to_fine, band.to_coarse, band.area) == (dense.to_fine, dense.to_coarse, dense.area)
    assert band.fine_points < dense.fine_points


def test_out_of_band_points_keep_the_side_of_their_cell() -> None:
    # One sample inside, far from the level: only the cells around it are crossed; the fine
    # points of the other cells keep the coarse side even where their mean would not.
    values = np.full((6, 6, 6), 5.0)
    values[2, 2, 2] = -1.0
    values[5, 5, 5] = np.nan  # non-finite: outside
    fine = np.empty((11, 11, 11))
    cells = fb._crossed_cells(values, 0.0)
    assert cells.sum() == 8
    todo, n = fb.band_points(cells, fine.shape)
    res._upsample(values, todo, 0.0, fine, np.empty((0, 0, 0)))
    assert todo.sum() == n == 5**3 - 3**3  # the crossed cells' fine points, less the coarse samples
    assert fine[4, 4, 4] == -1.0 and fine[10, 10, 10] != fine[10, 10, 10]
    outside = ~todo
    outside[::2, ::2, ::2] = False
    assert np.all(~(fine[outside] < 0))


def test_surface_distances_are_exact_point_to_triangle_distances() -> None:
    grid = Grid(Box.cube(1.5), (12,) * 3)
    mesh = extract_mesh(evaluate(parse("x^2+y^2+z^2-1"), grid, threads=1), 0.0, cap=True)
    rng = np.random.default_rng(3)
    points = rng.uniform(-1.5, 1.5, (400, 3))  # near, inside and far from the surface
    cell = grid.spacing[0]
    dims = np.array([11, 11, 11], dtype=np.int64)
    got = res.surface_distances(points, mesh, np.array(grid.box.lo), cell, dims, 100.0, 0.0)
    want = _brute_distances(points, mesh.vertices[mesh.faces])
    np.testing.assert_allclose(got * cell, want, rtol=0, atol=1e-12)
    # with a floor: exact above it, and at most the floor below it
    floored = res.surface_distances(points, mesh, np.array(grid.box.lo), cell, dims, 100.0, 0.3)
    above = got >= 0.3
    np.testing.assert_allclose(floored[above], got[above], rtol=0, atol=1e-12)
    assert np.all((floored[~above] >= got[~above]) & (floored[~above] <= 0.3))


def test_triangles_are_bucketed_as_their_centroids_are() -> None:
    """The bucketing of the distances' triangles is geometry's counting sort of the centroids,
    order included: below the floor the search stops at the first near triangle, so the order
    is part of the measure (and of the catalogue's figures)."""
    grid = Grid(Box.cube(1.5), (12,) * 3)
    mesh = extract_mesh(evaluate(parse(GYROID), grid, threads=1), 0.0, cap=True)
    v, f = mesh.vertices, mesh.faces
    lo, cell, dims = np.array(grid.box.lo), grid.spacing[0] * 1.5, np.array([7, 8, 9])
    start, order, centres, radii = res._bucket_triangles(v, f, lo, cell, dims)
    tri = v[f]
    mean = (tri[:, 0] + tri[:, 1] + tri[:, 2]) / 3.0
    want_start, want_order = bucket_points(mean, lo, cell, dims)
    assert np.array_equal(start, want_start) and np.array_equal(order, want_order)
    assert np.array_equal(centres, mean[order])
    reach = np.sqrt((((tri - mean[:, None, :]) ** 2).sum(-1)).max(axis=1))
    np.testing.assert_allclose(radii, reach[order], rtol=1e-15, atol=0)


def _brute_distances(points: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Point-to-triangle distances by another method: the foot on the plane when it falls
    inside (barycentric test), else the nearest of the three edges (segments)."""
    p = points[:, None, :]
    a, b, c = tri[None, :, 0], tri[None, :, 1], tri[None, :, 2]
    n = np.cross(b - a, c - a)
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    h = ((p - a) * n).sum(-1)
    foot = p - h[..., None] * n
    inside = np.ones(h.shape, dtype=bool)
    for u, w in ((a, b), (b, c), (c, a)):
        inside &= (np.cross(w - u, foot - u) * n).sum(-1) >= 0
    best = np.where(inside, np.abs(h), np.inf)
    for u, w in ((a, b), (b, c), (c, a)):
        t = np.clip(((p - u) * (w - u)).sum(-1) / ((w - u) ** 2).sum(-1), 0, 1)
        best = np.minimum(best, np.linalg.norm(p - (u + t[..., None] * (w - u)), axis=-1))
    return best.min(axis=1)


def test_distances_are_in_coarse_cells_and_capped() -> None:
    grid = Grid(Box.cube(2.0), (33,) * 3)
    tree = parse("x^2+y^2+z^2-1")
    a = extract_mesh(evaluate(tree, grid, threads=1), 0.0, cap=True)
    moved = type(a)(a.vertices + np.array([0.25, 0.0, 0.0]), a.faces)  # two cells of 0.125
    r = compare_meshes(a, moved, grid)
    assert 1.7 < r.to_fine < 2.1 and 1.7 < r.to_coarse < 2.1
    far = type(a)(a.vertices * 0.1, a.faces)  # 0.9 and more away: 7+ cells
    assert compare_meshes(a, far, grid, cap=3.0).to_fine == 3.0


def test_distances_are_in_cells_of_each_axis() -> None:
    """On a box stretched along z (longer cells there) a shape stretched alike measures as the
    unstretched one does, and a shift of one z cell is one cell, not a mean spacing."""
    tree, stretched = parse("x^2+y^2+z^2-1"), parse("x^2+y^2+(z/2.5)^2-1")
    cube, tall = (
        Grid(Box.cube(1.5), (24,) * 3),
        Grid(Box((-1.5, -1.5, -3.75), (1.5, 1.5, 3.75)), (24,) * 3),
    )
    for t, grid in ((tree, cube), (stretched, tall)):
        coarse = evaluate(t, grid, threads=1)
        mesh = extract_mesh(coarse, 0.0, cap=True)
        got = measure_resolution(t, coarse, mesh, 0.0, cap=True)
        if grid is cube:
            want = got
        else:
            assert got.to_fine == pytest.approx(want.to_fine, abs=0.02)
            assert got.to_coarse == pytest.approx(want.to_coarse, abs=0.02)
            assert got.area == pytest.approx(want.area, abs=0.01)
    a = extract_mesh(evaluate(stretched, tall, threads=1), 0.0, cap=True)
    dz = tall.spacing[2]
    moved = type(a)(a.vertices + np.array([0.0, 0.0, dz]), a.faces)  # one z cell
    assert 0.8 < compare_meshes(a, moved, tall).to_fine < 1.1


def test_compare_meshes_is_its_definition_bit_for_bit() -> None:
    """The one-pass comparison (each mesh taken to the grid's index space, measured and
    bucketed at once) gives what its definition gives, bit for bit: points sampled on each mesh
    moved there, their distances to the other by :func:`surface_distances`, the areas' ratio in
    world units — on a box with cells of three lengths and meshes of different sizes."""
    grid = Grid(Box((-1.5, -1.2, -2.0), (1.5, 1.2, 2.0)), (23, 19, 29))
    coarse_tree, fine_tree = parse("x^2+y^2+(z/1.3)^2-1"), parse(STRIPES)
    coarse = extract_mesh(evaluate(coarse_tree, grid, threads=1), 0.0, cap=True)
    fine = extract_mesh(evaluate(fine_tree, fine_grid(grid), threads=1), 0.0, cap=True)
    lo, spacing = np.array(grid.box.lo), np.array(grid.spacing)
    dims = np.array([n - 1 for n in grid.shape], dtype=np.int64)
    c_cells = type(coarse)((coarse.vertices - lo) / spacing, coarse.faces)
    f_cells = type(fine)((fine.vertices - lo) / spacing, fine.faces)
    origin = np.zeros(3)
    to_fine = res.surface_distances(res.sample_points(c_cells), f_cells, origin, 1.0, dims, 8.0)
    to_coarse = res.surface_distances(res.sample_points(f_cells), c_cells, origin, 1.0, dims, 8.0)
    area = float(res.face_areas(fine).sum()) / float(res.face_areas(coarse).sum())
    want = Resolution(
        float(np.percentile(to_fine, 95.0)), float(np.percentile(to_coarse, 95.0)), area, 7
    )
    assert compare_meshes(coarse, fine, grid, 7) == want  # float fields compared exactly
    assert want.to_fine > 0.1 and want.to_coarse > 0.1  # distances that searched


def test_bad_options_are_refused() -> None:
    tree = parse("x^2+y^2+z^2-1")
    coarse = evaluate(tree, Grid(Box.cube(1.5), (8,) * 3), threads=1)
    with pytest.raises(SpecError, match="allowed: band, dense"):
        fine_field(tree, coarse, 0.0, method="sparse-ish")
    with pytest.raises(SpecError, match="band"):
        fine_field(tree, coarse, 0.0, band=-1)
    with pytest.raises(SpecError, match="max_resolution_area"):
        FilterConfig(max_resolution_area=0.5)
    with pytest.raises(SpecError, match="resolution_band"):
        FilterConfig(resolution_band=9)


def test_unmeasured_shapes_are_not_judged() -> None:
    assert not unresolved({}, CFG)
    assert unresolved({"resolution_shift": 0.3, "resolution_area": 1.5}, CFG)
    assert unresolved({"resolution_shift": 1.5, "resolution_area": 1.0}, CFG)


def test_poles_only_the_fine_grid_samples_are_patched_and_counted() -> None:
    # 1/x is inf on the plane x = 0, a plane of the 31-point fine grid but not of the 16-point
    # coarse one: left as it is, it would cut the ball in two
    tree = parse("x^2+y^2+z^2-1+0.001/x^2")
    coarse = evaluate(tree, Grid(Box.cube(1.5), (16,) * 3), threads=1)
    assert np.isfinite(coarse.values).all()
    field, _, singular = fine_field(tree, coarse, 0.0, method="dense")
    assert singular == 31 * 31 and np.isfinite(field.values).all()
    mesh = extract_mesh(coarse, 0.0, cap=True)
    r = measure_resolution(tree, coarse, mesh, 0.0, cap=True)
    assert r.singular > 0 and r.to_metrics()["resolution_singular"] == r.singular
    assert r.shift < 0.6 and r.area < 1.1  # patched, the zero set has not moved...
    # ...but rendered at the fine grid the ball is slit by its pole plane: unresolved, unless
    # the new non-finite samples are few for the surface (a line of them, not a plane)
    metrics = {**r.to_metrics(), "faces": mesh.n_faces}
    assert r.singular > CFG.max_resolution_singular * mesh.n_faces
    assert unresolved(metrics, CFG)
    assert not unresolved({**metrics, "faces": 100 * r.singular}, CFG)
    assert not unresolved(metrics, FilterConfig(max_resolution_singular=1e9))
    with pytest.raises(SpecError, match="max_resolution_singular"):
        FilterConfig(max_resolution_singular=-1)


@pytest.mark.parametrize("band", [1, 2, 3])
def test_the_band_is_scipy_s_dilation_by_the_cube(band: int) -> None:
    """``_dilate`` marks what ``binary_dilation`` by the 3x3x3 cube, ``band`` times over, marks
    (the band the fine field evaluates: the same points, so the same fine field)."""
    rng = np.random.default_rng(band)
    for shape in [(63, 63, 63), (5, 9, 2), (1, 4, 7), (30, 20, 41)]:
        for share in (0.001, 0.05, 0.5):
            cells = rng.random(shape) < share
            want = binary_dilation(cells, np.ones((3, 3, 3), dtype=bool), iterations=band)
            assert np.array_equal(fb._dilate(cells, band), want), (shape, share)


def test_crossed_cells_are_those_with_corners_on_both_sides() -> None:
    """``_crossed_cells``: a cell is crossed when some of its 8 corners are inside (finite and
    below the level) and some are not — NaN and ±inf count as outside, as in marching cubes."""
    rng = np.random.default_rng(3)
    for shape in [(64, 64, 64), (5, 3, 9), (2, 2, 2), (1, 5, 5)]:
        values = rng.normal(size=shape)
        values[rng.random(shape) < 0.05] = np.nan
        values[rng.random(shape) < 0.02] = np.inf
        values[rng.random(shape) < 0.02] = -np.inf
        values[rng.random(shape) < 0.02] = 0.0
        values.flags.writeable = False  # as the sampler's fields are
        for level in (0.0, 0.5):
            inside = np.isfinite(values) & (values < level)
            c = tuple(max(n - 1, 0) for n in shape)
            corners = [
                inside[dx : dx + c[0], dy : dy + c[1], dz : dz + c[2]]
                for dx in (0, 1)
                for dy in (0, 1)
                for dz in (0, 1)
            ]
            want = np.any(corners, axis=0) & ~np.all(corners, axis=0)
            assert np.array_equal(fb._crossed_cells(values, level), want), (shape, level)
