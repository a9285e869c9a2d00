"""The sparse path's passes over the bricks (:mod:`~surfgen.generator.mesh.sparse_marching`):
the offsets, the crossings kept apart, and the mixed cells with their corners.

Each is what the dense path's step (:mod:`~surfgen.generator.mesh.marching`) gives at every
sample the bricks hold, in as few passes over the bricks as the steps allow, with nothing the
size of the grid or of its crossing edges:

- :func:`brick_offsets`: the float32 offsets (:func:`~.marching.offset_of`, the dense kernel's
  per-sample rule); a sample is inside exactly when its offset is negative, so no inside mask
  is kept;
- :func:`scan_bricks`: the mixed cells counted, and the crossing edges that need a raise
  (:func:`~.marching.too_near`) listed: usually few;
- :func:`raise_bricks`: the magnitudes raised from those edges only, sample by sample (a
  worklist), to the dense path's values: the least solution of ``m[a] >= _RATIO m[b]`` over
  the crossing edges, which does not depend on the order the edges are visited in;
- :func:`brick_cells`: the mixed cells in skimage's order with their corners.

A cell is mixed when its corners are neither all inside nor all outside; the scan and the
listing find them from bit masks of the inside samples of a brick's rows along its last axis
(:func:`_mixed`: a row of cells from four masks), and look at the samples only where a row
has a mixed cell or a crossing edge.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.eval.brick_lookup import holder, leaf_of, locate
from surfgen.generator.eval.tape import run_at_once
from surfgen.generator.jit.options import INLINE, KERNEL
from surfgen.generator.mesh.growing import grown
from surfgen.generator.mesh.marching import _RATIO, offset_of, too_near
from surfgen.generator.mesh.raise_table import POPS, find, push, seeded, with_room

#: Bricks per thread at least (a brick's pass takes about a microsecond: 13,000 bricks of
#: sculpture-1 at 512^3 in 11 ms).
RUN_BRICKS = 2000
_ONE = np.int64(1)  # room a growing list needs for its next entry (an int64, not a literal)


def brick_offsets(values, extent, level, threads: int = 1) -> tuple[np.ndarray, int]:
    """The bricks' float32 offsets (:func:`~.marching.offset_of`: non-finite samples are left
    NaN or clipped for the mirror) and the number of non-finite samples within the bricks'
    extents (entries past the grid's end get offsets too, never read); ``threads`` take runs
    of bricks."""
    offset = np.empty(values.shape, dtype=np.float32)
    bad = run_at_once(
        [
            lambda a=a, b=b: _offsets_of(values, extent, level, offset, a, b)
            for a, b in brick_runs(len(values), threads)
        ]
    )
    return offset, sum(bad)


def brick_runs(n_bricks: int, threads: int, least: int = RUN_BRICKS) -> list[tuple[int, int]]:
    """``threads`` runs of about equal numbers of bricks (or of other items: one run where
    there are fewer than ``least`` per thread), as ``(first, end)``."""
    n = max(1, min(int(threads), n_bricks // least))
    bounds = [n_bricks * r // n for r in range(n + 1)]
    return list(zip(bounds[:-1], bounds[1:], strict=True))


@njit(**KERNEL)
def _offsets_of(values, extent, level, offset, b0, b1):
    """:func:`brick_offsets` of bricks ``b0:b1`` into ``offset``; returns their non-finite
    samples. A brick is one run of samples (which the compiler vectorises: 15 -> 10 ms a
    thread for sculpture-1 at 512^3); a brick cut by the grid's end with a non-finite sample
    counts them again within its extent."""
    _, m0, m1, m2 = values.shape
    size = m0 * m1 * m2
    n_bad = 0
    for b in range(b0, b1):
        run, out = values[b].reshape(size), offset[b].reshape(size)
        bad = 0
        for q in range(size):
            x = run[q]
            out[q] = offset_of(x, level)[0]
            bad += np.int64(not abs(x) < np.inf)
        e0, e1, e2 = extent[b, 0], extent[b, 1], extent[b, 2]
        if bad and (e0 < m0 or e1 < m1 or e2 < m2):
            bad = 0
            for i in range(e0):
                for j in range(e1):
                    for k in range(e2):
                        bad += np.int64(not np.isfinite(values[b, i, j, k]))
        n_bad += bad
    return n_bad


def scan_bricks(offset, extent, corner, shape, threads: int = 1):
    """The number of mixed cells of each brick (int64), the crossing edges of the bricks that
    need a raise (``|a| < _RATIO |b|`` or the reverse) as global flat sample numbers ``(a, b)``
    (an edge on a face shared by two bricks twice), in brick order, with the two samples'
    magnitudes (float64 ``|a|``, ``|b|``: what the raises start from), and the bricks' row
    masks (:func:`_row_mask`; int16 where a row fits, else int64), which the raises leave as
    they are (they keep every sample's side) and the cells' listing reads
    (:func:`brick_cells`); ``threads`` take runs of bricks."""
    per = np.empty(len(offset), dtype=np.int64)
    masks = np.empty(offset.shape[:3], dtype=np.int16 if offset.shape[3] < 16 else np.int64)
    parts = run_at_once(
        [
            lambda a=a, b=b: _scan(offset, extent, corner, shape, per, masks, a, b)
            for a, b in brick_runs(len(offset), threads)
        ]
    )
    if len(parts) == 1:
        return (per, *parts[0], masks)
    return (per, *(np.concatenate([p[q] for p in parts]) for q in range(4)), masks)


@njit(**KERNEL)
def _scan(offset, extent, corner, shape, per, masks, b0, b1):
    """:func:`scan_bricks` of bricks ``b0:b1`` (their counts into ``per``, their row masks
    into ``masks``). Each row of a brick along its last axis is a bit mask of its inside
    samples (:func:`_row_mask`), so a pair of rows' mixed cells and a row's crossing edges
    are a few operations on masks, and only a crossing is looked at sample by sample
    (sculpture-1 at 512^3: 32 -> 15 ms a thread, against the flags summed column by
    column)."""
    rows = np.empty((offset.shape[1], offset.shape[2]), dtype=np.int64)
    ta = np.empty(64, dtype=np.int64)
    tb = np.empty(64, dtype=np.int64)
    ma = np.empty(64)
    mb = np.empty(64)
    m = 0
    s1, s2 = shape[1] * shape[2], shape[2]
    for b in range(b0, b1):
        e0, e1, e2 = extent[b, 0], extent[b, 1], extent[b, 2]
        for i in range(e0):
            for j in range(e1):
                rows[i, j] = _row_mask(offset, b, i, j, e2)
                masks[b, i, j] = rows[i, j]
        n_cells = 0
        for i in range(e0 - 1):
            for j in range(e1 - 1):
                n_cells += _bits(
                    _mixed(rows[i, j], rows[i, j + 1], rows[i + 1, j], rows[i + 1, j + 1], e2)
                )
        per[b] = n_cells
        along = (np.int64(1) << (e2 - 1)) - 1  # the samples with a next one on the row
        c0, c1, c2 = corner[b, 0], corner[b, 1], corner[b, 2]
        for i in range(e0):
            for j in range(e1):
                r = rows[i, j]
                cx = r ^ rows[i + 1, j] if i + 1 < e0 else np.int64(0)
                cy = r ^ rows[i, j + 1] if j + 1 < e1 else np.int64(0)
                cz = (r ^ (r >> 1)) & along
                crossing = cx | cy | cz
                if crossing == 0:
                    continue
                g0 = (c0 + i) * s1 + (c1 + j) * s2 + c2
                for k in range(e2):
                    if not (crossing >> k) & 1:
                        continue
                    here = abs(np.float64(offset[b, i, j, k]))
                    for axis in range(3):
                        if axis == 0:
                            cross, o, step = cx, offset[b, i + 1, j, k], s1
                        elif axis == 1:
                            cross, o, step = cy, offset[b, i, j + 1, k], s2
                        else:
                            cross, o, step = cz, offset[b, i, j, k + 1], 1
                        if not (cross >> k) & 1 or not too_near(here, abs(np.float64(o))):
                            continue
                        if m == ta.size:
                            ta = grown(ta, np.int64(m), _ONE)
                            tb = grown(tb, np.int64(m), _ONE)
                            ma = grown(ma, np.int64(m), _ONE)
                            mb = grown(mb, np.int64(m), _ONE)
                        ta[m], tb[m] = g0 + k, g0 + k + step
                        ma[m], mb[m] = here, abs(np.float64(o))
                        m += 1
    return ta[:m], tb[:m], ma[:m], mb[:m]


@njit(**INLINE)
def _row_mask(offset, b, i, j, n):
    """Bit ``k`` set where sample ``(i, j, k)`` of brick ``b`` is inside, for ``k < n``."""
    r = np.int64(0)
    for k in range(n):
        r |= np.int64(offset[b, i, j, k] < 0) << k
    return r


@njit(**INLINE)
def _mixed(r0, r1, r2, r3, n):
    """Bit ``k`` set where cell ``k`` between four neighbouring rows (their masks, ``n``
    samples each) is mixed: it is all inside when bits ``k`` and ``k + 1`` are set in every
    row, all outside when they are set in none."""
    every, some = r0 & r1 & r2 & r3, r0 | r1 | r2 | r3
    return ~(every & (every >> 1)) & (some | (some >> 1)) & ((np.int64(1) << (n - 1)) - 1)


@njit(**INLINE)
def _bits(x):
    """The number of bits set in ``x`` (non-negative)."""
    x = x - ((x >> 1) & 0x5555555555555555)
    x = (x & 0x3333333333333333) + ((x >> 2) & 0x3333333333333333)
    x = (x + (x >> 4)) & 0x0F0F0F0F0F0F0F0F
    return (x * 0x0101010101010101) >> 56


# ----------------------------------------------------------------------------- raises


@njit(**KERNEL)
def raise_bricks(ta, tb, ma, mb, offset, slot, block, shape):
    """:func:`~.marching._raise_from` on the bricks, in place, from the crossing edges
    ``(ta, tb)`` that need a raise, with their samples' magnitudes ``(ma, mb)``
    (:func:`scan_bricks`: the first pass over the edges reads no brick): the magnitudes in float64 end as
    the least solution of ``m[a] >= _RATIO m[b]`` on every crossing edge above the samples'
    own, the dense path's (the least solution, whatever the order the edges come in).  An
    edge raises a sample that is short of it; a raised sample puts its crossing edges (the
    neighbours on the other side that a brick holds: an edge no brick holds lies in an
    unsampled leaf, on one side) to the test again (:func:`_raise_run`).  The raised samples,
    rounded to float32 with their sign, are written to every brick holding them.  Returns how
    many were raised."""
    s1, s2 = shape[1] * shape[2], shape[2]
    keys, mags, stack, top, n = seeded(ta, tb, ma, mb, _RATIO)  # raised samples -> magnitudes
    while top > 0:
        keys, mags, stack = with_room(keys, mags, stack, top, n)
        top, n = _raise_run(keys, mags, stack, top, n, offset, slot, block, shape)
    for h in range(keys.size):
        g = keys[h]
        if g == -1:
            continue
        i, j, k = g // s1, (g // s2) % shape[1], g % s2
        _write_raised(offset, slot, block, i, j, k, np.float32(mags[h]))
    return n


@njit(**KERNEL)
def _raise_run(keys, mags, stack, top, n, offset, slot, block, shape):
    """Up to :data:`~.raise_table.POPS` samples taken off the worklist (which has room for
    what they put back, :func:`~.raise_table.with_room`), each putting its neighbours across a
    crossing edge that are short of its raised magnitude times the ratio back on it; returns
    the worklist's top and the raised count."""
    s1, s2 = shape[1] * shape[2], shape[2]
    for _ in range(POPS):
        if top == 0:
            break
        top -= 1
        g = stack[top]
        i, j, k = g // s1, (g // s2) % shape[1], g % s2
        need = _RATIO * mags[find(keys, g)]
        s0, l0, l1, l2 = locate(slot, block, i, j, k)
        neg = offset[s0, l0, l1, l2] < 0
        for d in range(6):
            a, c, f = i, j, k
            la, lc, lf = l0, l1, l2
            if d == 0:
                a, la = a - 1, la - 1
            elif d == 1:
                a, la = a + 1, la + 1
            elif d == 2:
                c, lc = c - 1, lc - 1
            elif d == 3:
                c, lc = c + 1, lc + 1
            elif d == 4:
                f, lf = f - 1, lf - 1
            else:
                f, lf = f + 1, lf + 1
            if a < 0 or c < 0 or f < 0 or a >= shape[0] or c >= shape[1] or f >= shape[2]:
                continue
            if min(la, lc, lf) >= 0 and max(la, lc, lf) <= block:
                s = s0  # in the same brick (a point of the grid there: within its extent)
            else:
                s, la, lc, lf = locate(slot, block, a, c, f)
            if s < 0 or (offset[s, la, lc, lf] < 0) == neg:
                continue
            x = a * s1 + c * s2 + f
            h = find(keys, x)
            if need <= (mags[h] if keys[h] == x else abs(np.float64(offset[s, la, lc, lf]))):
                continue
            top, n = push(keys, mags, stack, top, n, h, x, need)
    return top, n


# The raise's write-back is a function of its own rather than a numba-inlined copy: raise_bricks
# compiles in 3.1-3.6 s instead of 4.7 s alone (3.0 -> 2.4 s within a warm-up).
@njit(**KERNEL)
def _write_raised(offset, slot, block, i, j, k, m):
    """Write the raised magnitude ``m`` with the sample's own sign at grid sample ``(i, j, k)``
    of every brick holding it (they all hold the same sample, :func:`holder`), the leaf found
    once."""
    b0, b1, b2, r0, r1, r2 = leaf_of(i, j, k, block)
    for d in range(8):
        s, a, b, c = holder(slot, block, b0, b1, b2, r0, r1, r2, d)
        if s >= 0:
            offset[s, a, b, c] = -m if offset[s, a, b, c] < 0 else m


# ----------------------------------------------------------------------------- cells


def brick_cells(
    offset, extent, corner, shape, shift, per, masks, pad_keys, pad_corners, threads=1,
    corners=None,
):  # fmt: skip
    """The mixed cells of the bricks (``per``: each brick's count, and ``masks``: their row
    masks, :func:`scan_bricks`) and the pad's cells ``pad_keys`` (sorted, none a brick cell;
    corners ``pad_corners``) in skimage's order (C order of the volume): flat numbers in the
    (padded when ``shift``) volume and their corners in skimage's order
    (:func:`~.sparse_lewiner.lewiner_cells`).

    A *slab* (the bricks of one leaf x, consecutive: the bricks are in C order of their
    leaves) holds the cells of its own planes only, so the list is the slabs' cells one slab
    after the other, the pad's cells merged in by their numbers: a slab's cells start after
    the earlier slabs' and the pad's cells before its first plane. ``threads`` write runs of
    slabs of about equal counts at once (:func:`_slab_cells`), the same list. ``corners``:
    the float32 ``(cells, 8)`` array they are written into (the caller's, on memory done with:
    :func:`~surfgen.generator.allocator.recycled`), or None for a fresh one."""
    n_bricks, n_pad = len(per), len(pad_keys)
    if n_bricks == 0:  # the pad's cells alone
        return np.array(pad_keys, dtype=np.int64), np.array(pad_corners, dtype=np.float32)
    shape = np.asarray(shape, dtype=np.int64)
    slab = np.flatnonzero(np.r_[True, corner[1:, 0] != corner[:-1, 0]])  # each slab's first
    ends = np.r_[slab[1:], n_bricks]
    slab_cells = np.add.reduceat(per, slab)
    # the pad's cells a slab writes: from its first plane (the first slab: all before it) up
    # to the next slab's first plane (the last slab: all after it)
    plane = (shape[1] + 2 * shift) * (shape[2] + 2 * shift)
    q = np.searchsorted(pad_keys, (corner[slab, 0] + shift) * plane)
    q[0] = 0
    q_end = np.r_[q[1:], n_pad]
    done = np.cumsum(slab_cells)  # the cells of the slabs up to each
    m = np.r_[0, done[:-1]] + q
    keys = np.empty(int(per.sum()) + n_pad, dtype=np.int64)
    if corners is None:
        corners = np.empty((len(keys), 8), dtype=np.float32)
    elif corners.shape != (len(keys), 8) or corners.dtype != np.float32:
        raise ValueError(
            f"corners: expected float32 {(len(keys), 8)}, got {corners.dtype} {corners.shape}"
        )
    # runs of whole slabs of about equal cells (at least RUN_BRICKS bricks a thread)
    runs = max(1, min(int(threads), n_bricks // RUN_BRICKS))
    cut = np.searchsorted(done, done[-1] * np.arange(1, runs) / runs, side="right")
    bounds = sorted({0, *cut.tolist(), len(slab)})
    args = (offset, masks, extent, corner, shift, shape, pad_keys, pad_corners, keys, corners,
            slab, ends, m, q, q_end)  # fmt: skip
    run_at_once(
        [
            lambda a=a, b=b: _slab_cells(*args, a, b)
            for a, b in zip(bounds[:-1], bounds[1:], strict=True)
            if b > a
        ]
    )
    return keys, corners


@njit(**KERNEL)
def _slab_cells(offset, masks, extent, corner, shift, shape, pad_keys, pad_corners, keys,
                corners, slab, ends, m_at, q_at, q_end, r0, r1):  # fmt: skip
    """:func:`brick_cells` of slabs ``r0:r1`` (slab ``r``: bricks ``slab[r]:ends[r]``, its
    cells written from ``m_at[r]``, with the pad's cells ``q_at[r]:q_end[r]``): per plane
    ``i`` of a slab, the columns (one ``j`` range each) and, per row ``j``, the column's
    bricks (one ``k`` range each) come in order: no sort."""
    p1 = shape[1] + 2 * shift
    p2 = shape[2] + 2 * shift
    for r in range(r0, r1):
        s0, s1 = slab[r], ends[r]
        m, q, q1 = m_at[r], q_at[r], q_end[r]
        for i in range(extent[s0, 0] - 1):
            c0 = s0
            while c0 < s1:  # a column: the slab's bricks of one leaf y
                c1 = c0
                while c1 < s1 and corner[c1, 1] == corner[c0, 1]:
                    c1 += 1
                for j in range(extent[c0, 1] - 1):
                    for b in range(c0, c1):
                        e2 = extent[b, 2]
                        # the scan's masks (making them again took a third of the listing)
                        mixed = _mixed(np.int64(masks[b, i, j]), np.int64(masks[b, i, j + 1]),
                                       np.int64(masks[b, i + 1, j]),
                                       np.int64(masks[b, i + 1, j + 1]), e2)  # fmt: skip
                        if mixed == 0:
                            continue
                        gi = corner[b, 0] + i + shift
                        gj = corner[b, 1] + j + shift
                        row = (gi * p1 + gj) * p2 + corner[b, 2] + shift
                        for k in range(e2 - 1):
                            if not (mixed >> k) & 1:
                                continue
                            while q < q1 and pad_keys[q] < row + k:
                                keys[m] = pad_keys[q]
                                for c in range(8):  # not a row copy: numba would compile
                                    corners[m, c] = pad_corners[q, c]  # its shape error
                                m += 1
                                q += 1
                            keys[m] = row + k
                            corners[m, 0] = offset[b, i, j, k]
                            corners[m, 1] = offset[b, i, j, k + 1]
                            corners[m, 2] = offset[b, i, j + 1, k + 1]
                            corners[m, 3] = offset[b, i, j + 1, k]
                            corners[m, 4] = offset[b, i + 1, j, k]
                            corners[m, 5] = offset[b, i + 1, j, k + 1]
                            corners[m, 6] = offset[b, i + 1, j + 1, k + 1]
                            corners[m, 7] = offset[b, i + 1, j + 1, k]
                            m += 1
                c0 = c1
        while q < q1:  # the pad's cells after the slab's last cell, before the next slab
            keys[m] = pad_keys[q]
            for c in range(8):
                corners[m, c] = pad_corners[q, c]
            m += 1
            q += 1
