"""Marching cubes' kernels for :func:`surfgen.generator.mesh.mesh.extract_with_edges`.

The signs fixed in float64 and written into the cap's padded array (:func:`_offsets`), the
crossings kept apart (:func:`_separate`: a pass over the edges, then a worklist from the few
that need it) and the cells marching cubes visits: nothing the size of the grid beside the
offsets (the placement and merging of its vertices are in
:mod:`~surfgen.generator.mesh.placement`).
:mod:`surfgen.generator.mesh.mesh` calls them in order.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.jit.options import INLINE, KERNEL
from surfgen.generator.mesh.growing import grown
from surfgen.generator.mesh.raise_table import POPS, find, push, seeded, with_room

# skimage runs marching cubes in float32, so we hand it float32 offsets from the level whose signs
# we have fixed ourselves; magnitudes are clipped to stay finite there.
_CLIP = np.float32(1e30)
_TINY = np.float32(np.finfo(np.float32).smallest_normal)

# Every crossing stays at least this fraction of its edge away from both samples (see
# _separate).  At 1 % of a cell, vertices are >= 0.014 cells apart: far above float32's
# resolution (2.4e-4 cells at index 2048) and the usual "merge close vertices" thresholds
# (1e-6 of the bbox diagonal is 1.7e-6 * (N - 1) cells: 3.5e-3 cells at N = 2048), while the
# geometric error it allows is at most 1 % of a cell.
SEPARATION = 0.01
_RATIO = SEPARATION / (1.0 - SEPARATION) * 1.001  # |a| >= _RATIO |b| gives t >= SEPARATION


_CLIP64 = float(_CLIP)  # np.clip of float64 values against the float32 bound compares in float64
_TINY32 = np.float32(_TINY)


def _offsets(values: np.ndarray, level: float, pad: bool = False) -> tuple[np.ndarray, int]:
    """float32 ``F - level`` with signs decided in float64, and the count of inside samples.

    Inside samples (``F < level``, finite) get a strictly negative offset, all others a strictly
    positive one (or NaN until mirrored), so marching cubes never sees a sample on the level
    (where ``<`` vs ``<=`` would decide the topology), and a sample is inside exactly when its
    offset is negative (no inside mask is kept): offsets rounded to 0 in float32 (below
    ~1e-45) and exact-level samples get the smallest normal float32 with the sign decided in
    float64; magnitudes are clipped to 1e30 to stay finite in float32.  A non-finite sample
    gets a positive value mirroring the deepest inside sample in its 3x3x3 neighbourhood (at
    least the smallest normal), so a crossing on an edge to it falls at mid-edge or nearer the
    inside sample (a huge value would pile the crossings onto the inside samples, +inf
    exactly).  Magnitudes are then raised where needed so every crossing lies at least
    SEPARATION of its edge from both samples (:func:`_separate`).

    ``pad`` (the cap): the offsets come surrounded by one layer of outside samples, each
    mirroring its box neighbour (``|w|`` next to ``w``: every crossing towards the pad lies
    exactly half a cell outside the box, where it is told apart from the crossings inside and
    clamped onto the box), written into one array of two more samples an axis.
    """
    p = 1 if pad else 0
    n0, n1, n2 = values.shape
    offset = np.empty((n0 + 2 * p, n1 + 2 * p, n2 + 2 * p), dtype=np.float32)
    n_inside, n_bad = _offsets_kernel(values, float(level), offset, p)
    if n_bad:
        _mirror_nonfinite(values, offset, p)
    _separate(offset, p)
    if p:
        _pad_border(offset)
    return offset, int(n_inside)


@njit(**KERNEL)
def _offsets_kernel(values, level, offset, p):
    """Fill ``offset`` from ``p`` on along each axis (see :func:`_offsets`; non-finite samples
    are left NaN or clipped for :func:`_mirror_nonfinite`); returns the inside and non-finite
    counts."""
    n0, n1, n2 = values.shape
    n_inside = 0
    n_bad = 0
    for i in range(n0):
        for j in range(n1):
            v = values[i, j]
            out = offset[i + p, j + p]
            for k in range(n2):
                x = v[k]
                o, is_in = offset_of(x, level)
                if is_in:
                    n_inside += 1
                if not np.isfinite(x):
                    n_bad += 1
                out[k + p] = o
    return n_inside, n_bad


@njit(**KERNEL)
def _pad_border(padded):
    """The pad of :func:`_offsets`: each sample of ``padded``'s outer layer takes ``|w|`` of the
    box sample it clamps to."""
    m0, m1, m2 = padded.shape
    for i in range(m0):
        ci = min(max(i, 1), m0 - 2)
        for j in range(m1):
            cj = min(max(j, 1), m1 - 2)
            if i == 0 or i == m0 - 1 or j == 0 or j == m1 - 1:
                for k in range(m2):
                    padded[i, j, k] = abs(padded[ci, cj, min(max(k, 1), m2 - 2)])
            else:
                padded[i, j, 0] = abs(padded[i, j, 1])
                padded[i, j, m2 - 1] = abs(padded[i, j, m2 - 2])


@njit(**INLINE)
def offset_of(x, level):
    """The float32 offset of one sample ``x`` and whether it is inside (:func:`_offsets`' rule;
    a non-finite sample is left NaN or clipped, for :func:`_mirror_nonfinite`).  The inside
    samples' offsets are exactly the negative ones."""
    d = x - level
    d = -_CLIP64 if d < -_CLIP64 else (_CLIP64 if d > _CLIP64 else d)  # NaN stays NaN
    o = np.float32(d)
    # finite and below the level (NaN compares false); both signs' offsets made and one
    # chosen, no branch: a loop over samples vectorises (the bricks' 8.1 -> 5.0 ms a thread)
    is_in = (x < level) & (x > -np.inf)
    o_in = -_TINY32 if o >= 0 else o
    o_out = _TINY32 if o <= 0 else o
    return (o_in if is_in else o_out), is_in


