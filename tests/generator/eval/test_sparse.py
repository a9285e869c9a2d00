"""Sparse evaluation (:mod:`surfgen.generator.eval.sparse`) with the real interval bounds: the
sampled values are the dense grid's, bit for bit; every skipped leaf is on the side its state
says; the registry, the share limit and the sign proxy; and the real bounds' meshes are the
dense ones (the stand-in bounds of ``tests/generator/mesh/test_sparse_marching.py`` push the
skipping further)."""

from __future__ import annotations

from dataclasses import replace

import numba
import numpy as np
import pytest

from surfgen.filters.compare import inside_samples
from surfgen.generator.errors import EmptySurface
from surfgen.generator.eval.evaluate import EVALUATORS, evaluate, evaluate_points
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.sparse import (
    INSIDE,
    OUTSIDE,
    SAMPLED,
    SparseField,
    brick_layout,
    evaluate_sparse,
    leaf_counts,
)
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import extract_with_edges
from surfgen.generator.mesh.realise import AUTO_SPARSE_FROM, realise, resolve_evaluator
from surfgen.generator.mesh.sparse_marching import extract_sparse_with_edges
from surfgen.generator.model.presets import PRESETS
from surfgen.generator.model.spec import SurfaceSpec

SPHERE = parse("x^2+y^2+z^2-1")


def leaf_slices(sf: SparseField, leaf) -> tuple[slice, ...]:
    b = sf.block
    return tuple(slice(c * b, c * b + b + 1) for c in leaf)


@pytest.mark.parametrize("name", ["eqC", "schwarz", "chmutov", "clebsch"])
def test_states_and_values_match_the_dense_field(name):
    spec = PRESETS[name].spec()
    grid = Grid(spec.to_grid().box, (57, 50, 43))
    dense = evaluate(spec.tree(), grid, spec.params).values
    sf = evaluate_sparse(spec.tree(), grid, spec.params, level=spec.level)
    assert sf.state.shape == leaf_counts(grid)
    assert set(np.unique(sf.state)) <= {OUTSIDE, INSIDE, SAMPLED}
    for leaf in np.argwhere(sf.state != SAMPLED):
        v = dense[leaf_slices(sf, leaf)]
        inside = np.isfinite(v) & (v < spec.level)
        if sf.state[tuple(leaf)] == OUTSIDE:
            assert not inside.any()
        else:
            assert inside.all()
    # every sampled point holds the dense value, bit for bit
    for b, (c0, c1, c2) in enumerate(sf.corner):
        e0, e1, e2 = sf.extent[b]
        got = sf.values[b, :e0, :e1, :e2]
        want = dense[c0 : c0 + e0, c1 : c1 + e1, c2 : c2 + e2]
        assert got.tobytes() == want.tobytes()


def test_real_bounds_skip_blocks_and_keep_the_mesh():
    grid = Grid(Box.cube(1.5), (96, 96, 96))
    sf = evaluate_sparse(SPHERE, grid, faces=True)
    assert 0 < sf.share < 0.5
    assert np.any(sf.state == OUTSIDE) and np.any(sf.state == INSIDE)
    dense = extract_with_edges(evaluate(SPHERE, grid), 0.0, True)
    sparse = extract_sparse_with_edges(sf, True)
    assert dense[0].vertices.tobytes() == sparse[0].vertices.tobytes()
    assert dense[0].faces.tobytes() == sparse[0].faces.tobytes()


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_presets_with_real_bounds(name):
    spec = PRESETS[name].spec()
    grid = Grid(spec.to_grid().box, (44, 45, 46))
    cap = PRESETS[name].cap
    field = evaluate(spec.tree(), grid, spec.params)
    dense = extract_with_edges(field, spec.level, cap)
    sf = evaluate_sparse(spec.tree(), grid, spec.params, level=spec.level, faces=cap)
    sparse = extract_sparse_with_edges(sf, cap)
    assert dense[0].vertices.tobytes() == sparse[0].vertices.tobytes()
    assert dense[0].faces.tobytes() == sparse[0].faces.tobytes()
    assert dense[1].tobytes() == sparse[1].tobytes()


def _no_bounds(program, lo, hi):
    """Bounds that decide nothing: every leaf is sampled."""
    return np.full(len(lo), -np.inf), np.full(len(lo), np.inf), np.zeros(len(lo), bool)


