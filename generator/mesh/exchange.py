"""Mesh files: the one encoder (:func:`encode_mesh`; GLB by :func:`glb_bytes`), and
:func:`save_mesh` / :func:`load_mesh`, for the formats of
:data:`~surfgen.generator.mesh.formats.FORMATS`.

trimesh reads the files and writes them, but for the formats surfgen writes itself
(:data:`OWN_WRITERS`: binary PLY, byte for byte as trimesh writes it; the tests compare
them): importing trimesh (with scipy and networkx) took 0.65-0.73 s of a ``render -o x.ply``
on the Zen 4, more than meshing a 512^3 sculpture, and its writer hashed the arrays it was
given (0.14 s of 0.32 s for 5.8 million faces).
"""

from __future__ import annotations

import json
import logging
import os
import struct
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from surfgen.generator.errors import MeshError
from surfgen.generator.files import write_atomic
from surfgen.generator.mesh.formats import FORMATS, MESH_SUFFIXES, Format
from surfgen.generator.mesh.mesh import FACE_KINDS, JUMP, POLE, ROOT, Mesh

if TYPE_CHECKING:
    import trimesh

logger = logging.getLogger(__name__)

# sRGBA of each face kind in marked files: roots and caps neutral, poles red, jumps orange.
KIND_COLOURS = np.array(
    [[200, 200, 200, 255], [214, 39, 40, 255], [255, 127, 14, 255], [160, 160, 160, 255]],
    dtype=np.uint8,
)
MAX_MESH_FILE_BYTES = 4 << 30  # 4 GiB: ~100 M faces of binary PLY


def _trimesh() -> Any:
    """trimesh, imported when a file is first written or read: with scipy and networkx it adds
    about 60 MiB to a process, which ``render`` would otherwise hold through its meshing too
    (the whole command's peak for a 512^3 sculpture: 363 -> 338 MiB). The sampler's warm-up
    loads it before the workers fork."""
    import trimesh  # deferred: see the docstring

    return trimesh


def mesh_format(path: str | os.PathLike) -> Format:
    """The format of a mesh file named ``path`` (by its suffix, any case).

    Raises :class:`MeshError` when the suffix is not one :func:`save_mesh` writes."""
    path = Path(path)
    fmt = FORMATS.get(path.suffix.lower()[1:])
    if fmt is None or not fmt.mesh_file:
        raise MeshError(
            f"cannot tell the mesh format of '{path.name}': "
            f"the suffix must be one of {', '.join(MESH_SUFFIXES)}"
        )
    return fmt


def encode_mesh(mesh: Mesh, fmt: Format | str) -> bytes:
    """The file of ``mesh`` in ``fmt`` (a :class:`Format` or its name), in memory.

    A mesh with ``face_kinds`` is written marked where the format can: PLY gets a uchar face
    property ``kind`` (0 root, 1 pole, 2 jump, 3 cap) and face colours, GLB vertex colours
    (:data:`KIND_COLOURS`; a vertex takes the colour of a wall if any face around it is one).
    """
    fmt = FORMATS[fmt] if isinstance(fmt, str) else fmt
    own = OWN_WRITERS.get(fmt.name)
    if own is not None:
        return own(mesh)
    tm = _trimesh().Trimesh(mesh.vertices, mesh.faces, process=False)
    if mesh.face_kinds is not None and fmt.marks_walls:
        _add_kinds(tm, mesh)
    data = tm.export(file_type=fmt.trimesh_type, **dict(fmt.options))
    return data.encode("utf-8") if isinstance(data, str) else data