@njit(**KERNEL)
def _mirror_nonfinite(values, offset, p):
    """Each non-finite sample: the largest ``-offset`` of the inside samples (negative offsets)
    in its 3x3x3 neighbourhood (inside the grid), at least the smallest normal float32
    (``offset``'s samples from ``p`` on along each axis)."""
    nx, ny, nz = values.shape
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                if np.isfinite(values[i, j, k]):
                    continue
                deepest = np.float32(0.0)
                for a in range(max(i - 1, 0), min(i + 2, nx)):
                    for b in range(max(j - 1, 0), min(j + 2, ny)):
                        for c in range(max(k - 1, 0), min(k + 2, nz)):
                            if -offset[a + p, b + p, c + p] > deepest:
                                deepest = -offset[a + p, b + p, c + p]
                offset[i + p, j + p, k + p] = max(deepest, _TINY32)


def _separate(offset: np.ndarray, p: int = 0) -> None:
    """Keep every crossing SEPARATION of its edge from both samples of ``offset`` (the grid's
    samples from ``p`` on along each axis: the pad around them comes after), in place: the
    crossing edges that break it listed (:func:`_tight_edges`: usually few), and the
    magnitudes raised from there (:func:`_raise_from`).

    Marching cubes puts the crossing of edge (a, b) at ``t = a / (a - b)``; a sample at or near
    the level next to a large opposite value (staircase plateaus at the level, exact zeros,
    samples beside a pole) would put it on the sample itself, and several crossings would
    coincide there once stored in float32.  Raising a magnitude never changes a sign, so the
    same edges cross; it moves a crossing at most SEPARATION of the edge (in a locally linear
    field the distance to the true surface grows by at most _RATIO of a cell).  The magnitudes
    (in float64) end as the least solution of ``m[a] >= _RATIO * m[b]`` on every crossing edge
    above the samples' own, rounded to float32 once: the fixed point of sweeps over all the
    crossing edges (``tests/support/mesh_reference.py``), whatever the order the raises come in.
    """
    ta, tb, ma, mb = _tight_edges(offset, p)
    if ta.size:
        _raise_from(ta, tb, ma, mb, offset, p)


@njit(**KERNEL)
def _tight_edges(offset, p):
    """The crossing edges ``(a, b)`` of the grid's samples (``offset``'s from ``p`` on along each
    axis; ``a``, ``b`` their flat numbers in ``offset``, ``b`` one step after ``a`` along an
    axis) that break ``|a| >= _RATIO |b|`` or ``|b| >= _RATIO |a|``, with those magnitudes in
    float64. The edges from a row of samples along the last axis to the next sample, row and
    plane are tested together (:func:`_tight`) in a run the compiler vectorises, and listed
    edge by edge (:func:`_list_tight`) only where that run finds one (and on the grid's last
    row and plane)."""
    m0, m1, m2 = offset.shape
    n0, n1, n2 = m0 - 2 * p, m1 - 2 * p, m2 - 2 * p
    flat = offset.reshape(-1)
    ta = np.empty(64, dtype=np.int64)
    tb = np.empty(64, dtype=np.int64)
    ma = np.empty(64)
    mb = np.empty(64)
    m = 0
    for i in range(n0):
        for j in range(n1):
            if i + 1 < n0 and j + 1 < n1:
                w = offset[i + p, j + p, p : p + n2]
                u = offset[i + p, j + p + 1, p : p + n2]
                v = offset[i + p + 1, j + p, p : p + n2]
                # three flags, each its own run of tests: the form the compiler vectorises
                along, across, down = 0, 0, 0
                for k in range(n2 - 1):
                    along |= np.int64(_tight(w[k], w[k + 1]))
                    across |= np.int64(_tight(w[k], u[k]))
                    down |= np.int64(_tight(w[k], v[k]))
                found = along | across | down
                found |= np.int64(_tight(w[n2 - 1], u[n2 - 1]) | _tight(w[n2 - 1], v[n2 - 1]))
                if found == 0:
                    continue
            row = ((i + p) * m1 + j + p) * m2 + p
            m, ta, tb, ma, mb = _list_tight(flat, row, n2, i + 1 < n0, j + 1 < n1, m1 * m2, m2,
                                            m, ta, tb, ma, mb)  # fmt: skip
    return ta[:m], tb[:m], ma[:m], mb[:m]


