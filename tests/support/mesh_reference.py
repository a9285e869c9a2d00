"""The mesh stage before its numba rewrite (issue 13): numpy, step by step, as it was on main.

A straightforward reference for the fast path in :mod:`surfgen.generator.mesh.mesh`: the tests
compare meshes and edges bit for bit with it, and ``benchmarks/mesh_stage.py`` times it as the
baseline.  Not part of the library.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import maximum_filter
from skimage.measure import marching_cubes

from surfgen.generator.errors import EmptySurface
from surfgen.generator.eval.grid import Field
from surfgen.generator.mesh.marching import _CLIP, _RATIO, _TINY, SEPARATION
from surfgen.generator.mesh.mesh import Mesh, _empty_message

# the sweeps over the crossing edges at most (the fixed point is reached long before)
_MAX_ROUNDS = 200


def skimage_mask(work: np.ndarray) -> np.ndarray:
    """skimage's ``mask`` for the cells with both signs: True at each such cell's far corner
    (where skimage reads a cell's mask)."""
    neg = work < 0
    n0, n1, n2 = (n - 1 for n in neg.shape)
    cells = [
        neg[a : a + n0, b : b + n1, c : c + n2] for a in (0, 1) for b in (0, 1) for c in (0, 1)
    ]
    mask = np.zeros(work.shape, dtype=bool)
    mask[1:, 1:, 1:] = np.any(cells, axis=0) & ~np.all(cells, axis=0)
    return mask


def reference_extract_with_edges(
    field: Field, level: float = 0.0, cap: bool = False
) -> tuple[Mesh, np.ndarray]:
    """:func:`extract_mesh`, and the grid edge each vertex lies on.

    Returns the mesh and an int64 ``(V, 4)`` array ``(axis, i, j, k)``: the vertex lies on the
    edge from sample ``(i, j, k)`` to its neighbour one step along ``axis`` (0, 1, 2 for x, y,
    z); ``axis`` is -1 for vertices on no edge of the grid (cap vertices on box samples, and
    the few vertices marching cubes puts inside a cell to resolve ambiguous cases).
    """
    work, inside = _offsets(field.values, level)
    n_inside = int(np.count_nonzero(inside))
    if n_inside == 0:
        raise EmptySurface(_empty_message("outside", level, field))
    if n_inside == inside.size:
        raise EmptySurface(_empty_message("inside", level, field))
    if cap:
        work = _pad_outside(work)
    # 'descent' is skimage's winding for "values grow outward": normals towards F > level.
    verts, faces, _normals, _values = marching_cubes(work, 0.0, gradient_direction="descent")
    grid = field.grid
    lo = np.asarray(grid.box.lo, dtype=np.float64)
    hi = np.asarray(grid.box.hi, dtype=np.float64)
    index = verts.astype(np.float64) - (1.0 if cap else 0.0)
    vertices = lo + index * np.asarray(grid.spacing, dtype=np.float64)
    # Clamping puts the cap exactly on the box faces; without a cap it only removes rounding.
    # lo + (N-1) * spacing may miss hi by an ulp: snap the last samples' coordinate onto hi, or
    # a cap vertex clamped onto hi and one computed there would differ by an ulp (distinct
    # here, one point in float32).
    last = np.asarray(grid.shape, dtype=np.float64) - 1.0
    vertices = np.where(index >= last, hi, np.where(index <= 0.0, lo, vertices))
    faces = faces.astype(np.int64)
    moved = np.any((index < 0.0) | (index > np.asarray(grid.shape) - 1.0), axis=1)
    edges = _vertex_edges(index, moved)
    inner = _keep_off_cell_faces(index, faces, edges, moved)
    if inner is not None:
        rows, index_rows = inner
        vertices[rows] = lo + index_rows * np.asarray(grid.spacing, dtype=np.float64)
    # One point, one vertex: crossings towards the pad (cap) sit half a cell outside the box
    # and clamping put them on the box sample they came from, so a sample on a box edge
    # (corner) has two (three) copies; and skimage's Lewiner tables occasionally emit two
    # vertices for one crossing edge in ambiguous cells, joined by a zero-area triangle.
    # Give each such group one index and drop the triangles that collapse.
    vertices, faces, used = _merge_same(vertices, faces, index, edges, moved, grid.shape)
    edges = edges[used]
    return Mesh(vertices, faces), edges


def _vertex_edges(index: np.ndarray, moved: np.ndarray) -> np.ndarray:
    """``(axis, i, j, k)`` of the grid edge under each vertex (see :func:`extract_with_edges`).

    A vertex on an edge has exactly one fractional index coordinate, at least SEPARATION from
    a whole number (float32 keeps ~1e-4 of it at index 2048); other vertices get axis -1.
    """
    base = np.floor(index)
    frac = index - base
    fractional = (frac > 0.25 * SEPARATION) & (frac < 1.0 - 0.25 * SEPARATION)
    on_edge = (np.count_nonzero(fractional, axis=1) == 1) & ~moved
    out = np.full((len(index), 4), -1, dtype=np.int64)
    axis = np.argmax(fractional, axis=1)
    ijk = np.rint(np.where(fractional, base, index)).astype(np.int64)
    out[on_edge, 0] = axis[on_edge]
    out[on_edge, 1:] = ijk[on_edge]
    return out


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


def _offsets(values: np.ndarray, level: float) -> tuple[np.ndarray, np.ndarray]:
    """float32 ``F - level`` with signs decided in float64, and the boolean inside mask.

    Inside samples get a strictly negative offset, all others a strictly positive one, so
    marching cubes never sees a sample on the level (where ``<`` vs ``<=`` would decide the
    topology).  Magnitudes are then raised where needed so every crossing lies at least
    SEPARATION of its edge from both samples (:func:`_separate`).  A non-finite sample gets a
    positive value mirroring the deepest inside sample
    in its 3x3x3 neighbourhood, so a crossing on an edge to it falls at mid-edge or nearer the
    inside sample (a huge value would pile the crossings onto the inside samples, +inf exactly).
    """
    values = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(values)
    with np.errstate(invalid="ignore", over="ignore"):
        inside = finite & (values < level)
        offset = np.clip(values - level, -_CLIP, _CLIP).astype(np.float32)
    # Rounding to float32 turns offsets below ~1e-45 into 0 and exact-level samples are 0:
    # give them the smallest normal float32 with the sign decided above in float64.
    offset[inside & (offset >= 0)] = -_TINY
    offset[~inside & (offset <= 0)] = _TINY
    if not finite.all():
        depth = np.where(inside, -offset, np.float32(0))
        mirror = maximum_filter(depth, size=3, mode="constant", cval=0.0)
        offset[~finite] = np.maximum(mirror[~finite], _TINY)
    return _separate(offset), inside


def _separate(offset: np.ndarray) -> np.ndarray:
    """Raise ``|offset|`` until ``|a| >= _RATIO |b|`` for both samples of every crossing edge.

    Marching cubes puts the crossing of edge (a, b) at ``t = a / (a - b)``; a sample at or near
    the level next to a large opposite value (staircase plateaus at the level, exact zeros,
    samples beside a pole) would put it on the sample itself, and several crossings would
    coincide there once stored in float32.  Raising a magnitude never changes a sign, so the
    same edges cross; it moves a crossing at most SEPARATION of the edge (in a locally linear
    field the distance to the true surface grows by at most _RATIO of a cell).  A raise can
    require a raise of the sample's own opposite neighbours, each _RATIO smaller, so the loop
    ends after a few rounds (float32's range bounds it by ~40).
    """
    neg = offset < 0
    shape = offset.shape
    ends_a, ends_b = [], []
    for axis in range(offset.ndim):
        a = [slice(None)] * offset.ndim
        b = [slice(None)] * offset.ndim
        a[axis], b[axis] = slice(None, -1), slice(1, None)
        crossing = np.nonzero(neg[tuple(a)] != neg[tuple(b)])
        ends_a.append(np.ravel_multi_index(crossing, shape))
        moved = list(crossing)
        moved[axis] = moved[axis] + 1
        ends_b.append(np.ravel_multi_index(tuple(moved), shape))
    ia, ib = np.concatenate(ends_a), np.concatenate(ends_b)
    mag = np.abs(offset).astype(np.float64).reshape(-1)
    # Only samples on crossing edges matter: work on the (few) edges, not the whole grid.
    for _ in range(_MAX_ROUNDS):
        need_a, need_b = _RATIO * mag[ib], _RATIO * mag[ia]
        grow_a, grow_b = need_a > mag[ia], need_b > mag[ib]
        if not (grow_a.any() or grow_b.any()):
            break
        np.maximum.at(mag, ia[grow_a], need_a[grow_a])
        np.maximum.at(mag, ib[grow_b], need_b[grow_b])
    mag = mag.reshape(shape)
    out = mag.astype(np.float32)
    np.negative(out, out=out, where=neg)
    return out


def _pad_outside(work: np.ndarray) -> np.ndarray:
    """Surround ``work`` with one layer of outside samples mirroring their box neighbour.

    Mirroring (``|w|`` next to ``w``) puts every crossing towards the pad exactly half a cell
    outside the box, where it is told apart from the crossings inside and clamped onto the box.
    """
    padded = np.abs(np.pad(work, 1, mode="edge"))
    padded[1:-1, 1:-1, 1:-1] = work
    return padded


def _merge_same(
    vertices: np.ndarray,
    faces: np.ndarray,
    index: np.ndarray,
    edges: np.ndarray,
    moved: np.ndarray,
    shape: tuple[int, int, int],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Give one index to the vertices of one grid edge, and to exactly coincident moved ones.

    Other vertices keep theirs even where they are close (merging distinct crossings could
    pinch the surface).  Faces that lose a corner are dropped, then unreferenced vertices.
    Shapes: ``(V, 3)`` float64 vertices, ``(F, 3)`` int64 faces, ``(V, 3)`` grid indices,
    ``(V, 4)`` edges, ``(V,)`` bool moved; also returns the ``(V,)`` bool mask of the vertices kept.
    """
    n = len(vertices)
    nx, ny, nz = shape
    on_edge = edges[:, 0] >= 0
    key = np.arange(n, dtype=np.int64) + 4 * nx * ny * nz  # unique unless grouped below
    # (keys: edges below 3 N, box samples below 4 N, the others above; N = nx * ny * nz)
    e = edges[on_edge]
    key[on_edge] = ((e[:, 0] * nx + e[:, 1]) * ny + e[:, 2]) * nz + e[:, 3]
    # A moved vertex was clamped onto a box sample: the sample's number is its key.
    snapped = np.clip(np.rint(index[moved]).astype(np.int64), 0, np.asarray(shape) - 1)
    key[moved] = 3 * nx * ny * nz + (snapped[:, 0] * ny + snapped[:, 1]) * nz + snapped[:, 2]
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    target = first[inverse.reshape(-1)]
    if np.array_equal(target, np.arange(n)):
        return vertices, faces, np.ones(n, dtype=bool)
    faces = target[faces]
    keep = (
        (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    )
    faces = faces[keep]
    used = np.zeros(n, dtype=bool)
    used[faces.reshape(-1)] = True
    renumber = np.cumsum(used) - 1
    return vertices[used], renumber[faces], used
