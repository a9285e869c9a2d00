"""Marching cubes' kernels for :func:`surfgen.generator.mesh.mesh.extract_with_edges`.

The signs fixed in float64 (:func:`_offsets`), the crossings kept apart (:func:`_separate`), the
cap's pad, the cells marching cubes visits, and the placement and merging of its vertices: each
one numba pass.  :mod:`surfgen.generator.mesh.mesh` calls them in order.
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
_EDGE_LO = 0.25 * SEPARATION  # a vertex coordinate this far from a whole number is fractional
_EDGE_HI = 1.0 - 0.25 * SEPARATION
_FACE_HI = 1.0 - SEPARATION
_HASH_U = 0x9E3779B97F4A7C15  # Fibonacci hashing
_RUN = 9  # the vertex groups' table keeps runs of 512 keys (128 samples of a row) together
#: Vertices from which a mesh's groups are found plane by plane (:func:`_same_targets`): one
#: table for the whole mesh would take 16-32 MiB.
PLANE_TABLES_FROM = 1 << 19


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
    :func:`column_counts`, as the sparse path's scan counts them in a brick."""
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


@njit(**KERNEL)
def _place(verts, shift, shape, lo, hi, spacing):
    """Marching cubes' float32 vertices -> box coordinates and edges.

    Each vertex's grid index is ``verts - shift`` in float64 (1 with a cap's pad: exact, so
    it is recomputed where needed rather than kept); ``lo + index * spacing``, clamped: on the
    box's faces for indices at or past the first and last samples (the cap lies exactly on
    them; ``lo + (N-1) * spacing`` may miss ``hi`` by an ulp, and a cap vertex clamped onto hi
    and one computed there would differ by an ulp: distinct here, one point in float32).
    ``moved``: outside the grid (cap crossings towards the pad).  Edges as
    :func:`extract_with_edges` returns them: a vertex on an edge has exactly one fractional
    index coordinate, at least SEPARATION from a whole number (float32 keeps ~1e-4 of it at
    index 2048).  Also returns whether any vertex on no edge lies within SEPARATION of its
    cell's faces (:func:`_keep_off_cell_faces`).
    """
    n = verts.shape[0]
    vertices = np.empty((n, 3))
    edges = np.empty((n, 4), dtype=np.int64)
    moved = np.empty(n, dtype=np.bool_)
    off_cell = False
    for v in range(n):
        n_frac = 0
        axis = 0
        near_face = False
        out = False
        for c in range(3):
            x = np.float64(verts[v, c]) - shift
            last = np.float64(shape[c]) - 1.0
            if x >= last:
                vertices[v, c] = hi[c]
            elif x <= 0.0:
                vertices[v, c] = lo[c]
            else:
                vertices[v, c] = lo[c] + x * spacing[c]
            if x < 0.0 or x > last:
                out = True
            frac = x - np.floor(x)
            if frac > _EDGE_LO and frac < _EDGE_HI:
                if n_frac == 0:
                    axis = c
                n_frac += 1
            if frac < SEPARATION or frac > _FACE_HI:
                near_face = True
        moved[v] = out
        if n_frac == 1 and not out:
            edges[v, 0] = axis
            for c in range(3):
                x = np.float64(verts[v, c]) - shift
                edges[v, 1 + c] = np.int64(np.rint(np.floor(x) if c == axis else x))
        else:
            for c in range(4):
                edges[v, c] = -1
            if not out and near_face:
                off_cell = True
    return vertices, edges, moved, off_cell


