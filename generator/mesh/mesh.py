"""Triangle meshes: the :class:`Mesh` type, its face kinds and areas, and extraction of
F = level from a field (marching cubes; its kernels are in :mod:`~surfgen.generator.mesh.marching`).

Files are in :mod:`surfgen.generator.mesh.formats`; a spec made into a mesh in one call is
:func:`surfgen.generator.mesh.realise.realise`.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from surfgen.generator.errors import EmptySurface, MeshError
from surfgen.generator.eval.grid import Field, Grid
from surfgen.generator.jit.options import INLINE, KERNEL
from surfgen.generator.mesh.lewiner_chunks import lewiner_cells
from surfgen.generator.mesh.marching import _offsets, mixed_cells
from surfgen.generator.mesh.placement import (
    keep_off_cell_faces,
    merge_same,
    place_vertices,
    same_targets,
)

logger = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Mesh:
    """A triangle mesh in box coordinates.

    ``vertices``: float64 ``(V, 3)``; ``faces``: int64 ``(F, 3)``, counter-clockwise seen from
    outside (normals point outward, towards F > level).  ``face_kinds``: optional uint8 ``(F,)``
    labels, what each face is (:data:`FACE_KINDS`: root, pole, jump, cap); set by
    :func:`surfgen.generator.mesh.walls.label_walls` and written by
    :func:`surfgen.generator.mesh.formats.save_mesh` (``--walls mark``); operations that make
    new meshes drop them.  All arrays are read-only.
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


@njit(**KERNEL)
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
        a = face_area(v, f[n, 0], f[n, 1], f[n, 2])
        total += a
        if kinds[n] == POLE or kinds[n] == JUMP:  # noqa: SIM109 (numba)
            wall += a
    return wall, total


def face_areas(mesh: Mesh) -> np.ndarray:
    """Area of each face, shape ``(F,)``."""
    out = np.empty(mesh.n_faces)
    _face_areas(mesh.vertices, mesh.faces, out)
    return out


@njit(**INLINE)
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


@njit(**INLINE)
def face_area(v, i0, i1, i2):
    """``0.5 |(v[i1] - v[i0]) x (v[i2] - v[i0])|`` (:func:`face_cross`): the area of one face,
    the same bits as :func:`face_areas` gives it."""
    x, y, z = face_cross(v, i0, i1, i2)
    return 0.5 * math.sqrt(x * x + y * y + z * z)


@njit(**KERNEL)
def _face_areas(v, f, out):
    """``0.5 |(v1 - v0) x (v2 - v0)|`` per face (:func:`face_area`; one pass without
    temporaries)."""
    for n in range(f.shape[0]):
        out[n] = face_area(v, f[n, 0], f[n, 1], f[n, 2])


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

    Vertices are placed robustly: each lies on one crossing edge at least
    :data:`~surfgen.generator.mesh.marching.SEPARATION`
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

    Everything runs in numba kernels, one pass each; marching cubes is skimage's Lewiner
    algorithm ported to numba (:mod:`~surfgen.generator.mesh.sparse_lewiner`, the sparse
    path's too), over only the cells whose corners are on both sides (the other cells make no
    triangle): vertices and faces are those of the step-by-step numpy version with skimage's
    ``marching_cubes`` that this replaced, bit for bit (``tests/generator/mesh/test_mesh.py``
    compares them), in less than half of skimage's time on the sampler's 64³ fields.
    """
    values = np.ascontiguousarray(field.values, dtype=np.float64)
    work, n_inside = _offsets(values, level, pad=cap)
    if n_inside == 0:
        raise EmptySurface(_empty_message("outside", level, field))
    if n_inside == values.size:
        raise EmptySurface(_empty_message("inside", level, field))
    # skimage's marching cubes ('descent': "values grow outward", normals towards F > level)
    # on the cells with both signs: the Lewiner pass the sparse path runs too
    keys, corners = mixed_cells(work)
    verts, faces, centres = lewiner_cells([keys, corners], work.shape[2], work.shape[1])
    return finish_marching(verts, faces, centres, field.grid, level, cap)


def finish_marching(
    verts: np.ndarray,
    faces: np.ndarray,
    centres: np.ndarray,
    grid: Grid,
    level: float,
    cap: bool,
    threads: int = 1,
    spare: list[np.ndarray] | None = None,
) -> tuple[Mesh, np.ndarray]:
    """The end of :func:`extract_with_edges` after marching cubes (``verts``, ``faces``: what
    skimage's ``marching_cubes`` gives, in index coordinates, with the cap's pad when
    ``cap``; ``centres``: the vertices it made at a cell's centre): vertices placed on the
    box, interior vertices kept off their cell's faces, one vertex per grid edge
    (:mod:`~surfgen.generator.mesh.placement`; ``threads`` place a large mesh's vertices in
    runs at once; ``spare``: memory done with, for the placement's arrays). The sparse path
    (:mod:`~surfgen.generator.mesh.sparse_marching`) ends here too."""
    lo = np.asarray(grid.box.lo, dtype=np.float64)
    hi = np.asarray(grid.box.hi, dtype=np.float64)
    spacing = np.asarray(grid.spacing, dtype=np.float64)
    shape = np.asarray(grid.shape, dtype=np.int64)
    verts = np.ascontiguousarray(verts, dtype=np.float32)
    shift = 1.0 if cap else 0.0
    vertices, edges, moved, off_cell = place_vertices(
        verts, shift, shape, lo, hi, spacing, threads, spare
    )
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if off_cell:
        index = verts.astype(np.float64) - shift
        inner = keep_off_cell_faces(index, faces, edges, moved)
        if inner is not None:
            rows, index_rows = inner
            vertices[rows] = lo + index_rows * spacing
    # One point, one vertex: crossings towards the pad (cap) sit half a cell outside the box
    # and clamping put them on the box sample they came from, so a sample on a box edge
    # (corner) has two (three) copies; and the centre vertex of an ambiguous cell, drawn to a
    # corner near the level, can land on a crossing edge's vertex, joined to it by a
    # zero-area triangle. Give each such group one index and drop the triangles that collapse.
    target = same_targets(verts, shift, edges, moved, centres, shape)
    if target is not None:
        vertices, faces, edges = merge_same(vertices, faces, edges, target)
    logger.debug(
        "extract_mesh: %d vertices, %d faces (level %g, cap %s)",
        len(vertices),
        len(faces),
        level,
        cap,
    )
    return Mesh(vertices, faces), edges


def _empty_message(where: str, level: float, field: Field) -> str:
    n = field.values.size
    bad = field.nonfinite
    detail = f", {bad} of them non-finite (counted as outside)" if bad else ""
    rule = "F < level" if where == "inside" else "F >= level or non-finite"
    return f"no surface: all {n} samples are {where} ({rule}, level {level:g}){detail}"
