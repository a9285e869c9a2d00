"""Pictures of meshes without a display: thumbnails, turntable strips and contact sheets.

A small software renderer: one numba z-buffer rasteriser writes, for every pixel of a 2x
supersampled frame, the nearest triangle and its perspective-correct barycentrics; one numba
shading pass turns that into colour (per-pixel interpolated normals, two-sided lighting, height
colour map); depth discontinuities get a thin dark outline; 2x2 blocks are averaged in linear
light and encoded as sRGB. Pillow (which matplotlib already requires) writes the PNGs.

Conventions, fixed so every picture in the catalogue is comparable:

- the mesh is centred on its bounding-box centre and scaled by its longest side, so it lies in
  the unit cube ``[-1/2, 1/2]^3``; the camera frames that cube for *every* azimuth at the given
  elevation (shapes clipped by their box fill it, so this is the common case), hence a shape does
  not grow or shrink while a turntable spins;
- z is up; the camera looks at the origin from ``azimuth`` degrees around z and ``elevation``
  degrees above the xy plane, with a mild perspective (distance 4 unit-cubes);
- lights are fixed to the camera (key light upper left, weaker fill from the right, soft sky/ground
  ambient, Blinn-Phong highlight), so a turntable looks like the object spins under studio lights;
- front faces (counter-clockwise seen from the camera, i.e. the outside) are coloured by height z
  with a blue-teal-sand-coral map; back faces (the inside of open surfaces) get a muted lavender;
- normals are smoothed per face corner across edges bent less than 60 degrees, so marching-cubes
  surfaces look smooth while box edges and creases of min/max/abs formulas stay crisp.
"""

from __future__ import annotations

import functools
import io
import logging
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypeAlias

import numba
import numpy as np

from surfgen.generator.elementary import power
from surfgen.generator.errors import MeshError, SurfgenError
from surfgen.generator.files import write_atomic
from surfgen.generator.jit.options import KERNEL
from surfgen.generator.mesh.mesh import Mesh
from surfgen.pipelines.pictures.kernels import (
    _bounds,
    _corner_normals,
    _downsample,
    _face_normals,
    _project,
    _rasterise,
    _shade,
)

if TYPE_CHECKING:  # pillow is imported lazily: only picture-writing code needs it
    from PIL import ImageDraw, ImageFont

    _Font: TypeAlias = ImageFont.FreeTypeFont | ImageFont.ImageFont

__all__ = [
    "contact_sheet",
    "render_image",
    "render_thumbnail",
    "render_turntable",
    "write_png",
]

log = logging.getLogger(__name__)

# The catalogue's pictures: every path that makes them (sample, thumbnails, serve, gallery)
# uses these, so a cached picture looks the same whoever rendered it.
THUMBNAIL_SIZE = 256
TURNTABLE_SIZE = 256  # one frame: the gallery's cards are 256 px
TURNTABLE_VIEWS = 12
# zlib level of every PNG: 3 encodes a thumbnail in half the time of 6 for ~8 % more bytes.
_PNG_COMPRESSION = 3

# -- camera and look ---------------------------------------------------------------------------

_CAMERA_DISTANCE = 4.0  # from the origin, in unit-cube lengths: ~22 degree field of view
_FRAME_MARGIN = 0.04  # fraction of the half-frame left empty around the worst-case cube
_SUPERSAMPLE = 2  # render at 2x and average 2x2 blocks (anti-aliasing)

_BACKGROUND = (246, 246, 244)  # sRGB, a light neutral grey

# Lights in camera coordinates (x right, y up, z towards the viewer); normalised below.
_KEY_DIRECTION = (-0.45, 0.60, 0.66)
_FILL_DIRECTION = (0.70, -0.15, 0.45)

# Height colour map for front faces, sRGB stops from low z to high z.
_HEIGHT_STOPS = (
    (0.00, (56, 94, 168)),
    (0.25, (58, 142, 176)),
    (0.50, (126, 196, 168)),
    (0.72, (236, 214, 150)),
    (1.00, (226, 112, 84)),
)
# Walls under --walls mark (pole, jump), sRGB: the same red and orange as marked mesh files.
_WALL_TINTS = ((214, 39, 40), (255, 127, 14))
_BACK_TINT = (156, 146, 178)  # sRGB muted lavender for the inside of open surfaces
_BACK_HEIGHT_MIX = 0.15  # how much of the height colour still shows on back faces
_LUT_SIZE = 256
_CREASE_ANGLE = 60.0  # degrees: faces bent further apart than this do not share a smooth normal
_MAX_FAN = 256  # faces around one vertex beyond which creases are ignored (cost is fan²)
_EDGE_DEPTH_JUMP = 0.04  # unit-cube lengths: depth second difference marking an outline
_EDGE_DARKEN = 0.45  # outline pixels keep this fraction of their colour


