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
def test_columns_of_bricks_are_the_grids_values(monkeypatch, tile_max, threads):
    # The sparse evaluator's bricks, column by column in one kernel call per thread
    # (tape.evaluate_columns): each brick holds the dense grid's values, bit for bit, whether
    # its column's z run fits a tile twice (several rows to a tile) or not, with gaps in z.
    monkeypatch.setattr(fast, "TILE_MAX", tile_max)
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
