"""The table of mesh formats, the one encoder and the one GLB writer (bytes pinned)."""

from __future__ import annotations

import hashlib
import json
import struct

import numpy as np
import pytest
import trimesh

from surfgen.generator.errors import MeshError
from surfgen.generator.mesh.exchange import (
    encode_mesh,
    glb_bytes,
    load_mesh,
    mesh_format,
    ply_bytes,
)
from surfgen.generator.mesh.formats import (
    DATASET_FORMATS,
    EXPORT_FORMATS,
    FORMATS,
    MARKABLE,
    MESH_SUFFIXES,
    PRINTABLE,
)
from surfgen.generator.mesh.mesh import CAP, POLE, ROOT, Mesh

TETRA = Mesh(
    np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float),
    np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]),
)
# sha256 of what the viewer's GLB writer (explore.encode_glb before the table) gave.
WEB_TETRA = "06f17c6635eb6ec89f9bb74b3878316dc3c9943ced160450140d4aabd00f0576"
WEB_EMPTY = "509d76ee41a292c74ec4b062950a91b765166c9de9546c1c7fcd0b7f2dd918ef"


def test_the_lists_read_from_the_table_are_the_ones_commands_printed() -> None:
    assert MESH_SUFFIXES == (".ply", ".obj", ".stl", ".off", ".glb")
    assert EXPORT_FORMATS == ("stl", "obj", "ply", "glb", "3mf")
    assert (MARKABLE, PRINTABLE, DATASET_FORMATS) == (
        ("ply", "glb"),
        ("stl", "3mf"),
        ("ply", "glb"),
    )
    assert FORMATS["3mf"].needs == "lxml" and not FORMATS["3mf"].mesh_file
    assert all(FORMATS[name].suffix == f".{name}" for name in FORMATS)


def test_mesh_format_by_suffix_any_case() -> None:
    assert mesh_format("a/b.PLY") is FORMATS["ply"]
    for name in ("x.3mf", "x.txt", "x"):
        with pytest.raises(MeshError, match=r"the suffix must be one of \.ply, \.obj"):
            mesh_format(name)


def test_web_glb_bytes_are_pinned() -> None:
    marked = Mesh(TETRA.vertices, TETRA.faces, np.array([ROOT, POLE, ROOT, CAP]))
    assert hashlib.sha256(glb_bytes(TETRA, web=True)).hexdigest() == WEB_TETRA
    assert hashlib.sha256(glb_bytes(marked, web=True)).hexdigest() == WEB_TETRA  # no colours
    empty = glb_bytes(None, web=True)
    assert hashlib.sha256(empty).hexdigest() == WEB_EMPTY
    assert json.loads(empty[20:].decode().strip())["scenes"] == [{"nodes": []}]
    assert glb_bytes(Mesh(np.zeros((0, 3)), np.zeros((0, 3))), web=True) == empty


def test_file_glb_is_trimeshs_and_marks_walls(torus_mesh: Mesh) -> None:
    plain = trimesh.Trimesh(torus_mesh.vertices, torus_mesh.faces, process=False)
    assert glb_bytes(torus_mesh) == plain.export(file_type="glb")  # the dataset's GLB
    assert encode_mesh(torus_mesh, "glb") == glb_bytes(torus_mesh)
    kinds = np.zeros(torus_mesh.n_faces, dtype=np.uint8)
    kinds[::7] = POLE
    marked = Mesh(torus_mesh.vertices, torus_mesh.faces, kinds)
    data = glb_bytes(marked)
    assert data != glb_bytes(torus_mesh)
    magic, version, length = struct.unpack("<III", data[:12])
    assert (magic, version, length) == (0x46546C67, 2, len(data))
    with pytest.raises(MeshError):
        glb_bytes(None)


def _trimesh_ply(mesh: Mesh) -> bytes:
    """What encode_mesh gave through trimesh before it wrote PLY itself."""
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    if mesh.face_kinds is not None:
        tm.face_attributes["kind"] = mesh.face_kinds.astype(np.uint8)
        if mesh.n_faces:
            rank = np.array([0, 2, 1, 0])[mesh.face_kinds]
            best = np.zeros(mesh.n_vertices, dtype=np.int64)
            np.maximum.at(best, mesh.faces.reshape(-1), np.repeat(rank, 3))
            colours = np.array(
                [
                    [200, 200, 200, 255],
                    [214, 39, 40, 255],
                    [255, 127, 14, 255],
                    [160, 160, 160, 255],
                ]
            )
            tm.visual = trimesh.visual.ColorVisuals(
                tm,
                face_colors=colours[mesh.face_kinds],
                vertex_colors=colours[np.array([0, 2, 1])[best]],
            )
    return tm.export(file_type="ply", encoding="binary")


