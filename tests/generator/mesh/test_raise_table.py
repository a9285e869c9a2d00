"""The raises' table and worklist (generator/mesh/raise_table.py) and the worklist's runs of the
dense and sparse raises (generator/mesh/marching.py, generator/mesh/sparse_bricks.py)."""

from __future__ import annotations

import numpy as np

from surfgen.generator.eval.brick_lookup import locate
from surfgen.generator.mesh import marching, sparse_bricks
from surfgen.generator.mesh.raise_table import POPS, find, seeded, with_room
from tests.support.refcounts import kernel_ir, refcounts_in_loops


def test_seeded_raises_each_edge_both_ways_without_growing():
    # edge (10, 11): 10 is short of 11 (raised to ratio * 4); edge (11, 12): 12 short of the
    # 11's own magnitude; edge (20, 21): both within the ratio of each other, none raised
    ta = np.array([10, 11, 20], dtype=np.int64)
    tb = np.array([11, 12, 21], dtype=np.int64)
    ma = np.array([0.001, 4.0, 1.0])
    mb = np.array([4.0, 0.002, 1.0])
    keys, mags, stack, top, n = seeded(ta, tb, ma, mb, 0.5)
    assert n == top == 2 and sorted(stack[:top]) == [10, 12]
    assert mags[find(keys, 10)] == 2.0 and mags[find(keys, 12)] == 2.0
    assert keys[find(keys, 20)] == -1
    assert 2 * n <= keys.size and stack.size >= 2 * ta.size  # room for every edge's two


def test_with_room_keeps_the_entries_and_makes_room_for_a_run():
    rng = np.random.default_rng(4)
    samples = rng.choice(10**6, size=40, replace=False).astype(np.int64)
    keys = np.full(64, -1, dtype=np.int64)
    mags = np.empty(64)
    for g in samples:
        h = find(keys, g)
        keys[h], mags[h] = g, float(g) / 7
    stack = samples[:5].copy()  # a worklist of 5, no room left
    keys2, mags2, stack2 = with_room(keys, mags, stack, 5, 40)
    assert keys2.size >= 2 * (40 + 6 * POPS)  # half full at most after a run's pushes
    assert stack2.size >= 5 + 6 * POPS and np.array_equal(stack2[:5], samples[:5])
    for g in samples:
        h = find(keys2, g)
        assert keys2[h] == g and mags2[h] == float(g) / 7
    same = with_room(keys2, mags2, stack2, 5, 40)  # room already: the same arrays
    assert all(a is b for a, b in zip(same, (keys2, mags2, stack2), strict=True))


def test_the_worklist_runs_count_no_references():
    # no array reassigned in a run, the table's helpers and locate with one exit: numba
    # counts no reference per sample (42 atomic counts in the sparse raise's loops before)
    keys = np.full(64, -1, dtype=np.int64)
    mags, stack = np.zeros(64), np.zeros(64, dtype=np.int64)
    top, n = np.int64(0), np.int64(0)
    dense = kernel_ir(marching._raise_run.py_func, keys, mags, stack, top, n,
                      np.zeros((9, 9, 9), np.float32), np.int64(0))  # fmt: skip
    sparse = kernel_ir(sparse_bricks._raise_run.py_func, keys, mags, stack, top, n,
                       np.zeros((1, 9, 9, 9), np.float32), np.zeros((1, 1, 1), np.int64),
                       np.int64(8), np.array([8, 8, 8], dtype=np.int64))  # fmt: skip
    assert refcounts_in_loops(dense) == 0
    assert refcounts_in_loops(sparse) == 0


def _locate_all(slot, block, points):
    total = 0
    for q in range(points.shape[0]):
        s, a, b, c = locate(slot, block, points[q, 0], points[q, 1], points[q, 2])
        total += s + a + b + c
    return total


def test_locate_in_a_loop_counts_no_references():
    slot = np.zeros((2, 2, 2), dtype=np.int64)
    body = kernel_ir(_locate_all, slot, np.int64(8), np.zeros((3, 3), dtype=np.int64))
    assert refcounts_in_loops(body) == 0