@pytest.mark.parametrize("cap", [False, True])
def test_one_sided_bricks_are_decided_after_sampling(cap):
    # a ball cut by the box: leaves all outside, all inside (some on the box's faces) and mixed
    grid = Grid(Box((-1.0, -1.1, -0.9), (1.0, 1.2, 0.9)), (41, 42, 39))
    tree = parse("x^2+y^2+z^2-1.1")
    field = evaluate(tree, grid)
    sf = evaluate_sparse(tree, grid, faces=cap, bounds=_no_bounds)
    n_leaves = int(np.prod(leaf_counts(grid)))
    assert sf.stats["sampled_leaves"] == n_leaves
    # every leaf's brick was evaluated (shared faces once per brick), dropped ones too
    per_axis = [
        [min(sf.block + 1, n - sf.block * c) for c in range(m)]
        for n, m in zip(grid.shape, leaf_counts(grid), strict=True)
    ]
    assert sf.points_evaluated == sum(per_axis[0]) * sum(per_axis[1]) * sum(per_axis[2])
    assert sf.share == sf.points_evaluated / grid.size > 1.0
    top = np.asarray(sf.state.shape) - 1
    for leaf in np.argwhere(np.ones(sf.state.shape, bool)):
        v = field.values[leaf_slices(sf, leaf)]
        inside = np.isfinite(v) & (v < 0)
        face = bool(np.any((leaf == 0) | (leaf == top)))
        kept = inside.any() and not inside.all() or (cap and face and inside.all())
        want = SAMPLED if kept else (INSIDE if inside.all() else OUTSIDE)
        assert sf.state[tuple(leaf)] == want, leaf
    assert sf.values.shape[0] == sf.n_bricks == np.count_nonzero(sf.state == SAMPLED)
    assert np.any(sf.state == INSIDE) and np.any(sf.state == OUTSIDE)
    dense = extract_with_edges(field, 0.0, cap)
    sparse = extract_sparse_with_edges(sf, cap)
    assert dense[0].vertices.tobytes() == sparse[0].vertices.tobytes()
    assert dense[0].faces.tobytes() == sparse[0].faces.tobytes()
    assert dense[1].tobytes() == sparse[1].tobytes()


@pytest.mark.parametrize("cap", [False, True])
def test_a_field_all_inside_is_no_surface_once_its_bricks_are_dropped(cap):
    # every leaf sampled (bounds deciding nothing) and found all inside: dropped, or kept on
    # the box's faces for the caps; the field is still all inside, no surface either way (a
    # draw of the fuzz, capped, once meshed the box's caps sparsely where dense had no surface)
    grid = Grid(Box.cube(1.0), (41, 37, 30))
    tree = parse("x^2+y^2+z^2-10")
    sf = evaluate_sparse(tree, grid, faces=cap, bounds=_no_bounds)
    assert sf.stats["sampled_leaves"] == int(np.prod(leaf_counts(grid)))
    assert (sf.n_bricks > 0) == cap and np.all(sf.state != OUTSIDE)
    assert sf.any_inside() and sf.all_inside()
    with pytest.raises(EmptySurface, match="inside"):
        extract_with_edges(evaluate(tree, grid), 0.0, cap)
    with pytest.raises(EmptySurface, match="inside"):
        extract_sparse_with_edges(sf, cap)
    outside = evaluate_sparse(parse("x^2+y^2+z^2+1"), grid, faces=cap, bounds=_no_bounds)
    assert not outside.any_inside() and not outside.all_inside()


def test_values_at_and_sampled_at():
    grid = Grid(Box.cube(1.5), (40, 40, 40))
    sf = evaluate_sparse(SPHERE, grid)
    dense = evaluate(SPHERE, grid).values
    i, j, k = (a.ravel() for a in np.indices(grid.shape))
    have = sf.sampled_at(i, j, k)
    got = sf.values_at(i, j, k)
    assert have.any() and not have.all()
    assert np.array_equal(got[have], dense.ravel()[have])
    assert np.isnan(got[~have]).all()


def test_nonfinite_counts_each_sampled_point_once():
    tree = parse("sqrt(1-x^2-y^2-z^2)-0.3")
    grid = Grid(Box.cube(1.2), (33, 33, 33))
    sf = evaluate_sparse(tree, grid, bounds=_no_bounds)
    dense = evaluate(tree, grid)
    assert sf.nonfinite == dense.nonfinite > 0
    # without the sampling's count (a field built from bricks): the bricks' own points
    bare = replace(sf, stats={})
    i, j, k = (a.ravel() for a in np.indices(grid.shape))
    held = bare.sampled_at(i, j, k)
    assert bare.nonfinite == np.count_nonzero(~np.isfinite(dense.values.ravel()[held])) > 0


def test_registry_entry():
    grid = Grid(Box.cube(1.5), (24, 24, 24))
    assert "sparse" in EVALUATORS
    sf = evaluate(SPHERE, grid, evaluator="sparse", level=0.25)
    assert isinstance(sf, SparseField) and sf.level == 0.25
    x = np.linspace(-1, 1, 7)
    assert np.array_equal(
        evaluate_points(SPHERE, x, x, x, evaluator="sparse"), evaluate_points(SPHERE, x, x, x)
    )


