"""Triangle meshes: the :class:`Mesh` type, extraction of F = level from a field, and file I/O."""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
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
    outside (normals point outward, towards F > level). Both arrays are read-only.
    """

    vertices: np.ndarray
    faces: np.ndarray

    def __post_init__(self) -> None:
        v = np.ascontiguousarray(self.vertices, dtype=np.float64).reshape(-1, 3)
        f = np.ascontiguousarray(self.faces, dtype=np.int64).reshape(-1, 3)
        v.flags.writeable = False
        f.flags.writeable = False
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])


# --- extraction -------------------------------------------------------------------------------

# skimage runs marching cubes in float32, so we hand it float32 offsets from the level whose signs
# we have fixed ourselves; magnitudes are clipped to stay finite there.
_CLIP = np.float32(1e30)
_TINY = np.float32(np.finfo(np.float32).smallest_normal)


def face_areas(mesh: Mesh) -> np.ndarray:
    """Area of each face, shape ``(F,)``."""
    v, f = mesh.vertices, mesh.faces
    return 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)


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

    Returns a :class:`Mesh` with ``(V, 3)`` vertices and ``(F, 3)`` faces.
    Raises :class:`EmptySurface` when every sample is inside or every sample is outside.
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
    np.clip(vertices, lo, hi, out=vertices)
    faces = faces.astype(np.int64)
    if cap:
        # Crossings towards the pad sit half a cell outside the box; clamping put them on the
        # box sample they came from.  A sample on a box edge (corner) has two (three) of them:
        # merge those copies and drop the triangles that collapse.
        moved = np.any((index < 0.0) | (index > np.asarray(grid.shape) - 1.0), axis=1)
        vertices, faces = _merge_moved(vertices, faces, moved)
    logger.debug(
        "extract_mesh: %d vertices, %d faces (level %g, cap %s)",
        len(vertices),
        len(faces),
        level,
        cap,
    )
    return Mesh(vertices, faces)


def _offsets(values: np.ndarray, level: float) -> tuple[np.ndarray, np.ndarray]:
    """float32 ``F - level`` with signs decided in float64, and the boolean inside mask.

    Inside samples get a strictly negative offset, all others a strictly positive one, so
    marching cubes never sees a sample on the level (where ``<`` vs ``<=`` would decide the
    topology).  A non-finite sample gets a positive value mirroring the deepest inside sample
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
    return offset, inside


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


def _merge_moved(
    vertices: np.ndarray, faces: np.ndarray, moved: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Give exactly coincident moved vertices one index.

    Other vertices keep theirs even where they coincide (a sample exactly on the level puts
    several crossings on it): merging those can pinch the surface, keeping them keeps the
    topology marching cubes chose.  Faces that lose a corner are dropped, then unreferenced
    vertices.  Shapes: ``(V, 3)`` float64 vertices, ``(F, 3)`` int64 faces, ``(V,)`` bool moved.
    """
    idx = np.flatnonzero(moved)
    _, first, inverse = np.unique(vertices[idx], axis=0, return_index=True, return_inverse=True)
    target = np.arange(len(vertices))
    target[idx] = idx[first[inverse.reshape(-1)]]
    faces = target[faces]
    keep = (
        (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    )
    faces = faces[keep]
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.reshape(-1)] = True
    renumber = np.cumsum(used) - 1
    return vertices[used], renumber[faces]


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

    The file appears complete or not at all (temporary file + ``os.replace``).  Returns the path.
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


def mesh_bytes(mesh: Mesh, path: str | os.PathLike) -> bytes:
    """The file :func:`save_mesh` would write to ``path``, in memory (its suffix names the
    format). Raises :class:`MeshError` for an unknown suffix."""
    file_type, options = _FORMATS[_file_type(Path(path))]
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
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
    return Mesh(vertices, faces)


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