def _same_targets(
    verts: np.ndarray, shift: float, edges: np.ndarray, moved: np.ndarray, shape: np.ndarray
) -> np.ndarray | None:
    """For each vertex, the first vertex of its group (:func:`_merge_same`), or None when every
    vertex is alone (``verts - shift``: the vertices' grid indices, :func:`_place`). A large
    mesh's groups are found plane by plane (:func:`_targets_by_plane`: its table would hold
    tens of MiB at the end of a fine render, more than a gigabyte for equation B at 512^3), a
    small one's in one table (:func:`_targets_kernel`: the sampler's meshes, 11 % faster)."""
    if len(verts) >= PLANE_TABLES_FROM:
        target, any_merge, ordered = _targets_by_plane(verts, shift, edges, moved, shape)
        if ordered:
            return target if any_merge else None
    # a small mesh, or not marching cubes' plane order: one table for the whole mesh
    target, any_merge = _targets_kernel(verts, shift, edges, moved, shape)
    return target if any_merge else None


@njit(**INLINE)
def _vertex_key(axis, e1, e2, e3, moved, x, y, z, shift, nx, ny, nz):
    """The key of a vertex's group: its grid edge's first sample's number times 4 plus the
    edge's axis, or for a moved vertex its box sample's number times 4 plus 3; -1 for a vertex
    alone (a cell's centre). The vertex's edge row ``(axis, e1, e2, e3)``, ``moved`` flag and
    coordinates are passed as values: given the arrays, the inlined helper counted references
    to each at every vertex (numba's increments are atomic: a third of the groups' time)."""
    if axis >= 0:
        return (((e1 * ny + e2) * nz + e3) << 2) + axis
    if moved:
        # A moved vertex was clamped onto a box sample: the sample's number is its key.
        s0 = min(max(np.int64(np.rint(np.float64(x) - shift)), 0), nx - 1)
        s1 = min(max(np.int64(np.rint(np.float64(y) - shift)), 0), ny - 1)
        s2 = min(max(np.int64(np.rint(np.float64(z) - shift)), 0), nz - 1)
        return (((s0 * ny + s1) * nz + s2) << 2) + 3
    return np.int64(-1)


@njit(**INLINE)
def _table_size(n):
    """Slots of a vertex-group table for ``n`` keys (a power of two, at least ``2 n + 2`` and
    two runs), and the shift that keeps a run number's top bits (:func:`_find_or_add`)."""
    bits = _RUN + 1
    while (1 << bits) < 2 * n + 2:
        bits += 1
    return 1 << bits, np.uint64(64 - (bits - _RUN))


@njit(**INLINE)
def _find_or_add(tables, t, key, v, down, mask):
    """The first vertex of ``key`` in the open-addressing table ``tables[t]`` of ``(key,
    vertex)`` slots; ``v`` where the key is new (then added). The probe starts at the key's run
    of ``2**_RUN`` slots, placed by Fibonacci hashing of the run's number (its top ``64 - down``
    bits), at the key's place in the run. Given the tables and the row (not a view of the row)
    and with one exit, it leaves no reference count in the callers' loops (their tests)."""
    run = (np.uint64(key >> _RUN) * np.uint64(_HASH_U)) >> down
    h = np.int64(run) << _RUN | (key & ((1 << _RUN) - 1))
    while tables[t, 2 * h] != -1 and tables[t, 2 * h] != key:
        h = (h + 1) & mask
    if tables[t, 2 * h] == -1:
        tables[t, 2 * h] = key
        tables[t, 2 * h + 1] = v
    return tables[t, 2 * h + 1]


