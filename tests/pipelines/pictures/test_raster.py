"""Tests for surfgen.pipelines.pictures.raster: headless thumbnails, turntables and contact sheets."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image
from skimage import measure

from surfgen.generator.errors import MeshError, SurfgenError
from surfgen.generator.mesh.mesh import Mesh
from surfgen.pipelines.pictures.raster import (
    contact_sheet,
    render_image,
    render_thumbnail,
    render_turntable,
    write_png,
)
from tests.support.numpy_maths import shifted_ufuncs

BACKGROUND = (246, 246, 244)


def _mesh(t: trimesh.Trimesh) -> Mesh:
    return Mesh(t.vertices, t.faces)


@pytest.fixture(scope="module")
def sphere() -> Mesh:
    return _mesh(trimesh.creation.icosphere(subdivisions=4))


@pytest.fixture(scope="module")
def lumpy() -> Mesh:
    """A torus with a small sphere beside it: no rotational symmetry about z."""
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3)
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.35)
    ball.apply_translation([1.6, 0.0, 0.4])
    return _mesh(trimesh.util.concatenate([torus, ball]))


@pytest.fixture(scope="module")
def gyroid() -> Mesh:
    """A gyroid sheet from marching cubes (open, both sides visible), faces towards F > 0."""
    t = np.linspace(-np.pi, np.pi, 40)
    x, y, z = np.meshgrid(t, t, t, indexing="ij")
    f = np.sin(x) * np.cos(y) + np.sin(y) * np.cos(z) + np.sin(z) * np.cos(x)
    vertices, faces, _, _ = measure.marching_cubes(f, 0.0, spacing=(t[1] - t[0],) * 3)
    return Mesh(vertices, faces)


def _foreground(image: np.ndarray) -> np.ndarray:
    return np.any(image[..., :3] != np.array(BACKGROUND, dtype=np.uint8), axis=-1)


def _chroma(image: np.ndarray, mask: np.ndarray) -> float:
    rgb = image[..., :3].astype(float)[mask]
    return float(np.mean(rgb.max(axis=1) - rgb.min(axis=1)))


def test_sphere_thumbnail_is_centred_and_on_background(sphere: Mesh, tmp_path: Path) -> None:
    path = render_thumbnail(sphere, tmp_path / "sphere.png")
    image = np.asarray(Image.open(path))
    assert image.shape == (256, 256, 3)
    assert image.dtype == np.uint8
    for corner in (image[0, 0], image[0, -1], image[-1, 0], image[-1, -1]):
        assert tuple(corner) == BACKGROUND
    mask = _foreground(image)
    rows, cols = np.nonzero(mask)
    assert abs(rows.mean() - 127.5) < 1.5 and abs(cols.mean() - 127.5) < 1.5
    # A unit-cube-framed sphere fills a good part of the frame but leaves a margin.
    assert 0.2 < mask.mean() < 0.5
    assert not mask[0].any() and not mask[-1].any() and not mask[:, 0].any()


def test_sphere_disc_has_no_cracks(sphere: Mesh) -> None:
    """Every pixel inside the silhouette is fully covered: no gaps between triangles."""
    image = render_image(
        _mesh(trimesh.creation.icosphere(subdivisions=5)), size=256, background=None
    )
    assert image.shape == (256, 256, 4)
    alpha = image[..., 3]
    rows, cols = np.nonzero(alpha)
    radius = np.sqrt(np.count_nonzero(alpha == 255) / np.pi)
    r, c = np.mgrid[:256, :256]
    inside = np.hypot(r - rows.mean(), c - cols.mean()) < 0.9 * radius
    assert inside.sum() > 10_000
    assert np.all(alpha[inside] == 255)
    assert np.all(alpha[0] == 0)


def test_depth_order_does_not_depend_on_face_order(sphere: Mesh) -> None:
    """With a working z-buffer, drawing the far half last must not show through."""
    rng = np.random.default_rng(0)
    shuffled = Mesh(sphere.vertices, sphere.faces[rng.permutation(sphere.n_faces)])
    a = render_image(sphere).astype(int)
    b = render_image(shuffled).astype(int)
    # Ties on shared edges may pick the other neighbour: a rounding-level difference at most.
    assert np.abs(a - b).max() <= 2


def test_back_faces_get_their_own_tint(sphere: Mesh, gyroid: Mesh) -> None:
    """Outside (height colours) and inside (muted tint) of a surface look different."""
    outside = render_image(sphere)
    inside = render_image(Mesh(sphere.vertices, sphere.faces[:, ::-1]))
    mask = _foreground(outside)
    assert np.array_equal(mask, _foreground(inside))
    assert _chroma(outside, mask) > 1.5 * _chroma(inside, mask)
    # An open sheet shows both sides at once, and flipping it swaps them.
    sheet = render_image(gyroid)
    flipped = render_image(Mesh(gyroid.vertices, gyroid.faces[:, ::-1]))
    assert np.abs(sheet.astype(int) - flipped.astype(int)).mean() > 5


def test_height_colour_runs_from_bottom_to_top(sphere: Mesh) -> None:
    image = render_image(sphere, elevation=0.0).astype(int)
    rows, cols = np.nonzero(_foreground(image))
    centre = int(round(cols.mean()))
    top = image[rows.min() + 12, centre]
    bottom = image[rows.max() - 12, centre]
    assert top[0] > top[2] and bottom[2] > bottom[0]  # warm on top, cool at the bottom


def test_turntable_strip_has_distinct_views(lumpy: Mesh, tmp_path: Path) -> None:
    path = render_turntable(lumpy, tmp_path / "spin.png", views=12, size=64)
    strip = np.asarray(Image.open(path))
    assert strip.shape == (64, 12 * 64, 3)
    frames = [strip[:, 64 * i : 64 * (i + 1)] for i in range(12)]
    for i in range(12):
        for j in range(i + 1, 12):
            assert not np.array_equal(frames[i], frames[j]), (i, j)
    # The first view is the thumbnail's view.
    assert np.array_equal(frames[0], render_image(lumpy, size=64, azimuth=30.0))


def test_output_is_deterministic(gyroid: Mesh, tmp_path: Path) -> None:
    a = render_thumbnail(gyroid, tmp_path / "a.png")
    b = render_thumbnail(Mesh(gyroid.vertices.copy(), gyroid.faces.copy()), tmp_path / "b.png")
    assert a.read_bytes() == b.read_bytes()
    assert np.array_equal(render_image(gyroid, azimuth=77.0), render_image(gyroid, azimuth=77.0))


def test_pictures_are_the_same_whatever_numpys_maths(
    gyroid: Mesh, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A picture's bytes depend on no numpy transcendental (so not on the CPU): with every one
    of them off by 0.4 %, the same pixels."""
    from surfgen.pipelines.pictures import raster as pictures

    cached = (pictures._srgb_table, pictures._height_lut, pictures._wall_colours)

    def renders() -> list[np.ndarray]:
        for table in cached:
            table.cache_clear()
        return [render_image(gyroid, size=48), render_image(gyroid, size=48, background=None)]

    plain = renders()
    for name, fn in shifted_ufuncs(2.0**-8).items():
        monkeypatch.setattr(np, name, fn)
    assert np.power(2.0, 0.5) != 2.0**0.5  # the shift is in place
    try:
        for a, b in zip(plain, renders(), strict=True):
            assert np.array_equal(a, b)
    finally:
        monkeypatch.undo()
        for table in cached:
            table.cache_clear()


