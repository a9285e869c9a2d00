"""Marching cubes' kernels for :func:`surfgen.generator.mesh.mesh.extract_with_edges`.

The signs fixed in float64 (:func:`_offsets`), the crossings kept apart (:func:`_separate`), the
cap's pad and the cells marching cubes visits: each one numba pass (the placement and merging
of its vertices are in :mod:`~surfgen.generator.mesh.placement`).
:mod:`surfgen.generator.mesh.mesh` calls them in order.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.jit.options import INLINE, KERNEL

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
_MAX_ROUNDS = 200


_CLIP64 = float(_CLIP)  # np.clip of float64 values against the float32 bound compares in float64
_TINY32 = np.float32(_TINY)


def _offsets(values: np.ndarray, level: float) -> tuple[np.ndarray, np.ndarray, int]:
    """float32 ``F - level`` with signs decided in float64, the boolean inside mask and its count.

    Inside samples (``F < level``, finite) get a strictly negative offset, all others a strictly
    positive one, so marching cubes never sees a sample on the level (where ``<`` vs ``<=``
    would decide the topology): offsets rounded to 0 in float32 (below ~1e-45) and exact-level
    samples get the smallest normal float32 with the sign decided in float64; magnitudes are
    clipped to 1e30 to stay finite in float32.  A non-finite sample gets a positive value
    mirroring the deepest inside sample in its 3x3x3 neighbourhood (at least the smallest
    normal), so a crossing on an edge to it falls at mid-edge or nearer the inside sample (a
    huge value would pile the crossings onto the inside samples, +inf exactly).  Magnitudes are
    then raised where needed so every crossing lies at least SEPARATION of its edge from both
    samples (:func:`_separate`).
    """
    offset = np.empty(values.shape, dtype=np.float32)
    inside = np.empty(values.shape, dtype=np.bool_)
    n_inside, n_bad = _offsets_kernel(values, float(level), offset, inside)
    if n_bad:
        _mirror_nonfinite(values, offset, inside)
    _separate(offset, inside)
    return offset, inside, int(n_inside)


@njit(**KERNEL)
def _offsets_kernel(values, level, offset, inside):
    """Fill ``offset`` and ``inside`` (see :func:`_offsets`; non-finite samples are left NaN or
    clipped for :func:`_mirror_nonfinite`); returns the inside and non-finite counts."""
    v = values.reshape(-1)
    out = offset.reshape(-1)
    ins = inside.reshape(-1)
    n_inside = 0
    n_bad = 0
    for i in range(v.size):
        x = v[i]
        o, is_in = offset_of(x, level)
        if is_in:
            n_inside += 1
        if not np.isfinite(x):
            n_bad += 1
        out[i] = o
        ins[i] = is_in
    return n_inside, n_bad


@njit(**INLINE)
def offset_of(x, level):
    """The float32 offset of one sample ``x`` and whether it is inside (:func:`_offsets`' rule;
    a non-finite sample is left NaN or clipped, for :func:`_mirror_nonfinite`).  The inside
    samples' offsets are exactly the negative ones."""
    d = x - level
    d = -_CLIP64 if d < -_CLIP64 else (_CLIP64 if d > _CLIP64 else d)  # NaN stays NaN
    o = np.float32(d)
    is_in = np.isfinite(x) and x < level
    if is_in:
        if o >= 0:
            o = -_TINY32
    elif o <= 0:
        o = _TINY32
    return o, is_in


@njit(**KERNEL)
def _mirror_nonfinite(values, offset, inside):
    """Each non-finite sample: the largest ``-offset`` of the inside samples in its 3x3x3
    neighbourhood (inside the grid), at least the smallest normal float32."""
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
                            if inside[a, b, c] and -offset[a, b, c] > deepest:
                                deepest = -offset[a, b, c]
                offset[i, j, k] = max(deepest, _TINY32)


