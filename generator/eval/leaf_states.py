"""Coarse to fine: the states of a grid's leaf blocks from interval bounds.

The grid's cells are split into cubic leaf blocks of ``block`` cells a side
(:mod:`surfgen.generator.eval.sparse`).  :func:`classify_blocks` bounds blocks of
``block * 2**l`` cells, from the coarsest (at most :data:`TOP_BLOCKS` a side) to the leaves: a
block whose bounds lie above the level is *outside* (every grid point in it is above the level
or non-finite), one whose bounds are finite and below the level is *inside*; the children of
the others are bounded at the next level, down to the leaves.

The levels' bookkeeping (children of the uncertain blocks, their boxes, the states written
back) is compiled, as is the bounds' planning (:mod:`~surfgen.generator.eval.interval_plan`):
in numpy the two took four times as long as the bounds' kernel (sculpture-1 at 512^3: 13.3
ms in all, now 5.8).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numba import njit

from surfgen.generator.eval.compiler import Program
from surfgen.generator.eval.grid import Grid
from surfgen.generator.jit.options import KERNEL

#: Blocks per side at the coarsest level (at most): the first bounding pass.
TOP_BLOCKS = 8

OUTSIDE, INSIDE, SAMPLED = np.int8(0), np.int8(1), np.int8(2)

#: ``(program, lo, hi) -> (flo, fhi, finite)``: what bounds F over boxes.
Bounds = Callable[[Program, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]

__all__ = [
    "INSIDE",
    "OUTSIDE",
    "SAMPLED",
    "TOP_BLOCKS",
    "Bounds",
    "classify_blocks",
    "sampled_blocks",
]


def classify_blocks(
    program: Program,
    grid: Grid,
    axes: tuple[np.ndarray, np.ndarray, np.ndarray],
    level: float,
    block: int,
    bounds: Bounds,
) -> tuple[np.ndarray, int]:
    """The leaves' states (int8, ``ceil((N - 1) / block)`` per axis) and the number of boxes
    bounded (the module's docstring).

    Every block of the coarsest level is bounded; at each finer level the children of the
    uncertain blocks are, and a state is inherited from the parent where the parent was
    decided."""
    cells = np.asarray(grid.shape, dtype=np.int64) - 1
    n_leaf = -(-cells // block)
    top = 0
    while np.any(-(-n_leaf // (1 << top)) > TOP_BLOCKS):
        top += 1
    ax, ay, az = (np.ascontiguousarray(a, dtype=np.float64) for a in axes)
    level = float(level)
    boxes = 0
    state = np.full(tuple(-(-cells // (block << top))), SAMPLED, dtype=np.int8)
    todo = sampled_blocks(state)[0]  # every block of the coarsest level
    for lv in range(top, -1, -1):
        size = block << lv
        if lv < top:
            c0, c1, c2 = (int(c) for c in -(-cells // size))
            state, todo = _children(state, c0, c1, c2)
        if len(todo) == 0:
            continue
        lo, hi = _boxes(todo, size, cells, ax, ay, az)
        flo, fhi, finite = _checked(bounds(program, lo, hi), len(todo))
        boxes += len(todo)
        _decide(state, todo, flo, fhi, finite, level)
    return state, boxes


def _checked(made: tuple, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ``Bounds``' answer as the kernels read it: float64, float64, bool, ``n`` each."""
    flo, fhi, finite = made
    out = (
        np.ascontiguousarray(flo, dtype=np.float64),
        np.ascontiguousarray(fhi, dtype=np.float64),
        np.ascontiguousarray(finite, dtype=np.bool_),
    )
    if any(a.shape != (n,) for a in out):
        raise ValueError(f"bounds: expected {n} bounds, got shapes {[a.shape for a in out]}")
    return out


@njit(**KERNEL)
def _children(parent, c0, c1, c2):
    """The next level's states (each block its parent's, the grid's end cutting the last
    ones) and its uncertain blocks in C order (``np.argwhere``'s)."""
    state = np.empty((c0, c1, c2), dtype=np.int8)
    n = 0
    for i in range(c0):
        for j in range(c1):
            for k in range(c2):
                s = parent[i >> 1, j >> 1, k >> 1]
                state[i, j, k] = s
                n += s == SAMPLED
    return state, _sampled_in(state, n)


@njit(**KERNEL)
def sampled_blocks(state):
    """The uncertain (sampled) blocks of ``state``, ``(n, 3)`` in C order (``np.argwhere``'s,
    always C-contiguous), and each block's number among them (-1 for the others)."""
    number = np.full(state.shape, -1, dtype=np.int32)
    n = 0
    for i in range(state.shape[0]):
        for j in range(state.shape[1]):
            for k in range(state.shape[2]):
                if state[i, j, k] == SAMPLED:
                    number[i, j, k] = n
                    n += 1
    return _sampled_in(state, n), number


@njit(**KERNEL)
def _sampled_in(state, n):
    """The ``n`` uncertain blocks of ``state`` in C order."""
    todo = np.empty((n, 3), dtype=np.int64)
    t = 0
    for i in range(state.shape[0]):
        for j in range(state.shape[1]):
            for k in range(state.shape[2]):
                if state[i, j, k] == SAMPLED:
                    todo[t, 0], todo[t, 1], todo[t, 2] = i, j, k
                    t += 1
    return todo


@njit(**KERNEL)
def _boxes(todo, size, cells, ax, ay, az):
    """The closed boxes of blocks ``todo`` of ``size`` cells a side: from their first grid
    point to their last (the grid's last, where it cuts them)."""
    n = todo.shape[0]
    lo = np.empty((n, 3))
    hi = np.empty((n, 3))
    for t in range(n):
        for a in range(3):
            axis = ax if a == 0 else (ay if a == 1 else az)
            first = todo[t, a] * size
            lo[t, a] = axis[first]
            hi[t, a] = axis[min(first + size, cells[a])]
    return lo, hi


@njit(**KERNEL)
def _decide(state, todo, flo, fhi, finite, level):
    """Each block's state from its bounds: outside above the level, inside finite below it."""
    for t in range(todo.shape[0]):
        s = SAMPLED
        if flo[t] > level:
            s = OUTSIDE
        if finite[t] and fhi[t] < level:
            s = INSIDE
        state[todo[t, 0], todo[t, 1], todo[t, 2]] = s