@njit(**KERNEL)
def _targets_by_plane(verts, shift, edges, moved, shape):
    """:func:`_targets_kernel`'s groups with a table per plane of samples along the first axis,
    three at a time: marching cubes visits the cells plane by plane and numbers vertices as it
    makes them, and a cell of plane ``c`` makes vertices whose keys lie on plane ``c`` or
    ``c + 1`` (an edge, or a box sample, is in the cells of at most two neighbouring planes),
    so the vertices of one group come while the planes of its key and the one below are
    visited. A plane's table is reused three planes on, cleared. A few tables of a plane's
    vertices in place of one of the mesh's (16 bytes a slot, twice the vertices): the same
    targets in a sliver of the memory. Returns ``(target, any_merge, ordered)``; ``ordered``
    False (and nothing else meaningful) where a key lies two planes below one already seen."""
    n = verts.shape[0]
    nx, ny, nz = shape[0], shape[1], shape[2]
    plane = (ny * nz) << 2
    counts = np.zeros(nx, dtype=np.int64)
    for v in range(n):
        key = _vertex_key(
            edges[v, 0], edges[v, 1], edges[v, 2], edges[v, 3], moved[v],
            verts[v, 0], verts[v, 1], verts[v, 2], shift, nx, ny, nz,
        )  # fmt: skip
        if key >= 0:
            counts[key // plane] += 1
    size, down = _table_size(counts.max())
    mask = size - 1
    tables = np.full((3, 2 * size), -1, dtype=np.int64)
    tag = np.full(3, -1, dtype=np.int64)  # the plane each table holds
    target = np.empty(n, dtype=np.int64)
    any_merge = False
    top = np.int64(-1)
    for v in range(n):
        target[v] = v
        key = _vertex_key(
            edges[v, 0], edges[v, 1], edges[v, 2], edges[v, 3], moved[v],
            verts[v, 0], verts[v, 1], verts[v, 2], shift, nx, ny, nz,
        )  # fmt: skip
        if key < 0:
            continue
        q = key // plane
        if q < top - 1:
            return target, False, False
        top = max(top, q)
        t = q % 3
        if tag[t] != q:
            tables[t, :] = -1
            tag[t] = q
        first = _find_or_add(tables, t, key, v, down, mask)
        if first != v:
            target[v] = first
            any_merge = True
    return target, any_merge, True


@njit(**KERNEL)
def _targets_kernel(verts, shift, edges, moved, shape):
    """The vertices of one grid edge form a group, and moved vertices clamped onto one box
    sample; others are alone.  Returns ``target`` (``target[v]``: the first vertex of ``v``'s
    group) and whether any vertex is not its own target.

    The groups are found in an open-addressing table of their keys (:func:`_vertex_key`), so
    the keys of one sample's edges and of a row's samples are close; runs of ``2**_RUN`` keys
    keep their order in the table (the run's number is hashed), so the vertices of a row of
    cells, which marching cubes emits together, probe a few cache lines rather than one each.
    One table for the whole mesh: what :func:`_targets_by_plane` falls back to."""
    n = verts.shape[0]
    nx, ny, nz = shape[0], shape[1], shape[2]
    size, down = _table_size(n)
    mask = size - 1
    tables = np.full((1, 2 * size), -1, dtype=np.int64)  # one table of (key, first vertex)
    target = np.empty(n, dtype=np.int64)
    any_merge = False
    for v in range(n):
        target[v] = v
        key = _vertex_key(
            edges[v, 0], edges[v, 1], edges[v, 2], edges[v, 3], moved[v],
            verts[v, 0], verts[v, 1], verts[v, 2], shift, nx, ny, nz,
        )  # fmt: skip
        if key < 0:
            continue
        first = _find_or_add(tables, 0, key, v, down, mask)
        if first != v:
            target[v] = first
            any_merge = True
    return target, any_merge


@njit(**KERNEL)
def _merge_same(vertices, faces, edges, target):
    """Give one index to the vertices of one grid edge, and to exactly coincident moved ones.

    Other vertices keep theirs even where they are close (merging distinct crossings could
    pinch the surface).  Faces that lose a corner are dropped, then unreferenced vertices (the
    others keep their order).  Shapes: ``(V, 3)`` float64 vertices, ``(F, 3)`` int64 faces,
    ``(V, 4)`` edges, ``(V,)`` targets (:func:`_same_targets`); returns the kept vertices,
    the faces on them (renumbered) and the kept vertices' edges.
    """
    n_faces = faces.shape[0]
    out = np.empty((n_faces, 3), dtype=np.int64)
    used = np.zeros(target.size, dtype=np.bool_)
    m = 0
    for f in range(n_faces):
        a, b, c = target[faces[f, 0]], target[faces[f, 1]], target[faces[f, 2]]
        if a != b and b != c and a != c:
            out[m, 0], out[m, 1], out[m, 2] = a, b, c
            used[a] = used[b] = used[c] = True
            m += 1
    renumber = np.empty(target.size, dtype=np.int64)
    k = -1
    for v in range(target.size):
        if used[v]:
            k += 1
        renumber[v] = k
    for f in range(m):
        for c in range(3):
            out[f, c] = renumber[out[f, c]]
    kept = np.empty((k + 1, 3))
    kept_edges = np.empty((k + 1, 4), dtype=np.int64)
    for v in range(target.size):
        if used[v]:  # element by element: a row copy compiles numba's shape error (1.5 s)
            for c in range(3):
                kept[renumber[v], c] = vertices[v, c]
            for c in range(4):
                kept_edges[renumber[v], c] = edges[v, c]
    return kept, out[:m], kept_edges


def _keep_off_cell_faces(
    index: np.ndarray, faces: np.ndarray, edges: np.ndarray, moved: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Move cell-interior vertices that lie within SEPARATION of their cell's faces inside.

    Lewiner's tables put an extra vertex inside the cell of some ambiguous cases, at the mean
    of the cell's 8 corners weighted by ``1 / |value|``.  A corner whose offset is tiny next
    to the others' (a sample at or rounded onto the level: ``_TINY``, or raised only as far as
    :func:`_separate` needs) outweighs them all and pulls the vertex onto itself: within
    float32 resolution of the sample, of the cap vertex on it when it is a box sample, and of
    the centre vertex of a neighbouring cell pulled onto the same sample (issue shape 20d0c322:
    a centre vertex 5e-8 cells from a box sample carrying a cap vertex).  Two corners that
    outweigh the rest pull it onto the crossing of their edge; those (one fractional
    coordinate) are already on an edge for :func:`_vertex_edges` and merged with it.  The
    others are clamped into their cell shrunk by SEPARATION on every side: at least that far
    from every vertex on the cell's boundary and from every other cell's interior vertex, for
    a geometric change of at most SEPARATION of a cell per coordinate.

    The cell is the one holding the vertex's neighbours (the crossings of its cell): per axis,
    the floor of their smallest index.  Modifies ``index`` in place; returns the rows changed
    and their new indices, or None when no vertex needed it.
    """
    frac = index - np.floor(index)
    near_face = np.any((frac < SEPARATION) | (frac > 1.0 - SEPARATION), axis=1)
    candidates = np.flatnonzero((edges[:, 0] < 0) & ~moved & near_face)
    if candidates.size == 0:
        return None
    is_candidate = np.zeros(len(index), dtype=bool)
    is_candidate[candidates] = True
    touching = faces[is_candidate[faces].any(axis=1)]
    low = np.full((len(index), 3), np.inf)
    high = np.full((len(index), 3), -np.inf)
    for a in range(3):  # every corner of a touching face sees the other two
        for b in range(3):
            if a != b:
                np.minimum.at(low, touching[:, a], index[touching[:, b]])
                np.maximum.at(high, touching[:, a], index[touching[:, b]])
    low = np.minimum(low[candidates], index[candidates])
    high = np.maximum(high[candidates], index[candidates])
    cell = np.floor(low)
    # A zero span on an axis would leave the cell undecided there (a flat fan, which the
    # centre-vertex cases cannot make): such an axis is left as it is.
    decided = high > low
    inside = np.clip(index[candidates], cell + SEPARATION, cell + 1.0 - SEPARATION)
    new = np.where(decided, inside, index[candidates])
    changed = np.any(new != index[candidates], axis=1)
    if not changed.any():
        return None
    rows = candidates[changed]
    index[rows] = new[changed]
    return rows, index[rows]
