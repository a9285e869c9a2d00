"""The grid kernel's tiles (several short rows to a tile, long rows cut) and the sparse
evaluator's columns of bricks (:func:`~surfgen.generator.eval.grid_driver.run_columns`, through
``tape.evaluate_columns``): the grid's values bit for bit, whatever the tile length and the
threads."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from numba import types
from test_tape import assert_identical

from surfgen.generator.eval import grid_driver
from surfgen.generator.eval import tape as fast
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.opcodes import M_S, M_SV, M_VS
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.eval.tape import evaluate_program
from surfgen.generator.formula.parser import parse
from surfgen.generator.jit.options import KERNEL


@pytest.mark.parametrize("tile_max", [4, 8, 24, 512, 1024])
@pytest.mark.parametrize(
    "formula",
    [
        "tan(x*z+y*z)+atan(x-z)*abs(y*z)^1.5",  # no y or xy scalar in the per-point block
        "sin(x*y)*z+cos(y)*z^2+atan2(x*y,z)+(x*y)^z",  # y and xy scalars: rewritten to W rows
    ],
)
def test_tiles_of_several_rows_give_the_same_bits(monkeypatch, tile_max, formula):
    # Short z runs are packed several rows j to a tile (kernels._block_rows, with y and xy
    # scalars turned into rows by fast.rows_program); runs longer than the tile are cut into
    # chunks; every way must give the reference's values bit for bit, on 1 and 2 threads.
    monkeypatch.setattr(fast, "TILE_MAX", tile_max)
    tree = parse(formula)
    program = compile_tree(tree)
    l0, l1 = program.blocks[7, 2:4]
    per_j = [slot for k, _, slot, v in program.loads[l0:l1] if v == 0 and k in (2, 3)]
    assert bool(per_j) == ("sin" in formula)
    code, _, loads, _, _, _, n_vector, _ = fast.rows_program(program)
    rewritten = [
        q for lv in (6, 7) for q in range(*program.blocks[lv, 2:4]) if program.loads[q, 3] == 0
    ]
    rewritten = [q for q in rewritten if program.loads[q, 0] in (2, 3)]
    assert n_vector == program.n_vector + len(rewritten)
    assert not [s for k, _, s, v in loads[l0:l1] if v == 0 and k in (2, 3)]
    c0, c1 = program.blocks[7, :2]
    for _, mode, _, a, b, _ in code[c0:c1]:  # no instruction reads a per-row scalar any more
        assert not (mode == M_VS and b in per_j)
        assert not (mode in (M_SV, M_S) and a in per_j)
    for shape in ((5, 7, 4), (4, 9, 10), (4, 5, 26)):
        grid = Grid(Box.cube(2.0), shape)
        want = evaluate_reference(tree, grid).values
        for threads in (1, 2):
            got = evaluate_program(program, grid, threads=threads).values
            assert_identical(got, want, f"{formula} {shape} tile<={tile_max} {threads}T")


def test_the_tile_length_follows_the_cpu():
    # measured: AMD's Zen cores run the 50 stored formulas fastest with 1024-point tiles, an
    # Intel Xeon with 512 (tile_length.py); any length gives the same bits (the test above)
    assert fast.tile_max("znver3") == 1024
    assert fast.tile_max("znver5") == 1024
    for intel in ("sapphirerapids", "rocketlake", "skylake-avx512", "icelake-server"):
        assert fast.tile_max(intel) == 512
    assert fast.tile_max(fast._host_cpu_name()) == fast.TILE_MAX
    assert fast._tile(128) == fast.TILE_MAX  # several z rows of 128 to a tile


@pytest.mark.parametrize("tile_max", [8, 24, 1024])
@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("cost", [0, 4096, 10**12], ids=["grouped", "default", "apart"])
def test_columns_of_bricks_are_the_grids_values(monkeypatch, tile_max, threads, cost):
    # The sparse evaluator's bricks, a group of columns at a time in one kernel call per
    # thread (tape.evaluate_columns): each brick holds the dense grid's values, bit for bit,
    # whether its group's z run fits a tile twice (several rows to a tile) or not, with gaps
    # in z, whether the columns are grouped (as many as lose no point, the default's, or none)
    monkeypatch.setattr(fast, "TILE_MAX", tile_max)
    monkeypatch.setattr(grid_driver, "COLUMN_COST_POINTS", cost)
    tree = parse("sin(x*y)*z+cos(y)*z^2+atan2(x*y,z)+tan(x*z+y*z)")
    program = compile_tree(tree)
    grid = Grid(Box((-2.0, -1.5, -2.5), (2.0, 1.0, 3.0)), (17, 13, 45))
    want = evaluate_reference(tree, grid).values
    block = 4
    rng = np.random.default_rng(3)
    leaves = np.argwhere(rng.random((4, 3, 11)) < 0.6).astype(np.int64)  # argwhere: in order
    corner = leaves * block
    extent = np.minimum(block + 1, np.asarray(grid.shape)[None, :] - corner)
    members = np.arange(len(leaves), dtype=np.int64)
    values = np.full((len(leaves), block + 1, block + 1, block + 1), np.nan)
    fast.evaluate_columns(program, grid.axes(), members, corner, extent, values, threads)
    for b, (c, e) in enumerate(zip(corner, extent, strict=True)):
        got = values[b, : e[0], : e[1], : e[2]]
        assert_identical(got, want[c[0] : c[0] + e[0], c[1] : c[1] + e[1], c[2] : c[2] + e[2]])
    assert np.isnan(values[extent[:, 2] < block + 1][..., block]).all()  # past the grid: untouched


def groups_of(
    leaves: np.ndarray,
    block: int,
    shape: tuple[int, ...],
    cost: int,
    max_points: int = grid_driver.GROUP_POINTS,
) -> np.ndarray:
    corner = leaves * block
    extent = np.minimum(block + 1, np.asarray(shape)[None, :] - corner)
    members = np.arange(len(leaves), dtype=np.int64)
    return grid_driver.column_groups(members, corner, extent, cost, max_points)


def test_column_groups_merge_neighbouring_columns_where_one_grid_costs_less():
    # Columns (x, y) of 4-cell bricks: (0,0) z 0-1, (0,1) z 0-1, (0,2) z 6, (1,0) z 0: the
    # first two share their z points (one grid of 5x9x9 points < two of 5x5x9 and a cost
    # each); (0,2)'s z points are new, so it joins only where a grid costs more than its
    # points would add; (1,0) has other x points: never with them.
    leaves = np.array([[0, 0, 0], [0, 0, 1], [0, 1, 0], [0, 1, 1], [0, 2, 6], [1, 0, 0]])
    shape = (9, 13, 29)
    assert groups_of(leaves, 4, shape, 0).tolist() == [[0, 4], [4, 5], [5, 6]]
    # (0,2) alone: 5*5*5 points + cost; with the group: 5*13*14 - 5*9*9 more points
    assert groups_of(leaves, 4, shape, 5 * 13 * 14 - 5 * 9 * 9 - 125 - 1).tolist() == [
        [0, 4], [4, 5], [5, 6]
    ]  # fmt: skip
    assert groups_of(leaves, 4, shape, 5 * 13 * 14 - 5 * 9 * 9 - 125).tolist() == [[0, 5], [5, 6]]
    assert groups_of(leaves, 4, shape, 10**12).tolist() == [[0, 5], [5, 6]]
    # no merge past max_points (a group of one column may have more)
    capped = groups_of(leaves, 4, shape, 10**12, 5 * 9 * 9 - 1)
    assert capped.tolist() == [[0, 2], [2, 4], [4, 5], [5, 6]]
    # a gap along y (column (0,3) missing before (0,4)) is never bridged
    gap = np.array([[0, 0, 0], [0, 4, 0]])
    assert groups_of(gap, 4, (9, 21, 5), 10**12).tolist() == [[0, 1], [1, 2]]


def test_column_groups_cover_every_member_once_in_order():
    rng = np.random.default_rng(5)
    leaves = np.argwhere(rng.random((6, 7, 9)) < 0.3).astype(np.int64)
    for cost in (0, 100, 4096, 10**12):
        groups = groups_of(leaves, 4, (25, 29, 37), cost)
        assert groups[0, 0] == 0 and groups[-1, 1] == len(leaves)
        assert (groups[1:, 0] == groups[:-1, 1]).all() and (groups[:, 1] > groups[:, 0]).all()
        for a, b in groups:  # one x block, and its columns' y blocks without a gap
            assert len(set(leaves[a:b, 0])) == 1
            ys = np.unique(leaves[a:b, 1])
            assert (np.diff(ys) == 1).all()
    apart = groups_of(leaves, 4, (25, 29, 37), 0)
    merged = groups_of(leaves, 4, (25, 29, 37), 10**12)
    assert len(merged) < len(apart)


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_columns_then_runs_on_each_threads_bricks_once_they_are_filled(threads):
    # evaluate_columns(..., then=f): each thread calls f on the members it filled, as soon as
    # they are (the sparse evaluator decides the bricks' sides there): the ranges cover the
    # members once, in order, and each sees its bricks filled
    program = compile_tree(parse("x*y - z"))
    grid = Grid(Box.cube(1.0), (33, 17, 25))
    block = 4
    leaves = np.argwhere(np.ones((8, 4, 6), dtype=bool)).astype(np.int64)
    corner = leaves * block
    extent = np.minimum(block + 1, np.asarray(grid.shape)[None, :] - corner)
    values = np.full((len(leaves), block + 1, block + 1, block + 1), np.nan)

    def filled(m0: int, m1: int) -> tuple[int, int, bool]:
        done = all(
            np.isfinite(values[b, : extent[b, 0], : extent[b, 1], : extent[b, 2]]).all()
            for b in range(m0, m1)
        )
        return m0, m1, done

    members = np.arange(len(leaves), dtype=np.int64)
    got = fast.evaluate_columns(program, grid.axes(), members, corner, extent, values, threads,
                                filled)  # fmt: skip
    assert len(got) == threads
    assert [g[0] for g in got] == [0] + [g[1] for g in got[:-1]] and got[-1][1] == len(leaves)
    assert all(g[2] and g[1] > g[0] for g in got)
    assert fast.evaluate_columns(program, grid.axes(), members, corner, extent, values, 2) == []


def test_the_columns_kernel_calls_the_grid_kernel_with_the_grids_own_types(monkeypatch):
    # run_columns passes int64 values, not literal constants, for the grid kernel's part and
    # rows: numba then compiles run_grid once (for the grid evaluator and the bricks alike)
    # instead of a second time for Literal[int] arguments - seconds of a cold warm-up.
    tree = parse("sin(x*y)*z + x^2")
    program = compile_tree(tree)
    grid = Grid(Box.cube(1.0), (9, 9, 9))
    corner = np.zeros((1, 3), dtype=np.int64)
    extent = np.full((1, 3), 5, dtype=np.int64)
    values = np.full((1, 5, 5, 5), np.nan)
    members = np.zeros(1, dtype=np.int64)
    # a fresh (uncached) compile of run_columns: typing it asks run_grid for the signature of
    # its call, which a copy loaded from numba's cache would not
    fresh = numba.njit(**{**KERNEL, "cache": False})(grid_driver.run_columns.py_func)
    monkeypatch.setattr(grid_driver, "run_columns", fresh)
    fast.evaluate_columns(program, grid.axes(), members, corner, extent, values, 1)
    assert fresh.signatures  # the fresh copy ran
    signatures = grid_driver.run_grid.signatures
    assert signatures
    assert not [s for s in signatures if any(isinstance(t, types.Literal) for t in s)]


def test_the_columns_kernel_chooses_the_tile_as_the_grid_does():
    for n in range(1, 3000, 7):
        assert grid_driver.tile_for(n, fast.TILE_MAX) == fast._tile(n)