def test_ply_is_written_byte_for_byte_as_trimesh_writes_it(torus_mesh: Mesh) -> None:
    # surfgen writes binary PLY itself (importing trimesh took longer than meshing a 512^3
    # sculpture): the same bytes, plain and marked (every kind, the vertices painted by their
    # most wall-like face), with no face, and with indices past 2**16
    rng = np.random.default_rng(3)
    kinds = rng.integers(0, 4, torus_mesh.n_faces).astype(np.uint8)
    big = Mesh(rng.normal(size=(70_000, 3)) * 1e3, rng.integers(0, 70_000, (90_000, 3)))
    no_face = Mesh(torus_mesh.vertices, np.zeros((0, 3), dtype=np.int64))
    meshes = [torus_mesh, Mesh(torus_mesh.vertices, torus_mesh.faces, kinds), big, no_face]
    meshes.append(Mesh(no_face.vertices, no_face.faces, np.zeros(0, dtype=np.uint8)))
    for mesh in meshes:
        want = _trimesh_ply(mesh)
        assert ply_bytes(mesh) == want
        assert encode_mesh(mesh, "ply") == want


@pytest.mark.parametrize("name", [n for n, f in FORMATS.items() if f.mesh_file])
def test_every_mesh_file_format_round_trips(name: str, tmp_path, torus_mesh: Mesh) -> None:
    path = tmp_path / f"t.{name}"
    path.write_bytes(encode_mesh(torus_mesh, FORMATS[name]))
    back = load_mesh(path)
    assert back.n_faces == torus_mesh.n_faces
    assert np.allclose(
        np.sort(back.vertices, axis=0), np.sort(torus_mesh.vertices, axis=0), atol=1e-6
    )


def test_only_markable_formats_carry_kinds(tmp_path, torus_mesh: Mesh) -> None:
    kinds = np.zeros(torus_mesh.n_faces, dtype=np.uint8)
    kinds[::5] = POLE
    marked = Mesh(torus_mesh.vertices, torus_mesh.faces, kinds)
    for name, fmt in FORMATS.items():
        if not fmt.mesh_file:
            continue
        same = encode_mesh(marked, fmt) == encode_mesh(torus_mesh, fmt)
        assert same != fmt.marks_walls, name
    path = tmp_path / "m.ply"
    path.write_bytes(encode_mesh(marked, "ply"))
    assert np.array_equal(load_mesh(path).face_kinds, kinds)


def test_trimesh_is_loaded_when_a_file_other_than_ply_is_first_written():
    """``render``'s path evaluates and meshes without trimesh (60 MiB with scipy, which the
    command would hold through its meshing, and 0.7 s to import); a PLY file (the sampler's
    workers' only format) is written without it, the first file in another format loads it;
    the sampler's warm-up does not."""
    import subprocess
    import sys

    made = (
        "import sys\n"
        "import surfgen.pipelines.export.render\n"
        "from surfgen.generator.mesh.realise import realise\n"
        "from surfgen.generator.model.spec import SurfaceSpec\n"
        "made = realise(SurfaceSpec('x^2+y^2+z^2-1', (-1.5, 1.5) * 3, (12,) * 3))\n"
        "print('trimesh' in sys.modules)\n"
    )
    written = "from surfgen.generator.mesh.exchange import encode_mesh\n"
    written += "encode_mesh(made.mesh, 'ply')\nprint('trimesh' in sys.modules)\n"
    written += "encode_mesh(made.mesh, 'stl')\nprint('trimesh' in sys.modules)\n"
    warmed = "from surfgen.pipelines.run.warmup import _warm_extras\n"
    warmed += "_warm_extras(made.field, made.mesh)\nprint('trimesh' in sys.modules)\n"
    for code, want in (
        (made + written, ["False", "False", "True"]),
        (made + warmed, ["False", "False"]),
    ):
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        assert done.stdout.split() == want