# The sRGB curve's powers are surfgen's (generator/elementary), not numpy's, which runs SIMD code
# of its own on AVX-512 CPUs: a picture's bytes are then the same on every machine.


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, power((c + 0.055) / 1.055, 2.4))


def _linear_to_srgb8(c: np.ndarray) -> np.ndarray:
    """Linear light in [0, 1] (any shape) to sRGB uint8."""
    c = np.clip(c, 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * power(c, 1.0 / 2.4) - 0.055)
    return np.round(s * 255.0).astype(np.uint8)


@functools.cache
def _height_lut() -> tuple[np.ndarray, np.ndarray]:
    """Front and back colour tables, linear RGB ``(_LUT_SIZE, 3)`` each."""
    t = np.linspace(0.0, 1.0, _LUT_SIZE)
    where = np.array([s[0] for s in _HEIGHT_STOPS])
    rgb = np.array([s[1] for s in _HEIGHT_STOPS], dtype=np.float64) / 255.0
    # Interpolate in sRGB (perceptually smoother), then convert to linear for lighting.
    front_srgb = np.stack([np.interp(t, where, rgb[:, k]) for k in range(3)], axis=1)
    back_srgb = (1.0 - _BACK_HEIGHT_MIX) * (
        np.array(_BACK_TINT, dtype=np.float64) / 255.0
    ) + _BACK_HEIGHT_MIX * front_srgb
    front = np.ascontiguousarray(_srgb_to_linear(front_srgb))
    back = np.ascontiguousarray(_srgb_to_linear(back_srgb))
    return front, back


@functools.cache
def _wall_colours() -> np.ndarray:
    """Linear RGB ``(3, 3)``: row 0 unused, then the pole and jump tints."""
    rows = np.array([(0, 0, 0), *_WALL_TINTS], dtype=np.float64) / 255.0
    return np.ascontiguousarray(_srgb_to_linear(rows))


def _unit(v: Sequence[float]) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    return a / np.linalg.norm(a)


def _view_rotation(azimuth: float, elevation: float) -> np.ndarray:
    """World-to-camera rotation ``(3, 3)``: rows are the camera's right, up and back axes."""
    a, e = math.radians(azimuth), math.radians(elevation)
    back = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    right = np.array([-math.sin(a), math.cos(a), 0.0])
    up = np.cross(back, right)
    return np.stack([right, up, back])


@functools.lru_cache(maxsize=64)
def _focal(elevation: float) -> float:
    """Focal factor so the unit cube fits the frame at every azimuth for this elevation."""
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    extent = 0.0
    for azimuth in np.arange(0.0, 360.0, 1.0):
        cam = corners @ _view_rotation(float(azimuth), elevation).T
        depth = _CAMERA_DISTANCE - cam[:, 2]
        extent = max(extent, float(np.max(np.abs(cam[:, :2]) / depth[:, None])))
    return 1.0 / (extent * (1.0 + _FRAME_MARGIN))


# -- scene preparation -------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Scene:
    """A mesh made ready to draw from any angle: unit-cube vertices, normals, heights."""

    vertices: np.ndarray  # (V, 3) float64, in [-1/2, 1/2]^3
    faces: np.ndarray  # (F, 3) int64, non-degenerate
    normals: np.ndarray  # (F, 3, 3) unit normal at each face corner, creases kept
    face_normals: np.ndarray  # (F, 3) unit face normals
    heights: np.ndarray  # (V,) z rescaled to [0, 1]
    wall: np.ndarray  # (F,) uint8: 0 surface, 1 pole wall, 2 jump wall