def glb_bytes(mesh: Mesh | None, *, web: bool = False) -> bytes:
    """Binary glTF 2.0 of ``mesh``: the one GLB writer.

    Files (``web=False``: :func:`save_mesh`, ``render``, ``export``, ``dataset``) get trimesh's
    layout, with the kind colours of a marked mesh. The viewer (``web=True``: explore steps,
    the shape API, the static gallery) gets the compact layout it has always had: one indexed
    triangle primitive, float32 positions (with their bounds, which glTF requires) and uint32
    indices, no normals (the viewer computes them, flat or smooth); ``None`` (or no faces)
    gives a valid GLB with an empty scene. Both are pinned by ``tests/generator/mesh``.
    """
    if not web:
        if mesh is None:
            raise MeshError("no mesh to write as a GLB file")
        return encode_mesh(mesh, FORMATS["glb"])
    doc: dict[str, Any] = {"asset": {"version": "2.0", "generator": "surfgen"}, "scene": 0}
    binary = b""
    if mesh is None or mesh.n_faces == 0:
        doc["scenes"] = [{"nodes": []}]
    else:
        pos = np.ascontiguousarray(mesh.vertices, dtype="<f4")
        idx = np.ascontiguousarray(mesh.faces, dtype="<u4")
        pos_bytes, idx_bytes = pos.tobytes(), idx.tobytes()
        binary = pos_bytes + idx_bytes  # both multiples of 4 bytes
        doc |= {
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "mode": 4}]}],
            "buffers": [{"byteLength": len(binary)}],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": len(pos_bytes), "target": 34962},
                {
                    "buffer": 0,
                    "byteOffset": len(pos_bytes),
                    "byteLength": len(idx_bytes),
                    "target": 34963,
                },
            ],
            "accessors": [
                {
                    "bufferView": 0,
                    "componentType": 5126,
                    "count": int(len(pos)),
                    "type": "VEC3",
                    "min": [float(v) for v in pos.min(axis=0)],
                    "max": [float(v) for v in pos.max(axis=0)],
                },
                {
                    "bufferView": 1,
                    "componentType": 5125,
                    "count": int(idx.size),
                    "type": "SCALAR",
                },
            ],
        }
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text
    if binary:
        chunks += struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(chunks)) + chunks


def ply_bytes(mesh: Mesh) -> bytes:
    """Binary little-endian PLY of ``mesh``, the bytes trimesh's writer gives (its header, its
    comment line included, so files are the same whichever wrote them): float32 vertices, each
    face a uchar count and three int32 indices; a marked mesh (``face_kinds``) also has the
    vertices' colours (:func:`_vertex_colours`, as in GLB) and a uchar ``kind`` a face."""
    marked = mesh.face_kinds is not None
    coloured = marked and mesh.n_faces > 0
    vertex_type = [("xyz", "<f4", (3,))] + ([("rgba", "u1", (4,))] if coloured else [])
    face_type = [("count", "u1"), ("index", "<i4", (3,))] + ([("kind", "u1")] if marked else [])
    header = [
        "ply",
        "format binary_little_endian 1.0",
        "comment https://github.com/mikedh/trimesh",
        f"element vertex {mesh.n_vertices}",
        "property float x",
        "property float y",
        "property float z",
    ]
    if coloured:
        header += [f"property uchar {c}" for c in ("red", "green", "blue", "alpha")]
    header += [f"element face {mesh.n_faces}", "property list uchar int vertex_indices"]
    if marked:
        header.append("property uchar kind")
    vertices = np.empty(mesh.n_vertices, dtype=vertex_type)
    vertices["xyz"] = mesh.vertices
    if coloured:
        vertices["rgba"] = _vertex_colours(mesh)
    faces = np.empty(mesh.n_faces, dtype=face_type)
    faces["count"] = 3
    faces["index"] = mesh.faces
    if marked:
        faces["kind"] = mesh.face_kinds
    head = ("\n".join(header) + "\nend_header\n").encode("utf-8")
    return b"".join((head, vertices.tobytes(), faces.tobytes()))


def _vertex_colours(mesh: Mesh) -> np.ndarray:
    """sRGBA of each vertex of a marked mesh: the colour of its most wall-like face (pole over
    jump over root and cap)."""
    kinds = np.asarray(mesh.face_kinds)
    rank = np.array([0, 2, 1, 0], dtype=np.int64)[kinds]
    best = np.zeros(mesh.n_vertices, dtype=np.int64)
    np.maximum.at(best, mesh.faces.reshape(-1), np.repeat(rank, 3))
    return KIND_COLOURS[np.array([ROOT, JUMP, POLE])[best]]


