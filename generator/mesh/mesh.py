"""Triangle meshes: the :class:`Mesh` type, extraction of F = level from a field, and file I/O."""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from numba import njit
from skimage.measure import marching_cubes

from surfgen.generator.errors import EmptySurface, MeshError
from surfgen.generator.eval.grid import Field
from surfgen.generator.files import write_atomic

logger = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Mesh:
    """A triangle mesh in box coordinates.

    ``vertices``: float64 ``(V, 3)``; ``faces``: int64 ``(F, 3)``, counter-clockwise seen from
    outside (normals point outward, towards F > level).  ``face_kinds``: optional uint8 ``(F,)``
    labels, what each face is (:data:`FACE_KINDS`: root, pole, jump, cap); set by
    :func:`surfgen.generator.mesh.walls.label_walls` and written by :func:`save_mesh` (``--walls
    mark``); operations that make new meshes drop them.  All arrays are read-only.
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_kinds: np.ndarray | None = None

    def __post_init__(self) -> None:
        v = np.ascontiguousarray(self.vertices, dtype=np.float64).reshape(-1, 3)
        f = np.ascontiguousarray(self.faces, dtype=np.int64).reshape(-1, 3)
        v.flags.writeable = False
        f.flags.writeable = False
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)
        if self.face_kinds is not None:
            k = np.ascontiguousarray(self.face_kinds, dtype=np.uint8).reshape(-1)
            if k.shape[0] != f.shape[0]:
                raise MeshError(f"{k.shape[0]} face kinds for {f.shape[0]} faces")
            k.flags.writeable = False
            object.__setattr__(self, "face_kinds", k)

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])


# What a face of an extracted mesh is (``Mesh.face_kinds``): a piece of the zero set (root), a
# wall where F passes through infinity (pole) or jumps over the level (jump), or a box cap.
ROOT, POLE, JUMP, CAP = 0, 1, 2, 3
FACE_KINDS = ("root", "pole", "jump", "cap")
WALL_KINDS = (POLE, JUMP)


def wall_fraction(mesh: Mesh) -> float | None:
    """Share of the area on wall faces (poles and jumps); None when the mesh is not labelled."""
    if mesh.face_kinds is None:
        return None
    return wall_share(mesh.vertices, mesh.faces, mesh.face_kinds)


def wall_share(vertices: np.ndarray, faces: np.ndarray, kinds: np.ndarray) -> float:
    """The wall fraction of faces labelled ``kinds`` (one numba pass, areas summed in face
    order; the classification's report and a file's labels give the same value)."""
    wall, total = _wall_areas(vertices, faces, kinds)
    return float(wall / total) if wall > 0.0 and total > 0.0 else 0.0


@njit(cache=True, nogil=True, error_model="numpy")
def _wall_areas(v, f, kinds):
    """Area on wall faces and in all (:func:`_face_areas`' areas, summed in face order); the
    areas are only computed when a face is a wall."""
    any_wall = False
    for n in range(f.shape[0]):
        if kinds[n] == POLE or kinds[n] == JUMP:  # noqa: SIM109 (numba)
            any_wall = True
            break
    if not any_wall:
        return 0.0, 0.0
    wall = 0.0
    total = 0.0
    for n in range(f.shape[0]):
        x, y, z = face_cross(v, f[n, 0], f[n, 1], f[n, 2])
        a = 0.5 * math.sqrt(x * x + y * y + z * z)
        total += a
        if kinds[n] == POLE or kinds[n] == JUMP:  # noqa: SIM109 (numba)
            wall += a
    return wall, total


# --- extraction -------------------------------------------------------------------------------

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


def face_areas(mesh: Mesh) -> np.ndarray:
    """Area of each face, shape ``(F,)``."""
    out = np.empty(mesh.n_faces)
    _face_areas(mesh.vertices, mesh.faces, out)
    return out


@njit(cache=True, nogil=True, inline="always")
def face_cross(v, i0, i1, i2):
    """``(v[i1] - v[i0]) x (v[i2] - v[i0])`` by components: the same operations in the same
    order as numpy's ``np.cross`` on whole columns (for numba kernels, one face at a time)."""
    b0 = v[i1, 0] - v[i0, 0]
    b1 = v[i1, 1] - v[i0, 1]
    b2 = v[i1, 2] - v[i0, 2]
    c0 = v[i2, 0] - v[i0, 0]
    c1 = v[i2, 1] - v[i0, 1]
    c2 = v[i2, 2] - v[i0, 2]
    return b1 * c2 - b2 * c1, b2 * c0 - b0 * c2, b0 * c1 - b1 * c0


@njit(cache=True, nogil=True, error_model="numpy")
def _face_areas(v, f, out):
    """``0.5 |(v1 - v0) x (v2 - v0)|`` per face (:func:`face_cross`; one pass without
    temporaries)."""
    for n in range(f.shape[0]):
        x, y, z = face_cross(v, f[n, 0], f[n, 1], f[n, 2])
        out[n] = 0.5 * math.sqrt(x * x + y * y + z * z)


def bbox_diagonal(mesh: Mesh) -> float:
    """Length of the bounding box's diagonal (0 for an empty mesh)."""
    if mesh.n_vertices == 0:
        return 0.0
    return float(np.linalg.norm(mesh.vertices.max(axis=0) - mesh.vertices.min(axis=0)))


def compact_mesh(vertices: np.ndarray, faces: np.ndarray) -> Mesh:
    """A mesh of ``faces`` keeping only the vertices they use, renumbered in order."""
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.reshape(-1)] = True
    renumber = np.cumsum(used) - 1
    return Mesh(vertices[used], renumber[faces])