def _prepare(mesh: Mesh, bounds: Sequence[float] | None = None) -> _Scene:
    """Validate ``mesh`` and normalise it into the unit view (its own bounding box, or
    ``bounds`` = ``(xmin, xmax, ymin, ymax, zmin, zmax)`` so several meshes share one framing).

    Raises :class:`MeshError` for a mesh without faces, with indices out of range, with
    non-finite vertices or without any triangle of positive area.
    """
    vertices = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    if faces.shape[0] == 0 or vertices.shape[0] == 0:
        raise MeshError(
            f"cannot draw an empty mesh ({vertices.shape[0]} vertices, {faces.shape[0]} faces)"
        )
    if faces.min() < 0 or faces.max() >= vertices.shape[0]:
        raise MeshError(f"face indices outside [0, {vertices.shape[0]}): cannot draw the mesh")
    lo, hi = np.empty(3), np.empty(3)
    if not _bounds(vertices, faces, lo, hi):
        raise MeshError("mesh has non-finite vertex coordinates: cannot draw it")
    if bounds is not None:
        lo, hi = (
            np.asarray(bounds[0::2], dtype=np.float64),
            np.asarray(bounds[1::2], dtype=np.float64),
        )
    longest = float(np.max(hi - lo))
    if not longest > 0.0:
        raise MeshError("degenerate mesh: all vertices coincide, nothing to draw")
    unit = (vertices - 0.5 * (lo + hi)) / longest

    weighted = np.zeros((faces.shape[0], 3), dtype=np.float64)
    face_normals = np.zeros((faces.shape[0], 3), dtype=np.float64)
    keep = _face_normals(unit, faces, weighted, face_normals)
    if not keep.any():
        raise MeshError("degenerate mesh: every triangle has zero area, nothing to draw")
    wall = np.zeros(faces.shape[0], dtype=np.uint8)
    if mesh.face_kinds is not None:  # poles (1) and jumps (2) are drawn in their own colours
        kinds = np.asarray(mesh.face_kinds)
        wall = np.where((kinds == 1) | (kinds == 2), kinds, 0).astype(np.uint8)
    if not keep.all():
        faces, weighted, face_normals = faces[keep], weighted[keep], face_normals[keep]
        wall = wall[keep]
    faces = np.ascontiguousarray(faces)
    normals = np.zeros((faces.shape[0], 3, 3), dtype=np.float64)
    cos_crease = math.cos(math.radians(_CREASE_ANGLE))
    _corner_normals(faces, weighted, face_normals, unit.shape[0], cos_crease, _MAX_FAN, normals)
    z = unit[:, 2]
    z_lo, z_hi = (lo[2] - hi[2]) / (2.0 * longest), (hi[2] - lo[2]) / (2.0 * longest)
    heights = (z - z_lo) / (z_hi - z_lo) if z_hi > z_lo else np.full_like(z, 0.5)
    return _Scene(
        vertices=unit,
        faces=faces,
        normals=normals,
        face_normals=face_normals,
        heights=np.clip(heights, 0.0, 1.0),
        wall=np.ascontiguousarray(wall),
    )


def _check_size(size: int) -> int:
    size = int(size)
    if size < 8 or size > 8192:
        raise SurfgenError(f"image size must be between 8 and 8192 pixels, got {size}")
    return size


def _draw(
    scene: _Scene,
    size: int,
    azimuth: float,
    elevation: float,
    background: tuple[int, int, int] | None,
) -> np.ndarray:
    """One view of ``scene``: uint8 (size, size, 3), or (size, size, 4) if no background."""
    n = size * _SUPERSAMPLE
    rotation = _view_rotation(azimuth, elevation)
    count = scene.vertices.shape[0]
    sx, sy, inv_depth = np.empty(count), np.empty(count), np.empty(count)
    focal = _focal(float(elevation)) * 0.5 * n
    _project(scene.vertices, rotation, _CAMERA_DISTANCE, focal, 0.5 * n, sx, sy, inv_depth)

    depth_buffer = np.zeros((n, n), dtype=np.float64)
    face_buffer = np.full((n, n), -1, dtype=np.int64)
    # Read only where a face was drawn (which writes them): no need to clear them first.
    bary_buffer = np.empty((n, n, 2), dtype=np.float64)
    _rasterise(sx, sy, inv_depth, scene.faces, n, n, depth_buffer, face_buffer, bary_buffer)

    front_lut, back_lut = _height_lut()
    # Lights are fixed to the camera: take them from camera to world axes (rows of rotation).
    frame = np.stack(
        [
            _unit(_KEY_DIRECTION) @ rotation,
            _unit(_FILL_DIRECTION) @ rotation,
            rotation[1],
            _CAMERA_DISTANCE * rotation[2],
        ]
    )
    colour = np.empty((n, n, 3), dtype=np.float64)  # likewise: uncovered pixels are never read
    _shade(
        face_buffer,
        bary_buffer,
        scene.faces,
        scene.vertices,
        scene.normals,
        scene.face_normals,
        scene.heights,
        front_lut,
        back_lut,
        frame,
        scene.wall,
        _wall_colours(),
        colour,
    )
    covered = face_buffer >= 0
    _darken_edges(colour, depth_buffer, covered)
    return _resolve(colour, covered, size, background)


