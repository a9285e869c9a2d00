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
from scipy.ndimage import maximum_filter
from skimage.measure import marching_cubes

from surfgen.generator.errors import EmptySurface, MeshError
from surfgen.generator.files import write_atomic
from surfgen.generator.grid import Field

logger = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Mesh:
    """A triangle mesh in box coordinates.

    ``vertices``: float64 ``(V, 3)``; ``faces``: int64 ``(F, 3)``, counter-clockwise seen from
    outside (normals point outward, towards F > level).  ``face_kinds``: optional uint8 ``(F,)``
    labels, what each face is (:data:`FACE_KINDS`: root, pole, jump, cap); set by
    :func:`surfgen.generator.walls.label_walls` and written by :func:`save_mesh` (``--walls
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
    kinds = mesh.face_kinds
    wall = (kinds == POLE) | (kinds == JUMP)
    if not wall.any():
        return 0.0
    areas = face_areas(mesh)
    total = float(areas.sum())
    return float(areas[wall].sum()) / total if total > 0 else 0.0


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


@njit(cache=True, nogil=True, error_model="numpy")
def _face_areas(v, f, out):
    """``0.5 |(v1 - v0) x (v2 - v0)|`` per face, the cross product by components (the same
    operations in the same order as numpy on whole columns, one pass without temporaries)."""
    for n in range(f.shape[0]):
        i0, i1, i2 = f[n, 0], f[n, 1], f[n, 2]
        b0 = v[i1, 0] - v[i0, 0]
        b1 = v[i1, 1] - v[i0, 1]
        b2 = v[i1, 2] - v[i0, 2]
        c0 = v[i2, 0] - v[i0, 0]
        c1 = v[i2, 1] - v[i0, 1]
        c2 = v[i2, 2] - v[i0, 2]
        x = b1 * c2 - b2 * c1
        y = b2 * c0 - b0 * c2
        z = b0 * c1 - b1 * c0
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
    logger.debug(
        "extract_mesh: %d vertices, %d faces (level %g, cap %s)",
        len(vertices),
        len(faces),
        level,
        cap,
    )
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


def _empty_message(where: str, level: float, field: Field) -> str:
    n = field.values.size
    bad = field.nonfinite
    detail = f", {bad} of them non-finite (counted as outside)" if bad else ""
    rule = "F < level" if where == "inside" else "F >= level or non-finite"
    return f"no surface: all {n} samples are {where} ({rule}, level {level:g}){detail}"


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