#: The formats surfgen writes itself, by name (:func:`encode_mesh`; the others are trimesh's).
OWN_WRITERS: dict[str, Callable[[Mesh], bytes]] = {"ply": ply_bytes}


def _add_kinds(tm: trimesh.Trimesh, mesh: Mesh) -> None:
    """Attach ``mesh.face_kinds`` to ``tm`` as the ``kind`` face attribute and colours."""
    kinds = np.asarray(mesh.face_kinds)
    tm.face_attributes["kind"] = kinds.astype(np.uint8)
    if mesh.n_faces == 0:
        return
    tm.visual = _trimesh().visual.ColorVisuals(
        tm, face_colors=KIND_COLOURS[kinds], vertex_colors=_vertex_colours(mesh)
    )


def save_mesh(mesh: Mesh, path: str | os.PathLike) -> Path:
    """Write ``mesh`` to ``path`` in the format its suffix names (.ply .obj .stl .off .glb),
    marked where the format can (:func:`encode_mesh`).

    The file appears complete or not at all (temporary file + ``os.replace``).  Returns the path.
    Raises :class:`MeshError` for an unknown suffix or a file that cannot be written.
    """
    path = Path(path)
    data = encode_mesh(mesh, mesh_format(path))
    try:
        write_atomic(path, data)
    except OSError as exc:
        raise MeshError(f"cannot write '{path}': {exc.strerror}") from None
    logger.debug("save_mesh: %s (%d faces)", path, mesh.n_faces)
    return path


def load_mesh(path: str | os.PathLike) -> Mesh:
    """Read a mesh written by :func:`save_mesh` (or any triangle mesh in those formats).

    Indexed formats keep their vertex order; STL, which stores each triangle's corners apart,
    gets exactly coincident corners merged.  Returns ``(V, 3)`` vertices and ``(F, 3)`` faces.
    Raises :class:`MeshError` for an unknown suffix, a missing file, or one that is not a
    readable triangle mesh.
    """
    path = Path(path)
    fmt = mesh_format(path)
    if not path.is_file():
        raise MeshError(f"no mesh file '{path}'")
    size = path.stat().st_size
    if size > MAX_MESH_FILE_BYTES:
        raise MeshError(
            f"'{path}' is {size / 2**30:.1f} GiB: larger than the {MAX_MESH_FILE_BYTES >> 30} GiB "
            "a mesh file may have"
        )
    if fmt.name == "obj":
        _check_obj_indices(path)
    try:
        loaded = _trimesh().load(path, file_type=fmt.trimesh_type, force="mesh", process=False)
    # trimesh's readers fail on corrupt files with assorted exception types; all mean "unreadable".
    except Exception as exc:
        raise MeshError(f"cannot read '{path}' as {path.suffix.lower()[1:]}: {exc}") from exc
    faces = getattr(loaded, "faces", None)
    if faces is None or len(faces) == 0:
        raise MeshError(f"'{path}' holds no triangles")
    vertices = np.asarray(loaded.vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise MeshError(f"'{path}': a face refers to a vertex that does not exist")
    if not np.isfinite(vertices).all():
        raise MeshError(f"'{path}' holds non-finite vertex coordinates")
    if fmt.name == "stl":
        vertices, faces = _merge_exact(vertices, faces)
    return Mesh(vertices, faces, _read_kinds(loaded, len(faces)))


def _read_kinds(loaded: trimesh.Trimesh, n_faces: int) -> np.ndarray | None:
    """The ``kind`` face property of a marked PLY (see :func:`encode_mesh`), else None."""
    raw = (getattr(loaded, "metadata", None) or {}).get("_ply_raw", {})
    try:
        kinds = np.asarray(raw["face"]["data"]["kind"]).reshape(-1)
    except (KeyError, ValueError, TypeError, IndexError):
        return None
    if kinds.shape[0] != n_faces or kinds.size == 0 or kinds.max() >= len(FACE_KINDS):
        return None
    return kinds.astype(np.uint8)


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
