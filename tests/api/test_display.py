"""surfgen.display: meshes handed to trimesh as they are, pictures, notebook cards."""

from __future__ import annotations

import numpy as np

from surfgen.display import facts_html, from_trimesh, picture, png_of, shorten, to_trimesh
from surfgen.generator.mesh.mesh import Mesh


def test_to_trimesh_keeps_vertices_faces_and_kinds(sphere_mesh: Mesh) -> None:
    # two vertices at the same place: trimesh's default would merge them, here they stay
    v = np.vstack([sphere_mesh.vertices, sphere_mesh.vertices[:1]])
    kinds = np.arange(sphere_mesh.n_faces) % 4
    mesh = Mesh(v, sphere_mesh.faces, kinds)
    tm = to_trimesh(mesh, {"key": "abc"})
    assert tm.metadata == {"key": "abc"} and len(tm.vertices) == mesh.n_vertices
    np.testing.assert_array_equal(tm.faces, mesh.faces)
    back = from_trimesh(tm)
    np.testing.assert_array_equal(back.face_kinds, kinds)
    np.testing.assert_array_equal(back.vertices, mesh.vertices)
    assert from_trimesh(to_trimesh(sphere_mesh, {})).face_kinds is None


def test_picture_and_card(sphere_mesh: Mesh) -> None:
    image = picture(sphere_mesh, 32)
    assert image.size == (32, 32) and png_of(image).startswith(b"\x89PNG")
    card = facts_html("T <1>", [("formula", "x<y&" * 10), ("area", 1.23456789)], png_of(image))
    assert "T &lt;1&gt;" in card and "x&lt;y&amp;" in card and "1.23457" in card
    assert "data:image/png;base64," in card and "<img" not in facts_html("t", [])
    assert shorten("a" * 100, 10) == "aaaaaaa..." and shorten("abc") == "abc"