def test_sign_proxy_compares_as_the_dense_field():
    grid = Grid(Box.cube(1.5), (48, 48, 48))
    sf = evaluate_sparse(SPHERE, grid)
    target = Grid(Box.cube(1.6), (37, 37, 37))
    assert np.array_equal(
        inside_samples(sf.sign_proxy(), target), inside_samples(evaluate(SPHERE, grid), target)
    )


def _proxy_by_leaves(sf: SparseField) -> np.ndarray:
    """The sign proxy as it was written in Python, leaf by leaf then brick by brick."""
    b = sf.block
    values = np.empty(sf.grid.shape)
    below = sf.level - max(1.0, abs(sf.level) / 2)
    for side, fill in ((OUTSIDE, np.inf), (INSIDE, below)):
        for leaf in np.argwhere(sf.state == side):
            values[tuple(slice(c * b, c * b + b + 1) for c in leaf)] = fill
    samples = sf.samples()
    for brick, (c0, c1, c2) in enumerate(sf.corner):
        e0, e1, e2 = sf.extent[brick]
        values[c0 : c0 + e0, c1 : c1 + e1, c2 : c2 + e2] = samples[brick, :e0, :e1, :e2]
    return values


@pytest.mark.parametrize(
    ("formula", "shape", "level", "block", "faces"),
    [
        ("x^2+y^2+z^2-1", (48, 48, 48), 0.0, 8, False),
        ("x^2+y^2+z^2-1", (41, 37, 30), -0.3, 4, True),  # odd, unequal; inside leaves kept
        ("sin(3*x)*cos(3*y)+sin(3*y)*cos(3*z)+sin(3*z)*cos(3*x)", (33, 40, 26), 0.2, 8, False),
        ("1/(x^2+y^2+z^2-1)-3", (36, 36, 36), 0.0, 4, True),  # poles: non-finite samples
    ],
)
def test_sign_proxy_is_the_leaf_by_leaf_fill_bit_for_bit(formula, shape, level, block, faces):
    grid = Grid(Box((-1.5, -1.3, -1.6), (1.5, 1.4, 1.2)), shape)
    sf = evaluate_sparse(parse(formula), grid, level=level, block=block, faces=faces)
    assert (sf.state == INSIDE).any() or (sf.state == OUTSIDE).any()
    fast, slow = sf.sign_proxy().values, _proxy_by_leaves(sf)
    assert fast.tobytes() == slow.tobytes()


def test_auto_picks_sparse_on_large_grids_whatever_they_leave_to_sample():
    small, large = Grid(Box.cube(1), (159,) * 3), Grid(Box.cube(1), (160,) * 3)
    assert resolve_evaluator("auto", small) == "fast"
    assert resolve_evaluator("auto", large) == "sparse" and large.size >= AUTO_SPARSE_FROM
    assert resolve_evaluator("reference", large) == "reference"
    sphere = SurfaceSpec("x^2+y^2+z^2-1", (-1.5, 1.5) * 3, (160,) * 3)
    assert realise(sphere, evaluator="auto", cap=True).sparse
    # poles on planes x + y + z = k pi / 9, through every block (a value of all three axes:
    # infinite bounds wherever a plane passes): no block can be skipped, and auto stays sparse
    # (faster all the same: benchmarks/bench_auto.py), with the dense path's mesh
    poles = SurfaceSpec("1/sin(9*(x+y+z))-0.5", (-1.5, 1.5) * 3, (160,) * 3)
    made = realise(poles, evaluator="auto", cap=True)
    assert made.sparse and made.field.share > 1
    dense = realise(poles, evaluator="dense", cap=True).mesh
    assert made.mesh.vertices.tobytes() == dense.vertices.tobytes()
    assert made.mesh.faces.tobytes() == dense.faces.tobytes()
    # equation A's poles are on planes x, y or z = const (tan(m x) and the like): a value of
    # one axis is bounded at the grid's coordinates, so its blocks are skipped and auto is sparse
    eq_a = PRESETS["eqA"].spec().replace(grid=(160, 160, 160))
    assert realise(eq_a, evaluator="auto", allow_empty=True).sparse