@njit(**KERNEL)
def _list_tight(flat, row, n2, next_plane, next_row, s0, s1, m, ta, tb, ma, mb):
    """The tight edges from the row of ``n2`` samples starting at flat number ``row`` (to the
    next sample; to the next row and plane where there is one, ``s1`` and ``s0`` samples on)
    added to ``ta, tb, ma, mb`` (their first ``m`` entries used): counted, the arrays grown
    once if need be, then written (an array reassigned inside the loops would cost numba
    reference counting at every step: ten times the time); returns ``m`` and the arrays."""
    count = _row_tight(flat, row, n2, next_plane, next_row, s0, s1, -1, ta, tb, ma, mb)
    if m + count > ta.size:
        ta = grown(ta, np.int64(m), np.int64(count))
        tb = grown(tb, np.int64(m), np.int64(count))
        ma = grown(ma, np.int64(m), np.int64(count))
        mb = grown(mb, np.int64(m), np.int64(count))
    _row_tight(flat, row, n2, next_plane, next_row, s0, s1, m, ta, tb, ma, mb)
    return m + count, ta, tb, ma, mb


@njit(**INLINE)
def _row_tight(flat, row, n2, next_plane, next_row, s0, s1, m, ta, tb, ma, mb):
    """:func:`_list_tight`'s passes: how many tight edges the row has, written from entry
    ``m`` on unless ``m`` is -1."""
    q = max(m, 0)
    for d in range(3):
        step = 1 if d == 0 else (s1 if d == 1 else s0)
        n = n2 - 1 if d == 0 else (n2 if (next_row if d == 1 else next_plane) else 0)
        for a in range(row, row + n):
            x, y = flat[a], flat[a + step]
            if _tight(x, y):
                if m >= 0:
                    ta[q], tb[q], ma[q], mb[q] = a, a + step, abs(np.float64(x)), abs(np.float64(y))
                q += 1
    return q - max(m, 0)


@njit(**INLINE)
def _tight(x, y):
    """Whether the edge between offsets ``x`` and ``y`` crosses the level too near a sample
    (:func:`too_near`), without a branch."""
    return ((x < 0) ^ (y < 0)) & too_near(abs(np.float64(x)), abs(np.float64(y)))


@njit(**INLINE)
def too_near(mx, my):
    """Whether a crossing between samples of magnitudes ``mx`` and ``my`` (float64) lies too
    near one of them: ``mx < _RATIO my`` or ``my < _RATIO mx`` (the raises' test, dense and
    sparse)."""
    return (_RATIO * my > mx) | (_RATIO * mx > my)


@njit(**KERNEL)
def _raise_from(ta, tb, ma, mb, offset, p):
    """Raise magnitudes of ``offset`` in place from the crossing edges ``(ta, tb)`` that need
    it (:func:`_tight_edges`, with their magnitudes ``(ma, mb)``; the grid's samples from ``p``
    on along each axis): an edge raises a sample short of it; a raised sample puts its
    crossing edges to the test again (a worklist, the raised magnitudes in float64:
    :mod:`~.raise_table`; :func:`_raise_run`). The raised samples are written once, rounded to
    float32 with their sign. Returns how many were raised."""
    flat = offset.reshape(-1)
    keys, mags, stack, top, n = seeded(ta, tb, ma, mb, _RATIO)  # raised samples -> magnitudes
    while top > 0:
        keys, mags, stack = with_room(keys, mags, stack, top, n)
        top, n = _raise_run(keys, mags, stack, top, n, offset, p)
    for h in range(keys.size):
        g = keys[h]
        if g != -1:
            m = np.float32(mags[h])
            flat[g] = -m if flat[g] < 0 else m
    return n


