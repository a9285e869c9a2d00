"""The leaves' states coarse to fine (:mod:`surfgen.generator.eval.leaf_states`): the compiled
levels give the states and the box count of the plain algorithm (numpy, level by level), on
odd, even and uneven grids and with bounds that decide much, little or nothing; a leaf's state
is its blocks' at every level; the bounds' answers are checked; the sampled blocks are listed
and numbered as ``np.argwhere`` lists them."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.intervals import grid_point_bounds
from surfgen.generator.eval.leaf_states import (
    INSIDE,
    OUTSIDE,
    SAMPLED,
    TOP_BLOCKS,
    classify_blocks,
    sampled_blocks,
)
from surfgen.generator.formula.parser import parse
from surfgen.generator.model.presets import PRESETS


def plain_states(program, grid, axes, level, block, bounds):
    """The coarse-to-fine classification in numpy: each level's blocks repeat their parents'
    states; the uncertain ones are bounded."""
    cells = np.asarray(grid.shape) - 1
    leaves = np.ceil(cells / block).astype(int)
    top = 0
    while np.any(np.ceil(leaves / 2**top) > TOP_BLOCKS):
        top += 1
    state, boxes = None, 0
    for lv in range(top, -1, -1):
        size = block << lv
        counts = -(-cells // size)
        if state is None:
            state = np.full(tuple(counts), SAMPLED, dtype=np.int8)
        else:
            state = np.repeat(np.repeat(np.repeat(state, 2, 0), 2, 1), 2, 2)
            state = state[: counts[0], : counts[1], : counts[2]].copy()
        todo = np.argwhere(state == SAMPLED)
        if len(todo) == 0:
            continue
        first = todo * size
        last = np.minimum(first + size, cells)
        lo = np.stack([axes[a][first[:, a]] for a in range(3)], axis=1)
        hi = np.stack([axes[a][last[:, a]] for a in range(3)], axis=1)
        flo, fhi, finite = bounds(program, lo, hi)
        boxes += len(todo)
        decided = np.full(len(todo), SAMPLED, dtype=np.int8)
        decided[flo > level] = OUTSIDE
        decided[finite & (fhi < level)] = INSIDE
        state[tuple(todo.T)] = decided
    return state, boxes


def _nothing_decided(program, lo, hi):
    return np.full(len(lo), -np.inf), np.full(len(lo), np.inf), np.zeros(len(lo), bool)


@pytest.mark.parametrize(
    ("text", "shape", "block"),
    [
        ("x^2+y^2+z^2-1", (65, 65, 65), 8),
        ("x^2+y^2+z^2-1", (40, 73, 31), 8),
        ("sin(3*x)*cos(2*y) + sin(3*z) - 0.2", (97, 96, 33), 4),
        ("x^4 - 5*x^2 + y^4 - 5*y^2 + z^4 - 5*z^2 + 11.8", (130, 45, 201), 8),
        ("tan(2*x) + y^2 + abs(z) - 0.5", (51, 51, 52), 5),
        ("x + 0.1", (300, 9, 9), 8),
    ],
)
def test_the_levels_give_the_plain_algorithm_s_states(text, shape, block) -> None:
    program = compile_tree(parse(text))
    grid = Grid(Box((-1.7, -1.5, -1.3), (1.6, 1.9, 1.2)), shape)
    axes = grid.axes()
    for bounds in (grid_point_bounds(axes, 2), _nothing_decided):
        for level in (0.0, 0.7):
            state, boxes = classify_blocks(program, grid, axes, level, block, bounds)
            want, want_boxes = plain_states(program, grid, axes, level, block, bounds)
            assert state.dtype == np.int8 and state.flags.c_contiguous
            assert np.array_equal(state, want) and boxes == want_boxes
            assert state.shape == tuple(-(-(n - 1) // block) for n in shape)


def test_a_block_decided_at_a_coarse_level_decides_its_leaves() -> None:
    """Eq. C's states: the top level's 8^3 blocks decided, and their leaves never bounded
    again (fewer boxes than leaves), each leaf its decided block's state."""
    spec = PRESETS["eqC"].spec()
    grid = Grid(spec.to_grid().box, (257, 257, 257))
    axes = grid.axes()
    program = compile_tree(spec.tree(), dict(spec.params))
    state, boxes = classify_blocks(program, grid, axes, spec.level, 8, grid_point_bounds(axes))
    assert state.shape == (32, 32, 32) and boxes < state.size
    assert np.count_nonzero(state == OUTSIDE) and np.count_nonzero(state == SAMPLED)
    seen = []

    def counting(program, lo, hi):
        seen.append(len(lo))
        return grid_point_bounds(axes)(program, lo, hi)

    assert np.array_equal(classify_blocks(program, grid, axes, spec.level, 8, counting)[0], state)
    assert seen[0] == 8**3 and sum(seen) == boxes and len(seen) == 3  # 32, 16, 8 blocks a side


def test_bounds_of_the_wrong_length_are_refused() -> None:
    grid = Grid(Box.cube(1.0), (33, 33, 33))
    program = compile_tree(parse("x^2+y^2+z^2-0.5"))

    def short(program, lo, hi):
        return np.zeros(len(lo) - 1), np.zeros(len(lo) - 1), np.zeros(len(lo) - 1, bool)

    with pytest.raises(ValueError, match="expected 64 bounds"):
        classify_blocks(program, grid, grid.axes(), 0.0, 8, short)


@pytest.mark.parametrize("count", [0, 1, 2, 37, 60])
def test_sampled_blocks_are_argwhere_s_and_numbered_in_order(count) -> None:
    rng = np.random.default_rng(count)
    state = rng.choice([OUTSIDE, INSIDE], size=(3, 4, 5)).astype(np.int8)
    state.flat[rng.choice(60, count, replace=False)] = SAMPLED
    blocks, number = sampled_blocks(state)
    want = np.argwhere(state == SAMPLED)
    assert blocks.shape == (count, 3) and blocks.dtype == np.int64 and blocks.flags.c_contiguous
    assert np.array_equal(blocks, want)
    assert number.dtype == np.int32 and number.shape == state.shape
    assert np.array_equal(number[tuple(want.T)], np.arange(count))
    assert np.all(number[state != SAMPLED] == -1)
