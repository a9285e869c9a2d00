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
from surfgen.generator.mesh.sparse_lewiner import grown

_ONE = np.int64(1)  # room the worklist needs for its next entry (an int64, not a literal)


@njit(**INLINE)
def seeded(ta, tb, ma, mb, ratio):
    """The table and worklist after the crossing edges ``(ta, tb)`` that need a raise, with
    their samples' magnitudes ``(ma, mb)``, each tried both ways: a sample short of ``ratio``
    times the other's magnitude (the other's raised one where it was raised) is raised to it.
    Returns ``keys, mags, stack, top, n`` (:func:`push`)."""
    keys, mags, stack, top, n = _new_table(ta.size)
    for e in range(2 * ta.size):
        # each edge both ways: a from b, then b from (the raised) a
        q = e // 2
        x, y, mx, my = (ta[q], tb[q], ma[q], mb[q]) if e % 2 == 0 else (tb[q], ta[q], mb[q], ma[q])
        hy = find(keys, y)
        need = ratio * (mags[hy] if keys[hy] == y else my)
        h = find(keys, x)
        if need <= (mags[h] if keys[h] == x else mx):
            continue
        keys, mags, stack, top, n = push(keys, mags, stack, top, n, h, x, need)
    return keys, mags, stack, top, n


@njit(**INLINE)
def _new_table(count):
    """An empty table with room for ``count`` entries at most a quarter full, and an empty
    worklist: ``keys, mags, stack, top, n`` (``n``: the entries)."""
    size = 64
    while size < 4 * count:
        size *= 2
    keys = np.full(size, -1, dtype=np.int64)
    return keys, np.empty(size), np.empty(64, dtype=np.int64), 0, 0


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


@njit(**INLINE)
def push(keys, mags, stack, top, n, h, x, need):
    """Raise sample ``x`` (slot ``h`` of the table) to ``need`` and put it on the worklist;
    returns the table (grown when half full), the worklist, its top and the raised count."""
    if keys[h] != x:
        keys[h] = x
        n += 1
    mags[h] = need
    if top == stack.size:
        stack = grown(stack, np.int64(top), _ONE)
    stack[top] = x
    top += 1
    if 2 * n > keys.size:
        keys, mags = _rehash(keys, mags)
    return keys, mags, stack, top, n
