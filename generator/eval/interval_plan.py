"""The planning of :func:`~surfgen.generator.eval.interval_kernels.run_boxes`, compiled.

:func:`plan_kernel` finds, for a chunk of boxes, the items of each level of the program (one per
distinct combination of the boxes' ranges on the level's axes) and where each item reads the
items of its sub-levels; :func:`range_tables` and :func:`range_reduce_into` bound a one-axis
level over the grid's coordinates in a range (a sparse table: any range is two windows), one
rule for the minimum of +0 and -0 on every CPU (:func:`_pick`).  In numpy, on small arrays,
these took more than half of a sparse classification's time (sculpture-1 at 512^3: the items
4.7 ms and the ranges 2.5 of 13.3 ms, the bounds' own kernel 2.7).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.eval.point_driver import dedupe
from surfgen.generator.jit.options import INLINE, KERNEL


@njit(**KERNEL)
def plan_kernel(blo, bhi, share):
    """``(counts, offsets, item_map, firsts)`` of :func:`~.intervals.plan_levels` for boxes
    ``[blo[k], bhi[k]]`` (``(K, 3)`` C-contiguous float64): ``firsts[lv, :counts[lv]]`` a box
    of each item of level lv, in order of first appearance (the item's number)."""
    K = blo.shape[0]
    inverse = np.empty((8, K), dtype=np.int64)
    firsts = np.empty((8, K), dtype=np.int64)
    counts = np.zeros(8, dtype=np.int64)
    for lv in range(1, 8):
        for k in range(K):
            inverse[lv, k] = k
            firsts[lv, k] = k
        counts[lv] = K
    if share:
        axis_ids = np.empty((3, K), dtype=np.int64)
        axis_count = np.empty(3, dtype=np.int64)
        column = np.empty(K, dtype=np.float64)
        for a in range(3):
            for k in range(K):
                column[k] = blo[k, a]
            lo_ids, _ = dedupe(column.view(np.int64))  # a range told by its bits
            for k in range(K):
                column[k] = bhi[k, a]
            hi_ids, hi_first = dedupe(column.view(np.int64))
            ids, first = dedupe(lo_ids * hi_first.size + hi_ids)
            axis_ids[a] = ids
            axis_count[a] = first.size
        key = np.empty(K, dtype=np.int64)
        for lv in range(1, 7):
            key[:] = 0
            for a in range(3):
                if lv >> a & 1:
                    for k in range(K):
                        key[k] = key[k] * axis_count[a] + axis_ids[a, k]
            ids, first = dedupe(key)
            inverse[lv] = ids
            firsts[lv, : first.size] = first
            counts[lv] = first.size
    offsets = np.zeros(8, dtype=np.int64)
    for lv in range(1, 8):
        offsets[lv] = offsets[lv - 1] + counts[lv - 1]
    item_map = np.zeros((8, offsets[7] + counts[7]), dtype=np.int64)
    for lv in range(1, 8):
        for sub in range(1, 8):
            if sub & ~lv == 0:  # the levels of lv's axes (lv itself too)
                for i in range(counts[lv]):
                    item_map[sub, offsets[lv] + i] = offsets[sub] + inverse[sub, firsts[lv, i]]
    return counts, offsets, item_map, firsts


@njit(**INLINE)
def _pick(x, y, take_max):
    """The minimum (maximum with ``take_max``) of ``x`` and ``y``, NaN where either is NaN;
    of two equal values (+0 and -0) the first, whatever the CPU (numpy's vector and scalar
    loops differ there)."""
    if x != x:
        return x
    if take_max:
        return x if x >= y else y
    return x if x <= y else y


@njit(**KERNEL)
def range_tables(rows, take_max):
    """A sparse table of ``rows`` ``(depth, n)``: ``table[j, :, c]`` is the minimum (maximum
    with ``take_max``) of the columns ``c : c + 2**j`` (:func:`_pick`; ``j`` up to
    ``log2(n)``; columns past ``n - 2**j`` are never read), so any range is that of two
    windows."""
    depth, n = rows.shape
    levels = 1
    while (1 << levels) <= n:
        levels += 1
    table = np.empty((levels, depth, n), dtype=rows.dtype)
    table[0] = rows
    width = 1
    for j in range(1, levels):
        for r in range(depth):
            for c in range(n):
                x = table[j - 1, r, c]
                table[j, r, c] = (
                    _pick(x, table[j - 1, r, c + width], take_max) if c + width < n else x
                )
        width *= 2
    return table


@njit(**KERNEL)
def range_reduce_into(table, first, last, take_max, empty, out, c0):
    """The minimum (maximum with ``take_max``) over columns ``first[i] : last[i]`` of the rows
    of :func:`range_tables`' ``table``, into ``out[:, c0 + i]`` (``empty`` for a range
    without a column)."""
    depth = table.shape[1]
    for i in range(first.size):
        a = first[i]
        b = last[i]
        if b <= a:
            for r in range(depth):
                out[r, c0 + i] = empty
            continue
        length = b - a
        j = 0
        while (2 << j) <= length:
            j += 1
        b = b - (1 << j)
        for r in range(depth):
            out[r, c0 + i] = _pick(table[j, r, a], table[j, r, b], take_max)
