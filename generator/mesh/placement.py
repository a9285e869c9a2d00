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
    centres: np.ndarray,
    shape: np.ndarray,
) -> np.ndarray | None:
    """For each vertex, the first vertex of its group (:func:`merge_same`), or None when every
    vertex is alone (``verts - shift``: the vertices' grid indices, :func:`_place_range`;
    ``centres``: the vertices marching cubes made at a cell's centre, ascending).

    Marching cubes makes one vertex per crossing edge (its face layers hand an edge's vertex
    to every cell of the edge, plane after plane: :mod:`~surfgen.generator.mesh.sparse_lewiner`),
    so two vertices are one point only where one of them is

    - moved: a cap's crossing towards the pad, clamped onto the box sample it came from (a
      sample on a box edge or corner gets two or three): these group among themselves, in a
      table of the moved vertices alone (:func:`_targets_kernel`);
    - a cell's centre drawn onto a grid edge (its weights dominated by a corner close to the
      level): its edge's group is found in one pass over the vertices, looking each up in a
      table of those edges alone (:func:`_edge_groups`; rare).

    ``tests/generator/mesh/test_placement.py`` checks on meshes full of ambiguous cells that a
    table of every vertex finds the same groups. Sculpture-1 at 512^3 (790,000 vertices, none
    moved, no centre on an edge): 16 ms -> 0.2 ms, where that table found nothing to merge."""
    rows = np.flatnonzero(moved)
    on_edge = centres[edges[centres, 0] >= 0]
    if rows.size == 0 and on_edge.size == 0:
        return None
    target = np.arange(len(verts), dtype=np.int64)
    merged = False
    if rows.size:
        first, merged = _targets_kernel(verts[rows], shift, edges[rows], moved[rows], shape)
        target[rows] = rows[first]
    if on_edge.size:
        merged |= _edge_groups(edges, on_edge, shape, target)
    return target if merged else None


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
def _slot(table, key, down, mask):
    """The slot of ``key`` in the open-addressing ``table`` of ``(key, vertex)`` slots, or the
    free slot where it would go. The probe starts at the key's run of ``2**_RUN`` slots,
    placed by Fibonacci hashing of the run's number (its top ``64 - down`` bits), at the key's
    place in the run. Given the table (not a view of it) and with one exit, it leaves no
    reference count in the callers' loops (their test)."""
    run = (np.uint64(key >> _RUN) * np.uint64(_HASH_U)) >> down
    h = np.int64(run) << _RUN | (key & ((1 << _RUN) - 1))
    while table[2 * h] != key and table[2 * h] != -1:
        h = (h + 1) & mask
    return h


@njit(**INLINE)
def _find_or_add(table, key, v, down, mask):
    """The first vertex of ``key`` in ``table`` (:func:`_slot`); ``v`` where the key is new
    (then added)."""
    h = _slot(table, key, down, mask)
    if table[2 * h] != key:  # a free slot: the key is new
        table[2 * h] = key
        table[2 * h + 1] = v
    return table[2 * h + 1]


@njit(**KERNEL)
def _targets_kernel(verts, shift, edges, moved, shape):
    """The vertices of one grid edge form a group, and moved vertices clamped onto one box
    sample; others are alone.  Returns ``target`` (``target[v]``: the first vertex of ``v``'s
    group) and whether any vertex is not its own target.

    The groups are found in an open-addressing table of their keys (:func:`_vertex_key`), so
    the keys of one sample's edges and of a row's samples are close; runs of ``2**_RUN`` keys
    keep their order in the table (the run's number is hashed), so the vertices of a row of
    cells, which marching cubes emits together, probe a few cache lines rather than one each.
    """
    n = verts.shape[0]
    nx, ny, nz = shape[0], shape[1], shape[2]
    size, down = _table_size(n)
    mask = size - 1
    table = np.full(2 * size, -1, dtype=np.int64)  # (key, first vertex) slots
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
        first = _find_or_add(table, key, v, down, mask)
        if first != v:
            target[v] = first
            any_merge = True
    return target, any_merge


@njit(**INLINE)
def _edge_key(axis, e1, e2, e3, nx, ny, nz):
    """:func:`_vertex_key` of a vertex that is not moved: its edge's key, -1 on no edge."""
    return _vertex_key(axis, e1, e2, e3, False, 0.0, 0.0, 0.0, 0.0, nx, ny, nz)


@njit(**KERNEL)
def _edge_groups(edges, on_edge, shape, target):
    """The groups of the grid edges of the vertices ``on_edge`` (cells' centres placed on an
    edge, :func:`same_targets`): a table of those edges alone, then every vertex on an edge,
    in order, looked up in it; a vertex whose edge an earlier vertex holds takes that one as
    its target (into ``target``). Returns whether any did."""
    nx, ny, nz = shape[0], shape[1], shape[2]
    size, down = _table_size(on_edge.size)
    mask = size - 1
    table = np.full(2 * size, -1, dtype=np.int64)  # (key, first vertex) slots
    unseen = np.int64(edges.shape[0])  # a key of the table no vertex has reached yet
    for q in range(on_edge.size):
        v = on_edge[q]
        key = _edge_key(edges[v, 0], edges[v, 1], edges[v, 2], edges[v, 3], nx, ny, nz)
        _find_or_add(table, key, unseen, down, mask)
    merged = False
    for v in range(edges.shape[0]):
        key = _edge_key(edges[v, 0], edges[v, 1], edges[v, 2], edges[v, 3], nx, ny, nz)
        if key < 0:  # on no edge
            continue
        h = _slot(table, key, down, mask)
        if table[2 * h] != key:
            continue
        if table[2 * h + 1] == unseen:
            table[2 * h + 1] = v
        else:
            target[v] = table[2 * h + 1]
            merged = True
    return merged


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