def _crossing_edges(inside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flat indices ``(a, b)`` of the samples of every grid edge whose samples are on opposite
    sides (numpy's vectorised comparisons of the flat mask shifted by each axis's stride; pairs
    that would wrap from one row or plane to the next are dropped)."""
    nx, ny, nz = inside.shape
    flat = inside.reshape(-1)
    ends = []
    for stride in (ny * nz, nz, 1):
        a = np.flatnonzero(flat[:-stride] != flat[stride:])
        if stride == nz:
            a = a[(a // nz) % ny != ny - 1]
        elif stride == 1:
            a = a[a % nz != nz - 1]
        ends.append(a)
    ia = np.concatenate(ends)
    strides = np.repeat(np.array([ny * nz, nz, 1]), [len(e) for e in ends])
    return ia, ia + strides


def _separate(offset: np.ndarray, inside: np.ndarray) -> None:
    """Keep every crossing SEPARATION of its edge from both samples (:func:`_raise_magnitudes`),
    in place."""
    ia, ib = _crossing_edges(inside)
    if ia.size:
        _raise_magnitudes(offset.reshape(-1), inside.reshape(-1), ia, ib)


@njit(**KERNEL)
def _raise_magnitudes(flat, ins, ia, ib):
    """Raise ``|offset|`` (``flat``) in place until ``|a| >= _RATIO |b|`` for both samples of
    every crossing edge ``(ia, ib)`` (``ins``: the samples whose offset is negative).

    Marching cubes puts the crossing of edge (a, b) at ``t = a / (a - b)``; a sample at or near
    the level next to a large opposite value (staircase plateaus at the level, exact zeros,
    samples beside a pole) would put it on the sample itself, and several crossings would
    coincide there once stored in float32.  Raising a magnitude never changes a sign, so the
    same edges cross; it moves a crossing at most SEPARATION of the edge (in a locally linear
    field the distance to the true surface grows by at most _RATIO of a cell).

    The magnitudes (in float64) end as the least solution of ``m[a] >= _RATIO * m[b]`` on every
    crossing edge above the samples' own: whatever order the edges are raised in (here: sweeps
    over the edges, updating in place), each raise is ``_RATIO`` times a value no larger than
    that solution, so the sweeps end exactly on it.  A raise can require a raise of the
    sample's own opposite neighbours, each _RATIO smaller, so this ends after a few sweeps
    (float32's range bounds it by ~40).
    """
    count = ia.size
    mag = np.empty(flat.size)  # read only at the samples of crossing edges
    for e in range(count):
        mag[ia[e]] = abs(np.float64(flat[ia[e]]))
        mag[ib[e]] = abs(np.float64(flat[ib[e]]))
    changed = False
    for _ in range(_MAX_ROUNDS):
        grew = False
        for e in range(count):
            a, b = ia[e], ib[e]
            need = _RATIO * mag[b]
            if need > mag[a]:
                mag[a] = need
                grew = True
            need = _RATIO * mag[a]
            if need > mag[b]:
                mag[b] = need
                grew = True
        if not grew:
            break
        changed = True
    if changed:
        for e in range(count):
            a, b = ia[e], ib[e]
            m = np.float32(mag[a])
            flat[a] = -m if ins[a] else m
            m = np.float32(mag[b])
            flat[b] = -m if ins[b] else m


def _pad_outside(work: np.ndarray) -> np.ndarray:
    """Surround ``work`` with one layer of outside samples mirroring their box neighbour.

    Mirroring (``|w|`` next to ``w``) puts every crossing towards the pad exactly half a cell
    outside the box, where it is told apart from the crossings inside and clamped onto the box.
    """
    nx, ny, nz = work.shape
    padded = np.empty((nx + 2, ny + 2, nz + 2), dtype=np.float32)
    _pad_kernel(work, padded)
    return padded


@njit(**KERNEL)
def _pad_kernel(work, padded):
    nx, ny, nz = work.shape
    for i in range(nx + 2):
        ci = min(max(i - 1, 0), nx - 1)
        for j in range(ny + 2):
            cj = min(max(j - 1, 0), ny - 1)
            border = i == 0 or i == nx + 1 or j == 0 or j == ny + 1
            for k in range(nz + 2):
                ck = min(max(k - 1, 0), nz - 1)
                w = work[ci, cj, ck]
                if border or k == 0 or k == nz + 1:
                    w = abs(w)
                padded[i, j, k] = w


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
    cells make no triangle. One pass counts them, a second lists them into arrays of that
    size (:func:`_list_mixed`)."""
    count = _list_mixed(work, np.empty(0, dtype=np.int64), np.empty((0, 8), dtype=np.float32))
    keys = np.empty(count, dtype=np.int64)
    corners = np.empty((count, 8), dtype=np.float32)
    _list_mixed(work, keys, corners)
    return keys, corners


@njit(**INLINE)
def _list_mixed(work, keys, corners):
    """The number of mixed cells of ``work``, listed into ``keys`` and ``corners`` unless they
    are empty (the counting pass); the inside counts of a cell's corner columns by
    :func:`column_counts`."""
    n0, n1, n2 = work.shape
    one = work.reshape((1, n0, n1, n2))
    write = keys.size > 0
    col = np.empty(n2, dtype=np.int64)
    q = 0
    for i in range(n0 - 1):
        for j in range(n1 - 1):
            column_counts(one, 0, i, j, n2, col)
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
    return q