@njit(**KERNEL)
def _raise_run(keys, mags, stack, top, n, offset, p):
    """Up to :data:`~.raise_table.POPS` samples taken off the worklist (which has room for
    what they put back, :func:`~.raise_table.with_room`), each putting its neighbours across a
    crossing edge that are short of its raised magnitude times the ratio back on it; returns
    the worklist's top and the raised count."""
    m0, m1, m2 = offset.shape
    flat = offset.reshape(-1)
    s0 = m1 * m2
    for _ in range(POPS):
        if top == 0:
            break
        top -= 1
        g = stack[top]
        i, j, k = g // s0, (g // m2) % m1, g % m2  # in offset: the grid's first sample at p
        need = _RATIO * mags[find(keys, g)]
        neg = flat[g] < 0
        for d in range(6):
            if d == 0:
                x = g - s0 if i > p else -1
            elif d == 1:
                x = g + s0 if i + 1 < m0 - p else -1
            elif d == 2:
                x = g - m2 if j > p else -1
            elif d == 3:
                x = g + m2 if j + 1 < m1 - p else -1
            elif d == 4:
                x = g - 1 if k > p else -1
            else:
                x = g + 1 if k + 1 < m2 - p else -1
            if x < 0 or (flat[x] < 0) == neg:
                continue
            h = find(keys, x)
            if need <= (mags[h] if keys[h] == x else abs(np.float64(flat[x]))):
                continue
            top, n = push(keys, mags, stack, top, n, h, x, need)
    return top, n


@njit(**INLINE)
def column_counts(w, b, i, j, n, col):
    """``col[k]`` for ``k < n``: how many of the samples ``(i..i+1, j..j+1, k)`` of brick ``b``
    of the offsets ``w`` are inside (the dense path's volume is one brick). A cell is mixed
    when two neighbouring counts add up to neither 0 nor 8."""
    for k in range(n):
        col[k] = (
            np.int64(w[b, i, j, k] < 0)
            + np.int64(w[b, i, j + 1, k] < 0)
            + np.int64(w[b, i + 1, j, k] < 0)
            + np.int64(w[b, i + 1, j + 1, k] < 0)
        )


@njit(**KERNEL)
def mixed_cells(work):
    """The cells of ``work`` whose corners are not all on one side, as the Lewiner pass
    (:func:`surfgen.generator.mesh.lewiner_chunks.lewiner_cells`) takes them: their flat
    numbers ``(i * n1 + j) * n2 + k`` in order (skimage's visiting order, ``work`` read as
    ``im[z, y, x]``) and their corners (C, 8) float32 in skimage's order v0..v7. The other
    cells make no triangle. One pass counts them in each column of cells along the last axis,
    a second lists those of the columns that have some into arrays of that size
    (:func:`_list_mixed`)."""
    n0, n1, n2 = work.shape
    per = np.zeros((max(n0 - 1, 0), max(n1 - 1, 0)), dtype=np.int64)
    count = _list_mixed(work, per, np.empty(0, dtype=np.int64), np.empty((0, 8), dtype=np.float32))
    keys = np.empty(count, dtype=np.int64)
    corners = np.empty((count, 8), dtype=np.float32)
    _list_mixed(work, per, keys, corners)
    return keys, corners


@njit(**INLINE)
def _list_mixed(work, per, keys, corners):
    """The number of mixed cells of ``work``: counted into ``per`` (a column of cells along
    the last axis each) when ``keys`` is empty, else listed into ``keys`` and ``corners`` from
    the columns ``per`` counts some in; the inside counts of a cell's corner columns by
    :func:`column_counts`."""
    n0, n1, n2 = work.shape
    one = work.reshape((1, n0, n1, n2))
    write = keys.size > 0
    col = np.empty(n2, dtype=np.int64)
    q = 0
    for i in range(n0 - 1):
        for j in range(n1 - 1):
            if write and per[i, j] == 0:
                continue
            column_counts(one, 0, i, j, n2, col)
            first = q
            for k in range(n2 - 1):
                t = col[k] + col[k + 1]
                mixed = (t != 0) & (t != 8)
                if write and mixed:
                    keys[q] = (i * n1 + j) * n2 + k
                    corners[q, 0] = work[i, j, k]
                    corners[q, 1] = work[i, j, k + 1]
                    corners[q, 2] = work[i, j + 1, k + 1]
                    corners[q, 3] = work[i, j + 1, k]
                    corners[q, 4] = work[i + 1, j, k]
                    corners[q, 5] = work[i + 1, j, k + 1]
                    corners[q, 6] = work[i + 1, j + 1, k + 1]
                    corners[q, 7] = work[i + 1, j + 1, k]
                q += mixed
            if not write:
                per[i, j] = q - first
    return q