def _darken_edges(colour: np.ndarray, inv_depth: np.ndarray, covered: np.ndarray) -> None:
    """Darken ``colour`` (H, W, 3) in place along silhouettes and depth discontinuities.

    A pixel is on an edge if a 4-neighbour is empty or if the depth's second difference across
    it exceeds ``_EDGE_DEPTH_JUMP`` (a plane seen at a grazing angle has none, a fold or a layer
    in front of another has a large one). This keeps overlapping sheets of a lattice apart.
    """
    _darken_edges_kernel(
        colour, inv_depth, covered, _CAMERA_DISTANCE + 1.0, _EDGE_DEPTH_JUMP, _EDGE_DARKEN
    )


@numba.njit(**KERNEL)
def _darken_edges_kernel(
    colour: np.ndarray,
    inv_depth: np.ndarray,
    covered: np.ndarray,
    far: float,
    jump: float,
    darken: float,
) -> None:
    """:func:`_darken_edges` in one pass (numpy needed ten full-frame temporaries): empty
    pixels are at depth ``far``, the frame's border repeats its edge pixels."""
    h, w = covered.shape
    depth = np.empty((h, w))
    for r in range(h):
        for c in range(w):
            depth[r, c] = 1.0 / inv_depth[r, c] if covered[r, c] else far
    for r in range(h):
        up = depth[max(r - 1, 0)]
        down = depth[min(r + 1, h - 1)]
        row = depth[r]
        for c in range(w):
            if not covered[r, c]:
                continue
            d2 = 2.0 * row[c]
            lap_x = abs(row[max(c - 1, 0)] + row[min(c + 1, w - 1)] - d2)
            lap_y = abs(up[c] + down[c] - d2)
            if max(lap_x, lap_y) > jump:
                colour[r, c, 0] *= darken
                colour[r, c, 1] *= darken
                colour[r, c, 2] *= darken


def _resolve(
    colour: np.ndarray,
    covered: np.ndarray,
    size: int,
    background: tuple[int, int, int] | None,
) -> np.ndarray:
    """Average supersampled blocks in linear light and encode sRGB (straight alpha if RGBA)."""
    channels = 3 if background is not None else 4
    out = np.empty((size, size, channels), dtype=np.uint8)
    bg = _srgb_to_linear(np.asarray(background or (0, 0, 0), dtype=np.float64) / 255.0)
    _downsample(colour, covered, _SUPERSAMPLE, bg, _srgb_table(), out)
    return out


@functools.cache
def _srgb_table() -> np.ndarray:
    """sRGB uint8 of linear values ``i / 4095``: finer than one 8-bit step everywhere."""
    return _linear_to_srgb8(np.linspace(0.0, 1.0, 4096))


# -- public API --------------------------------------------------------------------------------


def render_image(
    mesh: Mesh,
    size: int = 256,
    azimuth: float = 30.0,
    elevation: float = 25.0,
    background: tuple[int, int, int] | None = _BACKGROUND,
    bounds: Sequence[float] | None = None,
) -> np.ndarray:
    """Render ``mesh`` shaded, as seen from ``azimuth``/``elevation`` degrees (z up), framed on
    its bounding box or on ``bounds`` (6 numbers: pictures of several meshes framed alike).

    Returns uint8 ``(size, size, 3)`` sRGB over ``background``, or ``(size, size, 4)`` RGBA with
    a transparent background if ``background`` is None. The picture depends only on the mesh
    and the arguments (bit-for-bit). Raises :class:`MeshError` for an empty or degenerate mesh
    and :class:`SurfgenError` for a size outside [8, 8192].
    """
    return _draw(_prepare(mesh, bounds), _check_size(size), azimuth, elevation, background)


def write_png(image: np.ndarray, path: str | os.PathLike[str]) -> Path:
    """Write a uint8 ``(H, W)``, ``(H, W, 3)`` or ``(H, W, 4)`` image to ``path`` atomically.

    The PNG goes to a temporary file in the same folder, then replaces ``path``, so a reader
    never sees half a file. Returns the path. Raises :class:`SurfgenError` for another shape.
    """
    array = np.asarray(image)
    data = png_bytes(array)
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(target, data)
    log.debug("wrote %s (%dx%d)", target, array.shape[1], array.shape[0])
    return target


def png_bytes(image: np.ndarray) -> bytes:
    """The PNG file of a uint8 ``(H, W)``, ``(H, W, 3)`` or ``(H, W, 4)`` image, in memory (so a
    command can write several files all or nothing). Raises :class:`SurfgenError` for another
    shape."""
    from PIL import Image

    array = np.asarray(image)
    if (
        array.dtype != np.uint8
        or array.ndim not in (2, 3)
        or (array.ndim == 3 and array.shape[2] not in (3, 4))
    ):
        raise SurfgenError(
            f"write_png needs uint8 (H, W), (H, W, 3) or (H, W, 4), got {array.dtype} {array.shape}"
        )
    buffer = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(array)).save(
        buffer, format="PNG", compress_level=_PNG_COMPRESSION
    )
    return buffer.getvalue()


