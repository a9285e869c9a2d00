"""The table of raised magnitudes the crossings' raises keep (dense: :func:`~.marching._separate`;
sparse: :func:`~.sparse_bricks.raise_bricks`).

A raise visits the few samples whose magnitude must grow so that every crossing stays
:data:`~.marching.SEPARATION` of its edge from both samples, one at a time from a worklist,
and keeps each raised sample's magnitude in float64 (the rounding to float32 comes once, at
the end): an open-addressing hash table of flat sample numbers (``keys``, -1 for an empty slot)
and their magnitudes (``mags``), grown when half full, and the worklist's stack of samples.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.jit.options import INLINE, KERNEL
from surfgen.generator.mesh.growing import grown

#: Samples a run of the raises' worklist takes from it at most (:func:`with_room` makes room
#: for what they may put back on it, six neighbours each, before the run).
POPS = np.int64(256)


@njit(**INLINE)
def seeded(ta, tb, ma, mb, ratio):
    """The table and worklist after the crossing edges ``(ta, tb)`` that need a raise, with
    their samples' magnitudes ``(ma, mb)``, each tried both ways: a sample short of ``ratio``
    times the other's magnitude (the other's raised one where it was raised) is raised to it.
    Returns ``keys, mags, stack, top, n`` (:func:`push`). Sized for every edge's two samples
    (the table half full at most, the worklist as long): nothing grows while they are
    pushed."""
    keys, mags, stack = _new_table(ta.size)
    top = n = 0
    for e in range(2 * ta.size):
        # each edge both ways: a from b, then b from (the raised) a
        q = e // 2
        x, y, mx, my = (ta[q], tb[q], ma[q], mb[q]) if e % 2 == 0 else (tb[q], ta[q], mb[q], ma[q])
        hy = find(keys, y)
        need = ratio * (mags[hy] if keys[hy] == y else my)
        h = find(keys, x)
        if need <= (mags[h] if keys[h] == x else mx):
            continue
        top, n = push(keys, mags, stack, top, n, h, x, need)
    return keys, mags, stack, top, n


@njit(**INLINE)
def _new_table(count):
    """An empty table with room for ``2 count`` entries at most half full, and a worklist of
    that length: ``keys, mags, stack``."""
    size = 64
    while size < 4 * count:
        size *= 2
    keys = np.full(size, -1, dtype=np.int64)
    return keys, np.empty(size), np.empty(2 * count + POPS, dtype=np.int64)


@njit(**INLINE)
def find(keys, g):
    """The slot of sample ``g`` in the open-addressing table ``keys`` (-1: empty)."""
    mask = keys.size - 1
    h = np.int64((np.uint64(g) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(17)) & mask
    while keys[h] != -1 and keys[h] != g:
        h = (h + 1) & mask
    return h


@njit(**KERNEL)
def _rehash(keys, mags):
    """The table twice as large, with the same entries."""
    out_keys = np.full(2 * keys.size, -1, dtype=np.int64)
    out_mags = np.empty(2 * keys.size)
    for h in range(keys.size):
        if keys[h] != -1:
            q = find(out_keys, keys[h])
            out_keys[q] = keys[h]
            out_mags[q] = mags[h]
    return out_keys, out_mags


@njit(**KERNEL)
def with_room(keys, mags, stack, top, n):
    """The table and worklist with room for a run of :data:`POPS` samples' pushes (six
    neighbours each): the table then at most half full, the worklist long enough. Between
    runs, so that no array is reassigned within one (numba would count references to each at
    every sample: 42 atomic counts in the sparse raise's loops; with :func:`push` branch-free
    and :func:`~surfgen.generator.eval.brick_lookup.locate` of one exit, none: sculpture-1's
    20,000 edges at 512^3 8.6 -> 5.7 ms, sculpture-0's 130,000 62.8 -> 54.2 ms, their table's
    cache misses the rest)."""
    more = 6 * POPS
    while 2 * (n + more) > keys.size:
        keys, mags = _rehash(keys, mags)
    if top + more > stack.size:
        stack = grown(stack, np.int64(top), more)
    return keys, mags, stack


@njit(**INLINE)
def push(keys, mags, stack, top, n, h, x, need):
    """Raise sample ``x`` (slot ``h`` of the table) to ``need`` and put it on the worklist,
    which has room for it (:func:`with_room`); returns the worklist's top and the raised
    count. Without a branch: inlined with one, it left numba counting references to the
    arrays at every push."""
    added = np.int64(keys[h] != x)
    keys[h] = x
    mags[h] = need
    stack[top] = x
    return top + 1, n + added