def extract_mesh(field: Field, level: float = 0.0, cap: bool = False) -> Mesh:
    """Triangulate ``F = level`` in ``field`` (marching cubes, Lewiner) in box coordinates.

    Inside is ``F < level``, strictly: a sample exactly at the level is outside, and so is every
    non-finite sample (NaN, +inf and -inf alike).  Faces are wound so normals point outward,
    towards ``F > level``.  With ``cap=True`` the box counts as outside too, so surfaces cut by
    the box are closed by flat caps lying exactly on its faces.  Every vertex lies in the box.

    Vertices are placed robustly: each lies on one crossing edge at least :data:`SEPARATION`
    of the edge away from both samples, so no two vertices come within float32 resolution of
    each other and merging coincident or close vertices (trimesh's default load, MeshLab,
    Blender, slicers) cannot pinch the surface.

    Returns a :class:`Mesh` with ``(V, 3)`` vertices and ``(F, 3)`` faces.
    Raises :class:`EmptySurface` when every sample is inside or every sample is outside.
    """
    return extract_with_edges(field, level, cap)[0]


def extract_with_edges(
    field: Field, level: float = 0.0, cap: bool = False
) -> tuple[Mesh, np.ndarray]:
    """:func:`extract_mesh`, and the grid edge each vertex lies on.

    Returns the mesh and an int64 ``(V, 4)`` array ``(axis, i, j, k)``: the vertex lies on the
    edge from sample ``(i, j, k)`` to its neighbour one step along ``axis`` (0, 1, 2 for x, y,
    z); ``axis`` is -1 for vertices on no edge of the grid (cap vertices on box samples, and
    the few vertices marching cubes puts inside a cell to resolve ambiguous cases).

    Everything around marching cubes runs in numba kernels, one pass each, and marching cubes
    visits only the cells whose corners are on both sides (its ``mask``): the other cells make
    no triangle, so vertices and faces are those of the step-by-step numpy version this
    replaced, bit for bit (``tests/generator/test_mesh.py`` compares them).
    """
    values = np.ascontiguousarray(field.values, dtype=np.float64)
    work, inside, n_inside = _offsets(values, level)
    if n_inside == 0:
        raise EmptySurface(_empty_message("outside", level, field))
    if n_inside == inside.size:
        raise EmptySurface(_empty_message("inside", level, field))
    if cap:
        work = _pad_outside(work)
    # 'descent' is skimage's winding for "values grow outward": normals towards F > level.
    verts, faces, _normals, _values = marching_cubes(
        work, 0.0, gradient_direction="descent", mask=_mixed_cells(work)
    )
    grid = field.grid
    lo = np.asarray(grid.box.lo, dtype=np.float64)
    hi = np.asarray(grid.box.hi, dtype=np.float64)
    spacing = np.asarray(grid.spacing, dtype=np.float64)
    shape = np.asarray(grid.shape, dtype=np.int64)
    verts = np.ascontiguousarray(verts, dtype=np.float32)
    index, vertices, edges, moved, off_cell = _place(
        verts, 1.0 if cap else 0.0, shape, lo, hi, spacing
    )
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if off_cell:
        inner = _keep_off_cell_faces(index, faces, edges, moved)
        if inner is not None:
            rows, index_rows = inner
            vertices[rows] = lo + index_rows * spacing
    # One point, one vertex: crossings towards the pad (cap) sit half a cell outside the box
    # and clamping put them on the box sample they came from, so a sample on a box edge
    # (corner) has two (three) copies; and skimage's Lewiner tables occasionally emit two
    # vertices for one crossing edge in ambiguous cells, joined by a zero-area triangle.
    # Give each such group one index and drop the triangles that collapse.
    target = _same_targets(index, edges, moved, shape)
    if target is not None:
        vertices, faces, used = _merge_same(vertices, faces, target)
        edges = edges[used]
    logger.debug(
        "extract_mesh: %d vertices, %d faces (level %g, cap %s)",
        len(vertices),
        len(faces),
        level,
        cap,
    )
    return Mesh(vertices, faces), edges