def render_thumbnail(
    mesh: Mesh, path: str | os.PathLike[str], size: int = 256, azimuth: float = 30.0
) -> Path:
    """Render the catalogue thumbnail of ``mesh`` (``size``² PNG, default view) to ``path``."""
    return write_png(render_image(mesh, size=size, azimuth=azimuth), path)


def render_turntable(
    mesh: Mesh,
    path: str | os.PathLike[str],
    views: int = 12,
    size: int = 256,
    azimuth: float = 30.0,
    elevation: float = 25.0,
) -> Path:
    """Render ``views`` views a full turn apart, side by side, as one PNG sprite strip.

    The strip is ``views * size`` wide and ``size`` high; view ``i`` is at azimuth
    ``azimuth + 360 * i / views`` and starts at x = ``i * size``, so a web page can spin the
    shape by stepping CSS ``background-position``. Raises :class:`MeshError` as
    :func:`render_image`.
    """
    return write_png(turntable_image(mesh, views, size, azimuth, elevation), path)


def turntable_image(
    mesh: Mesh, views: int = 12, size: int = 256, azimuth: float = 30.0, elevation: float = 25.0
) -> np.ndarray:
    """The sprite strip of :func:`render_turntable`, in memory: uint8 ``(size, views * size,
    3)`` on the pictures' background. Raises as :func:`render_turntable`."""
    if int(views) < 1:
        raise SurfgenError(f"a turntable needs at least one view, got {views}")
    scene = _prepare(mesh)
    size = _check_size(size)
    frames = [
        _draw(scene, size, azimuth + 360.0 * i / views, elevation, _BACKGROUND)
        for i in range(int(views))
    ]
    return np.concatenate(frames, axis=1)


_LABEL_COLOUR = (60, 60, 60)


def contact_sheet(
    items: Sequence[tuple[str | os.PathLike[str], str]],
    path: str | os.PathLike[str],
    columns: int = 6,
    label_size: int = 13,
    gap: int = 4,
) -> Path:
    """Compose thumbnail PNGs into a grid with each short key written under its picture.

    ``items`` are ``(thumbnail path, label)`` in reading order. Every cell is the size of the
    first thumbnail (others are resized to it) plus a label band ``label_size + 8`` high; cells
    are ``gap`` pixels apart and from the border. Labels too wide for a cell end with "…";
    transparent thumbnails are laid on the sheet's background. Raises :class:`SurfgenError`
    if ``items`` is empty or a thumbnail cannot be read.
    """
    from PIL import Image, ImageDraw, ImageFont

    if not items:
        raise SurfgenError("a contact sheet needs at least one thumbnail")
    columns = max(1, min(int(columns), len(items)))
    rows = math.ceil(len(items) / columns)
    font = ImageFont.load_default(size=label_size)
    band = label_size + 8
    sheet = None
    for i, (source, label) in enumerate(items):
        try:
            with Image.open(source) as opened:
                picture = opened.convert("RGBA")
        except OSError as error:
            raise SurfgenError(f"cannot read thumbnail {source}: {error}") from error
        if sheet is None:
            cell_w, cell_h = picture.size
            width = columns * cell_w + (columns + 1) * gap
            height = rows * (cell_h + band) + (rows + 1) * gap
            sheet = Image.new("RGB", (width, height), _BACKGROUND)
            draw = ImageDraw.Draw(sheet)
        if picture.size != (cell_w, cell_h):
            picture = picture.resize((cell_w, cell_h), Image.Resampling.LANCZOS)
        x = gap + (i % columns) * (cell_w + gap)
        y = gap + (i // columns) * (cell_h + band + gap)
        sheet.paste(picture, (x, y), picture)
        text = _fit_label(draw, str(label), font, cell_w - 4)
        draw.text(
            (x + cell_w / 2, y + cell_h + band / 2),
            text,
            fill=_LABEL_COLOUR,
            font=font,
            anchor="mm",
        )
    log.debug("contact sheet of %d thumbnails, %d columns", len(items), columns)
    return write_png(np.asarray(sheet), path)


def _fit_label(draw: ImageDraw.ImageDraw, text: str, font: _Font, width: float) -> str:
    """``text``, shortened with an ellipsis until it fits in ``width`` pixels."""
    if draw.textlength(text, font=font) <= width:
        return text
    while text and draw.textlength(text + "…", font=font) > width:
        text = text[:-1]
    return text + "…"
