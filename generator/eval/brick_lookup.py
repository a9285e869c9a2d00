"""Where a sparse field's bricks hold a grid point (:class:`~.sparse.SparseField`'s lookup).

A sampled leaf's brick holds the ``(BLOCK + 1)**3`` grid points of its closed box, so a point
on a leaf's face is in up to eight bricks, all with the same sample. ``slot`` maps each leaf
to its brick (-1: not sampled), ``corner`` each brick to its first grid point; the sparse
meshing's passes (:mod:`~surfgen.generator.mesh.sparse_bricks`,
:mod:`~surfgen.generator.mesh.sparse_marching`) find samples with :func:`locate`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.jit.options import INLINE, KERNEL

#: Per leaf size (0 to 64, :data:`~.sparse.MAX_BLOCK` at most), the exponent of the power of
#: two it is, -1 for the sizes that are none.
_SHIFTS = np.array([b.bit_length() - 1 if b > 0 and b & (b - 1) == 0 else -1 for b in range(65)])


@njit(**INLINE)
def leaf_of(i, j, k, block):
    """The leaf holding grid index ``(i, j, k)`` (``index // block`` per axis) and the index's
    place in it (``index % block``): by shifts for a leaf size that is a power of two
    (:data:`~.sparse.BLOCK`), as a floor division does for negative indices too. Three
    divisions a lookup took a seventh of the raises' time (5.9 -> 5.0 ms, sculpture-1 at
    512^3) and of the walls' line reading."""
    shift = _SHIFTS[block]
    if shift >= 0:
        b0, b1, b2 = i >> shift, j >> shift, k >> shift
    else:
        b0, b1, b2 = i // block, j // block, k // block
    return b0, b1, b2, i - b0 * block, j - b1 * block, k - b2 * block


@njit(**INLINE)
def holder(slot, block, b0, b1, b2, r0, r1, r2, d):
    """Candidate ``d`` (0-7) of the up to 8 bricks that may hold a grid point in leaf
    ``(b0, b1, b2)`` at place ``(r0, r1, r2)`` (:func:`leaf_of`): the leaf itself for 0, the
    lower neighbour along i, j, k where bit 2, 1, 0 of ``d`` is set (holding the point only
    where it is on that face). Returns the brick and the point's place in it, brick -1 where
    that leaf is past the grid, not sampled, or the point not on its face. One exit (see
    :func:`locate`)."""
    n0, n1, n2 = slot.shape
    d0, d1, d2 = d >> 2, (d >> 1) & 1, d & 1
    c0, c1, c2 = b0 - d0, b1 - d1, b2 - d2
    on_faces = (d0 == 0 or r0 == 0) and (d1 == 0 or r1 == 0) and (d2 == 0 or r2 == 0)
    inside = 0 <= c0 < n0 and 0 <= c1 < n1 and 0 <= c2 < n2
    s = np.int64(slot[c0, c1, c2]) if on_faces and inside else np.int64(-1)
    return s, r0 + d0 * block, r1 + d1 * block, r2 + d2 * block


@njit(**INLINE)
def locate(slot, block, i, j, k):
    """The brick holding grid point ``(i, j, k)`` and the point's place in it, or brick -1.

    A point on a leaf's face is in up to 8 bricks (all hold the same value, :func:`holder`);
    the one of the leaf ``index // block`` is tried first, then the lower neighbours where the
    point is on their face.  One exit, at the end: an inlined helper given an array that
    returns from within its loops leaves numba counting references to the array at every
    call in the caller's loops (the raises' worklist: six a sample)."""
    b0, b1, b2, r0, r1, r2 = leaf_of(i, j, k, block)
    found, a, b, c = np.int64(-1), np.int64(0), np.int64(0), np.int64(0)
    for d in range(8):
        if found < 0:
            found, a, b, c = holder(slot, block, b0, b1, b2, r0, r1, r2, d)
    return found, a, b, c


@njit(**INLINE)
def sample_at(i, j, k, slot, corner, values, block):
    """F at grid point ``(i, j, k)``, NaN where no brick holds it (:func:`locate`)."""
    s, li, lj, lk = locate(slot, block, i, j, k)
    if s < 0:
        return np.nan
    return values[s, li, lj, lk]


@njit(**KERNEL)
def values_at(ii, jj, kk, slot, corner, values, block, out):
    """``out[p]``: :func:`sample_at` of point ``(ii[p], jj[p], kk[p])``."""
    for p in range(ii.size):
        out[p] = sample_at(ii[p], jj[p], kk[p], slot, corner, values, block)


@njit(**KERNEL)
def sampled_at(ii, jj, kk, slot, block, out):
    """``out[p]``: whether a brick holds point ``(ii[p], jj[p], kk[p])`` (:func:`locate`)."""
    for p in range(ii.size):
        out[p] = locate(slot, block, ii[p], jj[p], kk[p])[0] >= 0