_NB = {"cache": True, "nogil": True, "error_model": "numpy"}
_CLIP64 = float(_CLIP)  # np.clip of float64 values against the float32 bound compares in float64
_TINY32 = np.float32(_TINY)
_EDGE_LO = 0.25 * SEPARATION  # a vertex coordinate this far from a whole number is fractional
_EDGE_HI = 1.0 - 0.25 * SEPARATION
_FACE_HI = 1.0 - SEPARATION
_HASH = -7046029254386353131  # 0x9E3779B97F4A7C15 (Fibonacci hashing) as a signed int64


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


@njit(**_NB)
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
        finite = np.isfinite(x)
        d = x - level
        d = -_CLIP64 if d < -_CLIP64 else (_CLIP64 if d > _CLIP64 else d)  # NaN stays NaN
        o = np.float32(d)
        is_in = finite and x < level
        if is_in:
            n_inside += 1
            if o >= 0:
                o = -_TINY32
        elif o <= 0:
            o = _TINY32
        if not finite:
            n_bad += 1
        out[i] = o
        ins[i] = is_in
    return n_inside, n_bad


@njit(**_NB)
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


@njit(**_NB)
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


@njit(**_NB)
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


@njit(**_NB)
def _mixed_cells(work):
    """Marching cubes' mask: True at the far corner ``(i+1, j+1, k+1)`` of every cell ``(i, j,
    k)`` whose corners are not all on one side (skimage reads a cell's mask there)."""
    nx, ny, nz = work.shape
    mask = np.zeros(work.shape, dtype=np.bool_)
    for i in range(nx - 1):
        for j in range(ny - 1):
            for k in range(nz - 1):
                neg = work[i, j, k] < 0
                if (
                    (work[i, j, k + 1] < 0) != neg
                    or (work[i, j + 1, k] < 0) != neg
                    or (work[i, j + 1, k + 1] < 0) != neg
                    or (work[i + 1, j, k] < 0) != neg
                    or (work[i + 1, j, k + 1] < 0) != neg
                    or (work[i + 1, j + 1, k] < 0) != neg
                    or (work[i + 1, j + 1, k + 1] < 0) != neg
                ):
                    mask[i + 1, j + 1, k + 1] = True
    return mask


@njit(**_NB)
def _place(verts, shift, shape, lo, hi, spacing):
    """Marching cubes' float32 vertices -> grid indices, box coordinates and edges.

    ``index = verts - shift`` (1 with a cap's pad); ``lo + index * spacing``, clamped: on the
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
    index = np.empty((n, 3))
    vertices = np.empty((n, 3))
    edges = np.full((n, 4), -1, dtype=np.int64)
    moved = np.zeros(n, dtype=np.bool_)
    off_cell = False
    for v in range(n):
        n_frac = 0
        axis = 0
        near_face = False
        out = False
        for c in range(3):
            x = np.float64(verts[v, c]) - shift
            index[v, c] = x
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
                x = index[v, c]
                edges[v, 1 + c] = np.int64(np.rint(np.floor(x) if c == axis else x))
        elif not out and near_face:
            off_cell = True
    return index, vertices, edges, moved, off_cell


def _same_targets(
    index: np.ndarray, edges: np.ndarray, moved: np.ndarray, shape: np.ndarray
) -> np.ndarray | None:
    """For each vertex, the first vertex of its group (:func:`_merge_same`), or None when every
    vertex is alone."""
    target = np.empty(len(index), dtype=np.int64)
    if not _targets_kernel(index, edges, moved, shape, target):
        return None
    return target


@njit(**_NB)
def _targets_kernel(index, edges, moved, shape, target):
    """The vertices of one grid edge form a group, and moved vertices clamped onto one box
    sample; others are alone.  ``target[v]``: the first vertex of ``v``'s group (an open
    addressing hash of the keys); returns whether any vertex is not its own target."""
    n = index.shape[0]
    nx, ny, nz = shape[0], shape[1], shape[2]
    size = 1
    while size < 2 * n + 2:
        size *= 2
    keys = np.full(size, -1, dtype=np.int64)
    firsts = np.empty(size, dtype=np.int64)
    any_merge = False
    for v in range(n):
        target[v] = v
        if edges[v, 0] >= 0:
            key = ((edges[v, 0] * nx + edges[v, 1]) * ny + edges[v, 2]) * nz + edges[v, 3]
        elif moved[v]:
            # A moved vertex was clamped onto a box sample: the sample's number is its key.
            s0 = min(max(np.int64(np.rint(index[v, 0])), 0), nx - 1)
            s1 = min(max(np.int64(np.rint(index[v, 1])), 0), ny - 1)
            s2 = min(max(np.int64(np.rint(index[v, 2])), 0), nz - 1)
            key = 3 * nx * ny * nz + (s0 * ny + s1) * nz + s2
        else:
            continue
        h = (key * _HASH) & (size - 1)
        while True:
            if keys[h] == -1:
                keys[h] = key
                firsts[h] = v
                break
            if keys[h] == key:
                target[v] = firsts[h]
                any_merge = True
                break
            h = (h + 1) & (size - 1)
    return any_merge


def _merge_same(
    vertices: np.ndarray, faces: np.ndarray, target: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Give one index to the vertices of one grid edge, and to exactly coincident moved ones.

    Other vertices keep theirs even where they are close (merging distinct crossings could
    pinch the surface).  Faces that lose a corner are dropped, then unreferenced vertices (the
    others keep their order).  Shapes: ``(V, 3)`` float64 vertices, ``(F, 3)`` int64 faces,
    ``(V,)`` targets (:func:`_same_targets`); also returns the ``(V,)`` bool mask of the
    vertices kept.
    """
    faces, used, renumber = _merge_kernel(faces, target)
    return vertices[used], renumber[faces], used


