"""Marching cubes' vertices placed on the box and merged: one vertex per grid edge.

:func:`place_vertices` turns skimage's float32 index coordinates into box coordinates and finds
the grid edge of each vertex; :func:`same_targets` groups the vertices that are one point (a
grid edge's, or a box sample's for cap vertices), :func:`merge_same` gives each group one index,
and :func:`keep_off_cell_faces` moves the rare cell-interior vertex off its cell's faces.
:func:`surfgen.generator.mesh.mesh.finish_marching` calls them in order, for the dense and the
sparse paths alike.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.allocator import recycled_many
from surfgen.generator.eval.tape import run_at_once
from surfgen.generator.jit.options import INLINE, KERNEL
from surfgen.generator.mesh.marching import SEPARATION

_EDGE_LO = 0.25 * SEPARATION  # a vertex coordinate this far from a whole number is fractional
_EDGE_HI = 1.0 - 0.25 * SEPARATION
_FACE_HI = 1.0 - SEPARATION
_HASH_U = 0x9E3779B97F4A7C15  # Fibonacci hashing
_RUN = 9  # the vertex groups' table keeps runs of 512 keys (128 samples of a row) together
#: Vertices from which a mesh's groups are found plane by plane (:func:`same_targets`): one
#: table for the whole mesh would take 16-32 MiB.
PLANE_TABLES_FROM = 1 << 19
#: Vertices from which, on more than one thread, a mesh's groups are found plane by plane in
#: two halves at once: sculpture-5 at 512^3 (490 000 vertices) 8.1 ms in one table, 3.6 ms in
#: halves; below about 200 000 the two are within a thread's wake-up of each other.
HALVES_FROM = 1 << 18


#: Vertices a thread of :func:`place_vertices` takes at least (a run of 100,000 takes about 3
#: ms, a thread's wake-up up to a millisecond).
PLACE_RUN = 100_000


def place_vertices(
    verts: np.ndarray,
    shift: float,
    shape: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    spacing: np.ndarray,
    threads: int = 1,
    spare: list[np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """:func:`_place_range` over all of ``verts``, in ``threads`` runs of at least
    :data:`PLACE_RUN` vertices at once (each vertex on its own: the same arrays whatever the
    runs). Returns ``(vertices, edges, moved, off_cell)``; ``edges`` and ``moved`` on the
    memory of the array in ``spare``, done with (the sparse marching's runs:
    :func:`~surfgen.generator.allocator.recycled_many`), the vertices, which the mesh keeps,
    on their own."""
    n = verts.shape[0]
    vertices = np.empty((n, 3))
    edges, moved = recycled_many(spare or [], [((n, 4), np.int64), ((n,), np.bool_)])
    runs = max(1, min(int(threads), n // PLACE_RUN))
    bounds = [n * r // runs for r in range(runs + 1)]
    near = run_at_once(
        [
            lambda a=a, b=b: _place_range(
                verts, shift, shape, lo, hi, spacing, vertices, edges, moved, a, b
            )  # fmt: skip
            for a, b in zip(bounds[:-1], bounds[1:], strict=True)
        ]
    )
    return vertices, edges, moved, any(near)


@njit(**KERNEL)
def _place_range(verts, shift, shape, lo, hi, spacing, vertices, edges, moved, v0, v1):
    """Marching cubes' float32 vertices ``v0:v1`` -> box coordinates and edges, written into
    ``vertices``, ``edges`` and ``moved`` (:func:`place_vertices`).

    Each vertex's grid index is ``verts - shift`` in float64 (1 with a cap's pad: exact, so
    it is recomputed where needed rather than kept); ``lo + index * spacing``, clamped: on the
    box's faces for indices at or past the first and last samples (the cap lies exactly on
    them; ``lo + (N-1) * spacing`` may miss ``hi`` by an ulp, and a cap vertex clamped onto hi
    and one computed there would differ by an ulp: distinct here, one point in float32).
    ``moved``: outside the grid (cap crossings towards the pad).  Edges as
    :func:`~surfgen.generator.mesh.mesh.extract_with_edges` returns them: a vertex on an edge has exactly one fractional
    index coordinate, at least SEPARATION from a whole number (float32 keeps ~1e-4 of it at
    index 2048).  Also returns whether any vertex on no edge lies within SEPARATION of its
    cell's faces (:func:`keep_off_cell_faces`).
    """
    off_cell = False
    for v in range(v0, v1):
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
    return off_cell


def same_targets(
    verts: np.ndarray,
    shift: float,
    edges: np.ndarray,
    moved: np.ndarray,
    shape: np.ndarray,
    threads: int = 1,
) -> np.ndarray | None:
    """For each vertex, the first vertex of its group (:func:`merge_same`), or None when every
    vertex is alone (``verts - shift``: the vertices' grid indices, :func:`_place_range`). A large
    mesh's groups are found plane by plane (:func:`_targets_by_plane`: its table would hold
    tens of MiB at the end of a fine render, more than a gigabyte for equation B at 512^3), with
    ``threads`` > 1 in two halves at once (:func:`_targets_in_halves`, from :data:`HALVES_FROM`
    vertices); a small one's in one table (:func:`_targets_kernel`: the sampler's meshes, 11 %
    faster)."""
    halves = threads > 1 and len(verts) >= min(HALVES_FROM, PLANE_TABLES_FROM)
    if halves or len(verts) >= PLANE_TABLES_FROM:
        found = _targets_in_halves(verts, shift, edges, moved, shape) if halves else None
        if found is None:
            target, any_merge, ordered = _targets_by_plane(verts, shift, edges, moved, shape)
            found = (target, any_merge) if ordered else None
        if found is not None:
            return found[0] if found[1] else None
    # a small mesh, or not marching cubes' plane order: one table for the whole mesh
    target, any_merge = _targets_kernel(verts, shift, edges, moved, shape)
    return target if any_merge else None


def _targets_in_halves(
    verts: np.ndarray,
    shift: float,
    edges: np.ndarray,
    moved: np.ndarray,
    shape: np.ndarray,
    mid: int | None = None,
) -> tuple[np.ndarray, bool] | None:
    """:func:`_targets_by_plane`'s targets and whether any vertex merges, the two halves of the
    vertices grouped at once (:func:`_plane_groups`), then the second half's vertices on the
    first half's last planes given the first half's first vertex of their key
    (:func:`_link_halves`). None where either half is out of plane order, or the second half
    reaches further down than the first's last two planes (:func:`_targets_by_plane` decides).
    ``mid``: the second half's first vertex (None: the middle one)."""
    n = len(verts)
    mid = n // 2 if mid is None else int(mid)
    target = np.empty(n, dtype=np.int64)
    first, second = run_at_once(
        [
            lambda a=a, b=b: _plane_groups(verts, shift, edges, moved, shape, target, a, b)
            for a, b in ((0, mid), (mid, n))
        ]
    )
    tables, down, mask, merged, ordered, _, top = first
    _, _, _, merged_second, ordered_second, low_second, _ = second
    del first, second  # the second half's tables
    if not (ordered and ordered_second and low_second >= top - 1):
        return None
    linked = _link_halves(verts, shift, edges, moved, shape, target, mid, tables, down, mask, top)
    return target, bool(merged or merged_second or linked)


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
    two runs), and the shift that keeps a run number's top bits (:func:`_probe`)."""
    bits = _RUN + 1
    while (1 << bits) < 2 * n + 2:
        bits += 1
    return 1 << bits, np.uint64(64 - (bits - _RUN))


