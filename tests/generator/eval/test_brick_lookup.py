"""The bricks' lookup: a grid index's leaf and place in it, and the brick holding a point."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from surfgen.generator.eval.brick_lookup import leaf_of, locate
from surfgen.generator.eval.sparse import MAX_BLOCK


@njit(cache=False)
def _leaves(indices, block):
    out = np.empty((indices.size, 2), dtype=np.int64)
    for p in range(indices.size):
        q = leaf_of(indices[p], indices[p], indices[p], block)
        out[p, 0], out[p, 1] = q[0], q[3]
    return out


@njit(cache=False)
def _located(slot, block, points):
    out = np.empty((points.shape[0], 4), dtype=np.int64)
    for p in range(points.shape[0]):
        out[p] = locate(slot, block, points[p, 0], points[p, 1], points[p, 2])
    return out


@pytest.mark.parametrize("block", range(1, MAX_BLOCK + 1))
def test_leaf_of_is_floor_division_and_remainder(block):
    """Shifts for the powers of two, divisions for the others: both Python's floor division
    and remainder, negative indices included (a neighbour before the grid's first point)."""
    indices = np.arange(-3 * block - 5, 9 * block + 7, dtype=np.int64)
    got = _leaves(indices, block)
    assert np.array_equal(got[:, 0], indices // block)
    assert np.array_equal(got[:, 1], indices % block)


@pytest.mark.parametrize("block", [4, 6, 8])
def test_locate_finds_a_brick_holding_the_point(block):
    """Against a search of every brick: a point is found (with its place in the brick) where
    some brick's closed box holds it, before, inside and past the grid; -1 elsewhere."""
    rng = np.random.default_rng(block)
    leaves = (3, 4, 3)
    slot = np.full(leaves, -1, dtype=np.int32)
    chosen = rng.random(leaves) < 0.4
    slot[chosen] = np.arange(int(chosen.sum()), dtype=np.int32)
    corner = np.argwhere(chosen) * block  # brick s's first point (slot numbers in C order)
    shape = np.array(leaves) * block + 1
    axes = [np.arange(-2, n + 2) for n in shape]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3).astype(np.int64)
    got = _located(slot, block, points)
    offsets = points[:, None, :] - corner[None, :, :]  # (P, K, 3)
    holds = np.all((offsets >= 0) & (offsets <= block), axis=2)
    found = got[:, 0] >= 0
    assert np.array_equal(found, holds.any(axis=1))
    rows = np.flatnonzero(found)
    assert holds[rows, got[rows, 0]].all()
    assert np.array_equal(got[rows, 1:], offsets[rows, got[rows, 0]])