@njit(**_NB)
def _merge_kernel(faces, target):
    """Faces on the targets without the collapsed ones, the used vertices and their new
    numbers."""
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
    return out[:m], used, renumber


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


def _empty_message(where: str, level: float, field: Field) -> str:
    n = field.values.size
    bad = field.nonfinite
    detail = f", {bad} of them non-finite (counted as outside)" if bad else ""
    rule = "F < level" if where == "inside" else "F >= level or non-finite"
    return f"no surface: all {n} samples are {where} ({rule}, level {level:g}){detail}"


# --- files ------------------------------------------------------------------------------------

# suffix -> (trimesh file type, export options); STL and PLY binary keep files small and exact.
_FORMATS: dict[str, tuple[str, dict]] = {
    ".ply": ("ply", {"encoding": "binary"}),
    ".obj": ("obj", {"include_normals": False, "include_texture": False}),
    ".stl": ("stl", {}),
    ".off": ("off", {}),
    ".glb": ("glb", {}),
}
MESH_SUFFIXES = tuple(_FORMATS)


def _file_type(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in _FORMATS:
        raise MeshError(
            f"cannot tell the mesh format of '{path.name}': "
            f"the suffix must be one of {', '.join(MESH_SUFFIXES)}"
        )
    return suffix


def save_mesh(mesh: Mesh, path: str | os.PathLike) -> Path:
    """Write ``mesh`` to ``path`` in the format its suffix names (.ply .obj .stl .off .glb).

    The file appears complete or not at all (temporary file + ``os.replace``).  A mesh with
    ``face_kinds`` is written marked: PLY gets a uchar face property ``kind`` (0 root, 1 pole,
    2 jump, 3 cap) and face colours, GLB vertex colours (:data:`KIND_COLOURS`; a vertex takes the
    colour of a wall if any face around it is one).  Returns the path.
    Raises :class:`MeshError` for an unknown suffix or a file that cannot be written.
    """
    path = Path(path)
    data = mesh_bytes(mesh, path)
    try:
        write_atomic(path, data)
    except OSError as exc:
        raise MeshError(f"cannot write '{path}': {exc.strerror}") from None
    logger.debug("save_mesh: %s (%d faces)", path, mesh.n_faces)
    return path


# sRGBA of each face kind in marked files: roots and caps neutral, poles red, jumps orange.
KIND_COLOURS = np.array(
    [[200, 200, 200, 255], [214, 39, 40, 255], [255, 127, 14, 255], [160, 160, 160, 255]],
    dtype=np.uint8,
)


def _add_kinds(tm: trimesh.Trimesh, mesh: Mesh) -> None:
    """Attach ``mesh.face_kinds`` to ``tm`` as the ``kind`` face attribute and colours."""
    kinds = np.asarray(mesh.face_kinds)
    tm.face_attributes["kind"] = kinds.astype(np.uint8)
    if mesh.n_faces == 0:
        return
    # A vertex is painted as its most wall-like face: pole over jump over root/cap.
    rank = np.array([0, 2, 1, 0], dtype=np.int64)[kinds]
    best = np.zeros(mesh.n_vertices, dtype=np.int64)
    np.maximum.at(best, mesh.faces.reshape(-1), np.repeat(rank, 3))
    vertex_kind = np.array([ROOT, JUMP, POLE])[best]
    tm.visual = trimesh.visual.ColorVisuals(
        tm, face_colors=KIND_COLOURS[kinds], vertex_colors=KIND_COLOURS[vertex_kind]
    )


def mesh_bytes(mesh: Mesh, path: str | os.PathLike) -> bytes:
    """The file :func:`save_mesh` would write to ``path``, in memory (its suffix names the
    format). Raises :class:`MeshError` for an unknown suffix."""
    suffix = _file_type(Path(path))
    file_type, options = _FORMATS[suffix]
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    if mesh.face_kinds is not None and suffix in (".ply", ".glb"):
        _add_kinds(tm, mesh)
    data = tm.export(file_type=file_type, **options)
    return data.encode("utf-8") if isinstance(data, str) else data


def load_mesh(path: str | os.PathLike) -> Mesh:
    """Read a mesh written by :func:`save_mesh` (or any triangle mesh in those formats).

    Indexed formats keep their vertex order; STL, which stores each triangle's corners apart,
    gets exactly coincident corners merged.  Returns ``(V, 3)`` vertices and ``(F, 3)`` faces.
    Raises :class:`MeshError` for an unknown suffix, a missing file, or one that is not a
    readable triangle mesh.
    """
    path = Path(path)
    suffix = _file_type(path)
    if not path.is_file():
        raise MeshError(f"no mesh file '{path}'")
    size = path.stat().st_size
    if size > MAX_MESH_FILE_BYTES:
        raise MeshError(
            f"'{path}' is {size / 2**30:.1f} GiB: larger than the {MAX_MESH_FILE_BYTES >> 30} GiB "
            "a mesh file may have"
        )
    if suffix == ".obj":
        _check_obj_indices(path)
    try:
        loaded = trimesh.load(path, file_type=_FORMATS[suffix][0], force="mesh", process=False)
    # trimesh's readers fail on corrupt files with assorted exception types; all mean "unreadable".
    except Exception as exc:
        raise MeshError(f"cannot read '{path}' as {suffix[1:]}: {exc}") from exc
    faces = getattr(loaded, "faces", None)
    if faces is None or len(faces) == 0:
        raise MeshError(f"'{path}' holds no triangles")
    vertices = np.asarray(loaded.vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise MeshError(f"'{path}': a face refers to a vertex that does not exist")
    if not np.isfinite(vertices).all():
        raise MeshError(f"'{path}' holds non-finite vertex coordinates")
    if suffix == ".stl":
        vertices, faces = _merge_exact(vertices, faces)
    return Mesh(vertices, faces, _read_kinds(loaded, len(faces)))


def _read_kinds(loaded: trimesh.Trimesh, n_faces: int) -> np.ndarray | None:
    """The ``kind`` face property of a marked PLY (see :func:`save_mesh`), else None."""
    raw = (getattr(loaded, "metadata", None) or {}).get("_ply_raw", {})
    try:
        kinds = np.asarray(raw["face"]["data"]["kind"]).reshape(-1)
    except (KeyError, ValueError, TypeError, IndexError):
        return None
    if kinds.shape[0] != n_faces or kinds.size == 0 or kinds.max() >= len(FACE_KINDS):
        return None
    return kinds.astype(np.uint8)


MAX_MESH_FILE_BYTES = 4 << 30  # 4 GiB: ~100 M faces of binary PLY


def _check_obj_indices(path: Path) -> None:
    """OBJ counts vertices from 1 (negative: from the end); 0 is no vertex, and trimesh would
    silently read it as the last one."""
    with open(path, "rb") as f:
        for number, line in enumerate(f, start=1):
            if not line.startswith(b"f ") and not line.startswith(b"f\t"):
                continue
            for item in line.split()[1:]:
                head = item.split(b"/", 1)[0]
                if head in (b"0", b"-0", b"+0"):
                    raise MeshError(
                        f"'{path}' line {number}: face index 0 (OBJ vertex indices start at 1)"
                    )


def _merge_exact(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Give bit-identical vertices one index (no tolerance, so distinct points stay apart)."""
    unique, inverse = np.unique(vertices, axis=0, return_inverse=True)
    return unique, inverse.reshape(-1)[faces]