def test_highlight_by_squarings_is_pow_to_rounding() -> None:
    from surfgen.pipelines.pictures import kernels

    assert kernels._SPECULAR_EXPONENT == 24
    for x in np.random.default_rng(2).uniform(0.0, 1.0, 2000):
        want = kernels._SPECULAR_STRENGTH * float(x) ** 24.0
        assert abs(kernels._highlight(float(x)) - want) <= 1e-14 * want


def test_buffers_left_unset_are_never_read(gyroid: Mesh, monkeypatch: pytest.MonkeyPatch) -> None:
    # The renderer skips clearing the colour and barycentric buffers (only pixels a face covers
    # are read): garbage in fresh memory must not change a pixel.
    clean = [render_image(gyroid, size=64), render_image(gyroid, size=64, background=None)]
    empty = np.empty

    def garbage(shape, dtype=float):
        out = empty(shape, dtype=dtype)
        out.fill(np.nan if np.dtype(dtype).kind == "f" else 7)
        return out

    monkeypatch.setattr(np, "empty", garbage)
    assert np.array_equal(render_image(gyroid, size=64), clean[0])
    assert np.array_equal(render_image(gyroid, size=64, background=None), clean[1])


def _corner_normals_reference(faces: np.ndarray, vertices: np.ndarray, crease: float) -> np.ndarray:
    """Per corner, the sum of the fan's area normals within the crease angle (plain loops)."""
    weighted = np.cross(
        vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]]
    )
    unit = weighted / np.linalg.norm(weighted, axis=1)[:, None]
    fans: dict[int, list[int]] = {}
    for t, face in enumerate(faces):
        for i in face:
            fans.setdefault(int(i), []).append(t)
    out = np.zeros((len(faces), 3, 3))
    for t, face in enumerate(faces):
        for k, i in enumerate(face):
            s = np.zeros(3)
            for g in fans[int(i)]:
                if unit[g] @ unit[t] >= crease:
                    s += weighted[g]
            out[t, k] = s / np.linalg.norm(s)
    return out