def test_bad_block_and_evaluator():
    grid = Grid(Box.cube(1), (16,) * 3)
    with pytest.raises(ValueError, match="block"):
        evaluate_sparse(SPHERE, grid, block=0)
    # a brick's rows are read as the bits of an int64: 63 samples at most
    with pytest.raises(ValueError, match="block must be a whole number from 1 to 62, got 63"):
        evaluate_sparse(SPHERE, Grid(Box.cube(1), (130,) * 3), block=63)
    big = Grid(Box.cube(1.5), (130,) * 3)
    field = extract_with_edges(evaluate(SPHERE, big, {}), 0.0, True)
    sparse = extract_sparse_with_edges(evaluate_sparse(SPHERE, big, block=62, faces=True), True)
    assert field[0].faces.tobytes() == sparse[0].faces.tobytes()
    assert resolve_evaluator("dense", grid) == "fast"  # the name for the fast path
    with pytest.raises(Exception, match="unknown evaluator 'sparce'.*auto, dense, fast"):
        resolve_evaluator("sparce", grid)


def test_the_bricks_kept_shrink_in_place_unless_held_elsewhere():
    from surfgen.generator.eval.sparse import _shrunk

    values = np.arange(80, dtype=np.float64).reshape(10, 2, 2, 2).copy()  # owns its memory
    want, identity = values[:4].copy(), id(values)
    held = [values]
    del values
    out = _shrunk(held, 4)
    assert id(out) == identity and held == []  # the same array, resized: no second copy
    assert out.tobytes() == want.tobytes()
    other = np.arange(80, dtype=np.float64).reshape(10, 2, 2, 2)
    kept = _shrunk([other], 4)  # `other` still held here: a copy, the original untouched
    assert kept is not other and other.shape == (10, 2, 2, 2)
    assert kept.tobytes() == want.tobytes()


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_bricks_kept_move_down_as_numpy_selects_them(threads):
    # drops before, within and after the halves, none, all but one, long runs of either, the
    # first drop a third of the way in (only the rows after it move, in halves): the
    # rows numpy's selection gives (two threads move the halves at once, the first half's
    # bricks read from the second's rows kept aside)
    from surfgen.generator.eval.sparse import MOVE_APART, moved_down

    rng = np.random.default_rng(7)
    n = 3 * MOVE_APART
    patterns = [np.ones(n, bool), np.arange(n) != 0, np.arange(n) == n - 1,
                np.arange(n) >= n // 3, np.arange(n) % 2 == 0, (np.arange(n) // 40) % 3 != 1,
                np.abs(np.arange(n) - n // 3 - 3) > 2]  # fmt: skip
    patterns += [rng.random(n) < p for p in (0.02, 0.1, 0.5, 0.97)]
    for keep in patterns:
        values = rng.standard_normal((n, 3, 3, 3))
        before = values.copy()
        kept = np.flatnonzero(keep)
        assert moved_down(values, kept, threads) == kept.size
        assert values[: kept.size].tobytes() == before[kept].tobytes()


def test_sampling_holds_no_second_copy_of_the_bricks_kept():
    import tracemalloc

    # 161^3: the bricks kept (824) outweigh the threads' grids of groups of columns (at most
    # GROUP_POINTS values each, with their stores: 1.75 MB in all here) twice over
    grid = Grid(Box.cube(1.5), (161, 161, 161))
    n_leaves = int(np.prod(leaf_counts(grid)))
    brick = 9**3 * 8
    evaluate_sparse(SPHERE, grid, bounds=_no_bounds)  # compiled, warm
    tracemalloc.start()
    try:
        sf = evaluate_sparse(SPHERE, grid, bounds=_no_bounds)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    kept = sf.n_bricks * brick
    assert sf.n_bricks < n_leaves / 2
    # every leaf's brick allocated (its pages touched only as far as the bricks kept and one
    # run), then shrunk in place: a copy of the bricks kept would add `kept` to the peak
    assert peak < n_leaves * brick + kept / 2


def test_brick_layout_has_one_layout_whatever_the_count() -> None:
    """``np.argwhere`` gives a transposed array when it finds two leaves or more and a
    contiguous one for one: the layout is made C-contiguous, so the kernels reading it are
    compiled once (the second layout's compile landed inside a timed 512^3 render)."""
    grid = Grid(Box.cube(1.0), (33, 33, 33))
    kinds = set()
    for count in (1, 2, 17, 64):
        state = np.full((4, 4, 4), OUTSIDE, dtype=np.int8)
        state.flat[np.arange(0, 64, 64 // count)[:count]] = SAMPLED
        leaves, slot, corner, extent = brick_layout(state, grid, 8)
        assert len(leaves) == count
        assert all(a.flags.c_contiguous for a in (leaves, slot, corner, extent))
        assert (corner == leaves * 8).all() and (extent == np.minimum(9, 33 - corner)).all()
        kinds.add(tuple(numba.typeof(a) for a in (leaves, slot, corner, extent)))
    assert len(kinds) == 1