@njit(**INLINE)
def _probe(tables, t, key, down, mask, plane):
    """The slot of ``key`` in the open-addressing table ``tables[t]`` of ``(key, vertex)``
    slots, or the free slot where it would go. The probe starts at the key's run of
    ``2**_RUN`` slots, placed by Fibonacci hashing of the run's number (its top ``64 - down``
    bits), at the key's place in the run. With ``plane`` (keys per plane, > 0) a slot holding
    a key of another plane than ``key``'s counts as free (:func:`_plane_groups` reuses a table
    without clearing it: a current key is never overwritten, so the probes of the plane's keys
    meet the same keys as in a cleared table); ``plane`` 0: only -1 is free. Given the tables
    and the row (not a view of the row) and with one exit, it leaves no reference count in the
    callers' loops (their tests)."""
    run = (np.uint64(key >> _RUN) * np.uint64(_HASH_U)) >> down
    h = np.int64(run) << _RUN | (key & ((1 << _RUN) - 1))
    q = key // plane if plane > 0 else np.int64(0)
    while True:
        held = tables[t, 2 * h]
        if held == key or held == -1 or (plane > 0 and held // plane != q):
            break
        h = (h + 1) & mask
    return h


@njit(**INLINE)
def _find_or_add(tables, t, key, v, down, mask, plane):
    """The first vertex of ``key`` in ``tables[t]`` (:func:`_probe`); ``v`` where the key is
    new (then added)."""
    h = _probe(tables, t, key, down, mask, plane)
    if tables[t, 2 * h] != key:  # a free slot: the key is new
        tables[t, 2 * h] = key
        tables[t, 2 * h + 1] = v
    return tables[t, 2 * h + 1]


@njit(**INLINE)
def _find(tables, t, key, down, mask, plane):
    """The first vertex of ``key`` in ``tables[t]`` (:func:`_probe`), or -1."""
    h = _probe(tables, t, key, down, mask, plane)
    return tables[t, 2 * h + 1] if tables[t, 2 * h] == key else np.int64(-1)


@njit(**KERNEL)
def _targets_by_plane(verts, shift, edges, moved, shape):
    """:func:`_targets_kernel`'s groups with a table per plane of samples along the first axis,
    two at a time (:func:`_plane_groups` over every vertex). Returns ``(target, any_merge,
    ordered)``; ``ordered`` False (and nothing else meaningful) where a key lies two planes
    below one already seen."""
    n = verts.shape[0]
    target = np.empty(n, dtype=np.int64)
    _, _, _, any_merge, ordered, _, _ = _plane_groups(
        verts, shift, edges, moved, shape, target, 0, n
    )
    return target, any_merge, ordered


@njit(**KERNEL)
def _plane_groups(verts, shift, edges, moved, shape, target, v0, v1):
    """The groups of vertices ``v0:v1`` (among themselves: their targets into ``target``) with
    a table per plane of samples along the first axis, two at a time: marching cubes visits
    the cells plane by plane and numbers vertices as it makes them, and a cell of plane ``c``
    makes vertices whose keys lie on plane ``c`` or ``c + 1`` (an edge, or a box sample, is in
    the cells of at most two neighbouring planes), so the vertices of one group come while the
    planes of its key and the one below are visited, and once a key of plane ``c + 2`` comes,
    none of plane ``c`` does (else the keys are out of order: ``ordered`` False). A plane's
    table is reused two planes on as it is: the keys of the plane it held count as free slots
    (:func:`_probe`; clearing the tables took 40 % of the time for equation C at 512^3,
    0.20 -> 0.12 s; a third table, which the order never needs, held 8 of equation C's 24
    MiB). A few tables of a plane's vertices in place of one of the mesh's (16 bytes a slot,
    twice the vertices): the same targets in a sliver of the memory.

    Returns ``(tables, down, mask, any_merge, ordered, low, top)``: the tables as they end and
    their hashing, whether any vertex merged, whether the keys came in plane order (False,
    and nothing else meaningful, where a key lies two planes below one already seen), and the
    lowest and highest planes of their keys."""
    nx, ny, nz = shape[0], shape[1], shape[2]
    plane = (ny * nz) << 2
    counts = np.zeros(nx, dtype=np.int64)
    for v in range(v0, v1):
        key = _vertex_key(
            edges[v, 0], edges[v, 1], edges[v, 2], edges[v, 3], moved[v],
            verts[v, 0], verts[v, 1], verts[v, 2], shift, nx, ny, nz,
        )  # fmt: skip
        if key >= 0:
            counts[key // plane] += 1
    size, down = _table_size(counts.max())
    mask = size - 1
    tables = np.full((2, 2 * size), -1, dtype=np.int64)
    any_merge = False
    low = nx
    top = np.int64(-1)
    for v in range(v0, v1):
        target[v] = v
        key = _vertex_key(
            edges[v, 0], edges[v, 1], edges[v, 2], edges[v, 3], moved[v],
            verts[v, 0], verts[v, 1], verts[v, 2], shift, nx, ny, nz,
        )  # fmt: skip
        if key < 0:
            continue
        q = key // plane
        if q < top - 1:
            return tables, down, mask, False, False, low, top
        top = max(top, q)
        low = min(low, q)
        first = _find_or_add(tables, q % 2, key, v, down, mask, plane)
        if first != v:
            target[v] = first
            any_merge = True
    return tables, down, mask, any_merge, True, low, top


@njit(**KERNEL)
def _link_halves(verts, shift, edges, moved, shape, target, mid, tables, down, mask, top):
    """The vertices from ``mid`` on whose key the first half has too (on its last plane
    ``top`` or the one below, whose tables ``tables`` still holds) take the first half's first
    vertex of the key (:func:`_targets_in_halves`); they come before any key two planes above
    ``top`` (the second half is in plane order). Returns whether any did."""
    nx, ny, nz = shape[0], shape[1], shape[2]
    plane = (ny * nz) << 2
    linked = False
    for v in range(mid, verts.shape[0]):
        key = _vertex_key(
            edges[v, 0], edges[v, 1], edges[v, 2], edges[v, 3], moved[v],
            verts[v, 0], verts[v, 1], verts[v, 2], shift, nx, ny, nz,
        )  # fmt: skip
        if key < 0:
            continue
        q = key // plane
        if q >= top + 2:
            break
        if q <= top:
            first = _find(tables, q % 2, key, down, mask, plane)
            if first >= 0:
                target[v] = first
                linked = True
    return linked


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
        first = _find_or_add(tables, 0, key, v, down, mask, np.int64(0))
        if first != v:
            target[v] = first
            any_merge = True
    return target, any_merge


@njit(**KERNEL)
def merge_same(vertices, faces, edges, target):
    """Give one index to the vertices of one grid edge, and to exactly coincident moved ones.

    Other vertices keep theirs even where they are close (merging distinct crossings could
    pinch the surface).  Faces that lose a corner are dropped, then unreferenced vertices (the
    others keep their order).  Shapes: ``(V, 3)`` float64 vertices, ``(F, 3)`` int64 faces,
    ``(V, 4)`` edges, ``(V,)`` targets (:func:`same_targets`); returns the kept vertices,
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


def keep_off_cell_faces(
    index: np.ndarray, faces: np.ndarray, edges: np.ndarray, moved: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Move cell-interior vertices that lie within SEPARATION of their cell's faces inside.

    Lewiner's tables put an extra vertex inside the cell of some ambiguous cases, at the mean
    of the cell's 8 corners weighted by ``1 / |value|``.  A corner whose offset is tiny next
    to the others' (a sample at or rounded onto the level: ``_TINY``, or raised only as far as
    :func:`~surfgen.generator.mesh.marching._separate` needs) outweighs them all and pulls the vertex onto itself: within
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