def test_corner_normals_match_plain_loops() -> None:
    from surfgen.pipelines.pictures import raster as pictures

    box = trimesh.creation.box(extents=(1.0, 1.4, 0.8)).subdivide().subdivide()
    ball = trimesh.creation.icosphere(subdivisions=2)
    crease = float(np.cos(np.radians(60.0)))
    for t in (box, ball):  # creases along the box's rims; smooth fans everywhere on the ball
        vertices, faces = np.asarray(t.vertices, float), np.asarray(t.faces, np.int64)
        weighted, unit = np.zeros((len(faces), 3)), np.zeros((len(faces), 3))
        assert pictures._face_normals(vertices, faces, weighted, unit).all()
        got = np.zeros((len(faces), 3, 3))
        pictures._corner_normals(faces, weighted, unit, len(vertices), crease, 256, got)
        assert np.allclose(got, _corner_normals_reference(faces, vertices, crease), atol=1e-12)
        if t is box:  # flat sides, crisp rims: every corner keeps its face's normal
            assert np.allclose(got, unit[:, None, :], atol=1e-12)


def test_same_framing_whatever_the_scale_and_position(sphere: Mesh) -> None:
    moved = Mesh(sphere.vertices * 37.0 + np.array([5.0, -3.0, 100.0]), sphere.faces)
    a = render_image(sphere).astype(int)
    b = render_image(moved).astype(int)
    assert np.abs(a - b).max() <= 2


def test_contact_sheet_layout(sphere: Mesh, lumpy: Mesh, tmp_path: Path) -> None:
    items = []
    for i, mesh in enumerate([sphere, lumpy, sphere, lumpy, sphere]):
        path = render_thumbnail(mesh, tmp_path / f"t{i}.png", size=64, azimuth=30.0 * i)
        items.append((path, f"key{i}abcdef"))
    out = contact_sheet(items, tmp_path / "sheet.png", columns=3, label_size=12, gap=4)
    sheet = np.asarray(Image.open(out))
    assert sheet.shape == (2 * (64 + 20) + 3 * 4, 3 * 64 + 4 * 4, 3)
    first = np.asarray(Image.open(items[0][0]))
    assert np.array_equal(sheet[4 : 4 + 64, 4 : 4 + 64], first)
    label_band = sheet[4 + 64 : 4 + 64 + 20, 4 : 4 + 64].astype(int)
    assert (label_band.sum(axis=-1) < 3 * 150).any()  # some dark text under the picture
    empty_cell = sheet[4 + 84 + 4 :, 4 + 2 * 68 :]
    assert np.all(empty_cell == np.array(BACKGROUND, dtype=np.uint8))


def test_write_png_is_atomic_and_checks_input(tmp_path: Path) -> None:
    image = np.zeros((4, 5, 3), dtype=np.uint8)
    path = write_png(image, tmp_path / "sub" / "x.png")
    assert np.array_equal(np.asarray(Image.open(path)), image)
    assert [p.name for p in path.parent.iterdir()] == ["x.png"]  # no temporary left over
    with pytest.raises(SurfgenError):
        write_png(np.zeros((4, 5, 3)), tmp_path / "bad.png")


def test_bad_meshes_raise_mesh_error(sphere: Mesh) -> None:
    with pytest.raises(MeshError, match="empty"):
        render_image(Mesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)))
    with pytest.raises(MeshError, match="coincide"):
        render_image(Mesh(np.ones((3, 3)), np.array([[0, 1, 2]])))
    with pytest.raises(MeshError, match="zero area"):
        render_image(Mesh(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]), np.array([[0, 1, 2]])))
    with pytest.raises(MeshError, match="outside"):
        render_image(Mesh(sphere.vertices, sphere.faces + sphere.n_vertices))
    bad = sphere.vertices.copy()
    bad[0] = np.nan
    with pytest.raises(MeshError, match="non-finite"):
        render_image(Mesh(bad, sphere.faces))
    with pytest.raises(SurfgenError):
        contact_sheet([], "unused.png")
