"""Benchmark: the per-accepted-shape checks and outputs before and after issue 13, same meshes.

Every accepted candidate of ``surfgen sample`` (and every near duplicate the parent throws away
afterwards) pays four things in its worker: ``quality`` (:func:`quality_metrics`: solidity and
the 48 symmetry elements), ``shape`` (:func:`shape_metrics`: pymeshlab's topology, edges,
volume, curvature), ``descriptor`` and ``thumbnail`` (render + PNG). This script times the
library's versions against the previous ones, kept here as the baseline (numpy with a k-d tree,
whole-array temporaries, corner normals summed per corner, ``pow`` in the shader, cleared
buffers, PNG zlib level 6), on the same
meshes in the same run, and checks that both give the same metrics, descriptors and pixels.

Meshes: the accepted shapes among the first ``--n`` draws of ``--seed`` (default config, made
in-process), or the meshes of an existing catalogue (``--catalogue DIR``). Per mesh and check,
the best of ``--repeats`` calls; old and new alternate, so load changes hit both alike.

    python -m benchmarks.shape_checks [--n 60] [--seed 7] [--repeats 3] [--catalogue DIR]
"""

from __future__ import annotations

import io
import math
import tempfile
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numba
import numpy as np
from PIL import Image
from scipy.spatial import ConvexHull, QhullError, cKDTree

from benchmarks import harness
from surfgen.filters import descriptor as desc
from surfgen.filters import meshlab, shape
from surfgen.filters.descriptor import descriptor
from surfgen.filters.metrics import Metrics
from surfgen.filters.shape import quality_metrics
from surfgen.filters.verdict import quick_metrics, shape_metrics
from surfgen.generator.errors import MeshError
from surfgen.generator.mesh.exchange import load_mesh
from surfgen.generator.mesh.mesh import Mesh, face_areas
from surfgen.pipelines.pictures import raster as pic
from surfgen.pipelines.pictures.kernels import (
    _FILL_STRENGTH,
    _GROUND_AMBIENT,
    _KEY_STRENGTH,
    _SKY_AMBIENT,
    _SPECULAR_STRENGTH,
)
from surfgen.pipelines.pictures.raster import png_bytes, render_image
from surfgen.pipelines.run.config import load_config
from surfgen.pipelines.run.shapes import make_shape

# -- the baseline: the checks as they were before issue 13 -------------------------------------


def old_symmetries(mesh: Mesh) -> list[str]:
    """Symmetry elements with a k-d tree over the vertices (the first 128 points first)."""
    tri = mesh.vertices[mesh.faces]
    areas = face_areas(mesh)
    total = float(areas.sum())
    centroid = (areas[:, None] * tri.mean(axis=1)).sum(axis=0) / total
    rng = np.random.default_rng(shape.SYMMETRY_SEED)
    n = shape.SYMMETRY_POINTS
    faces = np.minimum(
        np.searchsorted(np.cumsum(areas), rng.random(n) * total, side="right"), len(areas) - 1
    )
    r1, r2 = rng.random((2, n))
    s = np.sqrt(r1)
    a, b, c = tri[faces, 0], tri[faces, 1], tri[faces, 2]
    pts = (1 - s)[:, None] * a + (s * (1 - r2))[:, None] * b + (s * r2)[:, None] * c
    tree = cKDTree(mesh.vertices[np.unique(mesh.faces)] - centroid)
    v, f = mesh.vertices, mesh.faces
    edge = float(np.linalg.norm(v[f[:, 1]] - v[f[:, 0]], axis=1).mean())
    limit = shape.SYMMETRY_TOLERANCE * max(edge, 1e-12)
    pts = pts - centroid
    found = []
    allowed = int((1.0 - shape.SYMMETRY_SHARE) * len(pts))
    for perm, signs in shape.SIGNED_PERMUTATIONS:
        image = pts[:, perm] * np.array(signs, dtype=np.float64)
        dist, _ = tree.query(image[:128], k=1, distance_upper_bound=limit)
        misses = int(np.count_nonzero(~np.isfinite(dist)))
        if misses > allowed:
            continue
        dist, _ = tree.query(image[128:], k=1, distance_upper_bound=limit)
        if misses + int(np.count_nonzero(~np.isfinite(dist))) <= allowed:
            found.append(shape.element_label(perm, signs))
    return found


def old_quality(mesh: Mesh, metrics: dict[str, Any]) -> dict[str, Any]:
    volume = metrics.get("volume")
    solid = None
    if volume is not None:
        try:
            hull = ConvexHull(mesh.vertices[np.unique(mesh.faces)]).volume
            solid = float(abs(volume) / hull) if hull > 0 else None
        except (QhullError, ValueError):
            pass
    found = old_symmetries(mesh)
    return {
        "free_standing": bool(metrics.get("box_fraction", 1.0) == 0.0),
        "solidity": solid,
        "symmetry": len(found),
        "symmetry_permutations": len({"".join(c for c in x if c != "-") for x in found}),
        "symmetry_mirrors": len({"-xyz", "x-yz", "xy-z"} & set(found)),
        "symmetries": " ".join(found),
    }


def old_measure(mesh: Mesh) -> Metrics:
    """measure_mesh with the edges counted by one np.unique sort and numpy area and volume."""
    v, f = mesh.vertices, mesh.faces
    start = f.reshape(-1)
    end = f[:, [1, 2, 0]].reshape(-1)
    key = np.minimum(start, end) * np.int64(mesh.n_vertices) + np.maximum(start, end)
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    forward = np.bincount(inverse.reshape(-1), weights=start < end, minlength=len(counts))
    n_edges = len(counts)
    boundary = int(np.count_nonzero(counts == 1))
    nonmanifold = int(np.count_nonzero(counts > 2))
    oriented = bool(np.all(forward[counts == 2] == 1))
    topo = meshlab.topology(mesh)
    used = np.bincount(f.reshape(-1), minlength=mesh.n_vertices) > 0
    euler = int(np.count_nonzero(used)) - n_edges + mesh.n_faces
    components = int(topo["components"])
    nmv = int(topo["nonmanifold_vertices"])
    watertight = boundary == 0 and nonmanifold == 0
    closed = watertight and nmv == 0 and oriented
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    area = float(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())
    genus = volume = None
    if closed:
        genus = (2 * components - euler) // 2
        o = 0.5 * (v.min(axis=0) + v.max(axis=0))
        volume = float(np.einsum("ij,ij->i", a - o, np.cross(b - o, c - o)).sum() / 6.0)
    lo, hi = v[used].min(axis=0), v[used].max(axis=0)
    return Metrics(
        vertices=mesh.n_vertices,
        faces=mesh.n_faces,
        components=components,
        euler=int(euler),
        genus=None if genus is None else int(genus),
        watertight=bool(watertight),
        boundary_edges=boundary,
        nonmanifold_edges=nonmanifold,
        nonmanifold_vertices=nmv,
        area=area,
        volume=volume,
        bbox=tuple(float(x) for pair in zip(lo, hi, strict=True) for x in pair),
    )


def old_curvature(v: np.ndarray, f: np.ndarray) -> float:
    edges = [v[f[:, (k + 1) % 3]] - v[f[:, k]] for k in range(3)]
    lengths = [np.linalg.norm(e, axis=1) for e in edges]
    angles = np.empty(f.shape)
    for k in range(3):
        j = (k + 2) % 3
        cos = -np.einsum("ij,ij->i", edges[k], edges[j]) / (lengths[k] * lengths[j] + 1e-300)
        angles[:, k] = np.arccos(np.clip(cos, -1.0, 1.0))
    angle_sum = np.bincount(f.ravel(), weights=angles.ravel(), minlength=len(v))
    used = np.bincount(f.ravel(), minlength=len(v)) > 0
    return float(np.abs(2 * math.pi - angle_sum[used]).sum())


def old_shape(mesh: Mesh, quick: dict[str, Any]) -> dict[str, Any]:
    m = old_measure(mesh).to_dict()
    m.update(quick)
    m["total_curvature"] = old_curvature(mesh.vertices, mesh.faces) / (4 * math.pi)
    return m


def old_descriptor(mesh: Mesh) -> np.ndarray:
    """The numpy descriptor: whole (F, 3, 3) triangles, np.unique cells, an unbounded query."""
    tri = mesh.vertices[mesh.faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    doubled = np.linalg.norm(cross, axis=1)
    areas = 0.5 * doubled
    total = float(areas.sum())
    rng = np.random.default_rng(desc.SEED)
    cumulative = np.cumsum(areas)
    faces = np.minimum(
        np.searchsorted(cumulative, rng.random(desc.POINTS) * total, side="right"), len(areas) - 1
    )
    r1, r2 = rng.random((2, desc.POINTS))
    s = np.sqrt(r1)
    a, b, c = tri[faces, 0], tri[faces, 1], tri[faces, 2]
    points = (1 - s)[:, None] * a + (s * (1 - r2))[:, None] * b + (s * r2)[:, None] * c
    centroid = (areas[:, None] * tri.mean(axis=1)).sum(axis=0) / total
    i, j = rng.integers(0, desc.POINTS, size=(2, desc.PAIRS))
    d2 = np.linalg.norm(points[i] - points[j], axis=1)
    d1 = np.linalg.norm(points - centroid, axis=1)
    normals = cross / np.maximum(doubled, np.finfo(np.float64).tiny)[:, None]
    parts = [desc._histogram(d2, desc.D2_BINS), desc._histogram(d1, desc.D1_BINS)]
    for k in range(3):
        counts, _ = np.histogram(
            np.abs(normals[:, k]), bins=desc.NORMAL_BINS, range=(0.0, 1.0), weights=areas
        )
        parts.append(counts / total)
    radius = float(np.sqrt(np.mean(d1**2)))
    axis = np.linspace(-desc.PLACE_EXTENT, desc.PLACE_EXTENT, desc.PLACE_GRID)
    nodes = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    dist, _ = cKDTree((points - centroid) / radius).query(nodes)
    parts.append(desc._quantise(np.minimum(dist, desc.PLACE_CLIP)))
    centres = (tri.mean(axis=1) - centroid) / radius
    cells = np.floor(centres / desc.RELIEF_CELL).astype(np.int64)
    cells -= cells.min(axis=0)
    dims = cells.max(axis=0) + 1
    flat = np.ravel_multi_index(cells.T, tuple(int(d) for d in dims))
    _, cell = np.unique(flat, return_inverse=True)
    area_normals = 0.5 * cross
    tot = np.bincount(cell, weights=areas)
    summed = np.stack([np.bincount(cell, weights=area_normals[:, k]) for k in range(3)], axis=1)
    keep = tot > 0
    spread = 1.0 - np.linalg.norm(summed[keep], axis=1) / tot[keep]
    counts, _ = np.histogram(
        np.sqrt(np.clip(spread, 0.0, 1.0)), bins=desc.RELIEF_BINS, range=(0, 1), weights=tot[keep]
    )
    parts.append(counts / counts.sum())
    return np.concatenate(parts)


@numba.njit(cache=True, error_model="numpy", nogil=True)
def _old_shade(
    face_buffer: np.ndarray,
    bary_buffer: np.ndarray,
    faces: np.ndarray,
    vertices: np.ndarray,
    normals: np.ndarray,
    face_normals: np.ndarray,
    heights: np.ndarray,
    front_lut: np.ndarray,
    back_lut: np.ndarray,
    frame: np.ndarray,
    wall: np.ndarray,
    wall_colours: np.ndarray,
    out: np.ndarray,
) -> None:
    """Linear RGB of every covered pixel into ``out`` (H, W, 3).

    Everything is in world coordinates: ``vertices`` (V, 3), corner ``normals`` (F, 3, 3),
    ``face_normals`` (F, 3); ``frame`` (4, 3) holds the key light direction, the fill light direction, the
    camera's up axis and the eye position. ``heights`` (V,) in [0, 1] index the colour tables.
    A face whose geometric normal points away from the eye is a back face: its normal is
    flipped and it takes the back colour table.  A face with ``wall[t] = w > 0`` takes the flat
    linear colour ``wall_colours[w]`` instead (``--walls mark``: poles and jumps).
    """
    n_lut = front_lut.shape[0]
    kx, ky, kz = frame[0, 0], frame[0, 1], frame[0, 2]
    fx, fy, fz = frame[1, 0], frame[1, 1], frame[1, 2]
    ux, uy, uz = frame[2, 0], frame[2, 1], frame[2, 2]
    ex, ey, ez = frame[3, 0], frame[3, 1], frame[3, 2]
    for r in range(face_buffer.shape[0]):
        for c in range(face_buffer.shape[1]):
            t = face_buffer[r, c]
            if t < 0:
                continue
            i0 = faces[t, 0]
            i1 = faces[t, 1]
            i2 = faces[t, 2]
            b1 = bary_buffer[r, c, 0]
            b2 = bary_buffer[r, c, 1]
            b0 = 1.0 - b1 - b2
            vx = ex - (b0 * vertices[i0, 0] + b1 * vertices[i1, 0] + b2 * vertices[i2, 0])
            vy = ey - (b0 * vertices[i0, 1] + b1 * vertices[i1, 1] + b2 * vertices[i2, 1])
            vz = ez - (b0 * vertices[i0, 2] + b1 * vertices[i1, 2] + b2 * vertices[i2, 2])
            vn = math.sqrt(vx * vx + vy * vy + vz * vz)
            vx /= vn
            vy /= vn
            vz /= vn
            gx = face_normals[t, 0]
            gy = face_normals[t, 1]
            gz = face_normals[t, 2]
            front = gx * vx + gy * vy + gz * vz >= 0.0
            nx = b0 * normals[t, 0, 0] + b1 * normals[t, 1, 0] + b2 * normals[t, 2, 0]
            ny = b0 * normals[t, 0, 1] + b1 * normals[t, 1, 1] + b2 * normals[t, 2, 1]
            nz = b0 * normals[t, 0, 2] + b1 * normals[t, 1, 2] + b2 * normals[t, 2, 2]
            nn = math.sqrt(nx * nx + ny * ny + nz * nz)
            if nn > 1e-12:
                nx /= nn
                ny /= nn
                nz /= nn
            else:  # corner normals cancel (a fold at a grazing angle): use the face's own
                nx, ny, nz = gx, gy, gz
            if not front:
                nx, ny, nz = -nx, -ny, -nz
            h = b0 * heights[i0] + b1 * heights[i1] + b2 * heights[i2]
            k = int(h * (n_lut - 1) + 0.5)
            k = min(max(k, 0), n_lut - 1)
            key = max(nx * kx + ny * ky + nz * kz, 0.0)
            fill = max(nx * fx + ny * fy + nz * fz, 0.0)
            sky = 0.5 * (1.0 + nx * ux + ny * uy + nz * uz)
            diffuse = (
                _SKY_AMBIENT * sky
                + _GROUND_AMBIENT * (1.0 - sky)
                + _KEY_STRENGTH * key
                + _FILL_STRENGTH * fill
            )
            hx = kx + vx
            hy = ky + vy
            hz = kz + vz
            hn = math.sqrt(hx * hx + hy * hy + hz * hz)
            spec = 0.0
            if hn > 1e-12 and key > 0.0:
                ndh = max((nx * hx + ny * hy + nz * hz) / hn, 0.0)
                spec = _SPECULAR_STRENGTH * ndh**24.0
            w = wall[t]
            for ch in range(3):
                if w > 0:
                    base = wall_colours[w, ch]
                else:
                    base = front_lut[k, ch] if front else back_lut[k, ch]
                out[r, c, ch] = base * diffuse + spec


@numba.njit(cache=True, error_model="numpy", nogil=True)
def _old_corner_normals(
    faces: np.ndarray,
    weighted: np.ndarray,
    unit: np.ndarray,
    n_vertices: int,
    cos_crease: float,
    max_fan: int,
    out: np.ndarray,
) -> None:
    """Smooth normals per face corner into ``out`` (F, 3, 3), keeping creases sharp.

    The normal at corner k of face t is the area-weighted mean of the faces around that vertex
    whose normals are within the crease angle of face t's (``cos_crease``), so smooth parts are
    smooth and box edges or cone rims stay crisp. Around a vertex with more than ``max_fan``
    faces every face counts (bounds the quadratic cost of a huge fan).
    """
    start = np.zeros(n_vertices + 1, dtype=np.int64)
    for t in range(faces.shape[0]):
        for k in range(3):
            start[faces[t, k] + 1] += 1
    for i in range(n_vertices):
        start[i + 1] += start[i]
    fill = start[:-1].copy()
    incident = np.empty(3 * faces.shape[0], dtype=np.int64)  # faces around each vertex
    for t in range(faces.shape[0]):
        for k in range(3):
            i = faces[t, k]
            incident[fill[i]] = t
            fill[i] += 1
    for t in range(faces.shape[0]):
        for k in range(3):
            i = faces[t, k]
            crisp = start[i + 1] - start[i] <= max_fan
            sx = 0.0
            sy = 0.0
            sz = 0.0
            for j in range(start[i], start[i + 1]):
                g = incident[j]
                cos = unit[g, 0] * unit[t, 0] + unit[g, 1] * unit[t, 1] + unit[g, 2] * unit[t, 2]
                if cos >= cos_crease or not crisp:
                    sx += weighted[g, 0]
                    sy += weighted[g, 1]
                    sz += weighted[g, 2]
            length = math.sqrt(sx * sx + sy * sy + sz * sz)
            if length > 1e-300:
                out[t, k, 0] = sx / length
                out[t, k, 1] = sy / length
                out[t, k, 2] = sz / length


def old_prepare(mesh: Mesh) -> pic._Scene:
    """pictures._prepare as it was: the same checks and scene, corner normals per corner."""
    vertices = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    if faces.shape[0] == 0 or vertices.shape[0] == 0:
        raise MeshError(
            f"cannot draw an empty mesh ({vertices.shape[0]} vertices, {faces.shape[0]} faces)"
        )
    if faces.min() < 0 or faces.max() >= vertices.shape[0]:
        raise MeshError(f"face indices outside [0, {vertices.shape[0]}): cannot draw the mesh")
    lo, hi = np.empty(3), np.empty(3)
    if not pic._bounds(vertices, faces, lo, hi):
        raise MeshError("mesh has non-finite vertex coordinates: cannot draw it")
    longest = float(np.max(hi - lo))
    if not longest > 0.0:
        raise MeshError("degenerate mesh: all vertices coincide, nothing to draw")
    unit = (vertices - 0.5 * (lo + hi)) / longest

    weighted = np.zeros((faces.shape[0], 3), dtype=np.float64)
    face_normals = np.zeros((faces.shape[0], 3), dtype=np.float64)
    keep = pic._face_normals(unit, faces, weighted, face_normals)
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
    cos_crease = math.cos(math.radians(pic._CREASE_ANGLE))
    _old_corner_normals(
        faces, weighted, face_normals, unit.shape[0], cos_crease, pic._MAX_FAN, normals
    )
    z = unit[:, 2]
    z_lo, z_hi = (lo[2] - hi[2]) / (2.0 * longest), (hi[2] - lo[2]) / (2.0 * longest)
    heights = (z - z_lo) / (z_hi - z_lo) if z_hi > z_lo else np.full_like(z, 0.5)
    return pic._Scene(
        vertices=unit,
        faces=faces,
        normals=normals,
        face_normals=face_normals,
        heights=np.clip(heights, 0.0, 1.0),
        wall=np.ascontiguousarray(wall),
    )


def old_image(mesh: Mesh, size: int = 256) -> np.ndarray:
    """render_image's default view with the previous corner normals, shader (pow) and cleared
    buffers."""
    scene = old_prepare(mesh)
    n = size * pic._SUPERSAMPLE
    rotation = pic._view_rotation(30.0, 25.0)
    count = scene.vertices.shape[0]
    sx, sy, inv_depth = np.empty(count), np.empty(count), np.empty(count)
    focal = pic._focal(25.0) * 0.5 * n
    pic._project(scene.vertices, rotation, pic._CAMERA_DISTANCE, focal, 0.5 * n, sx, sy, inv_depth)
    depth = np.zeros((n, n))
    face = np.full((n, n), -1, dtype=np.int64)
    bary = np.zeros((n, n, 2))
    pic._rasterise(sx, sy, inv_depth, scene.faces, n, n, depth, face, bary)
    front_lut, back_lut = pic._height_lut()
    frame = np.stack(
        [
            pic._unit(pic._KEY_DIRECTION) @ rotation,
            pic._unit(pic._FILL_DIRECTION) @ rotation,
            rotation[1],
            pic._CAMERA_DISTANCE * rotation[2],
        ]
    )
    colour = np.zeros((n, n, 3))
    _old_shade(
        face,
        bary,
        scene.faces,
        scene.vertices,
        scene.normals,
        scene.face_normals,
        scene.heights,
        front_lut,
        back_lut,
        frame,
        scene.wall,
        pic._wall_colours(),
        colour,
    )
    covered = face >= 0
    pic._darken_edges(colour, depth, covered)
    return pic._resolve(colour, covered, size, pic._BACKGROUND)


def old_thumbnail(mesh: Mesh) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(old_image(mesh)).save(buffer, format="PNG", compress_level=6)
    return buffer.getvalue()


def new_thumbnail(mesh: Mesh) -> bytes:
    return png_bytes(render_image(mesh, size=pic.THUMBNAIL_SIZE))


# -- the run -------------------------------------------------------------------------------------


def sample_meshes(n: int, seed: int) -> list[Mesh]:
    """The meshes of the accepted shapes among the first ``n`` draws (as written to disk)."""
    config = load_config(None)
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for index in range(n):
            shape_out = make_shape(index, seed=seed, config=config, staging=Path(tmp))
            if shape_out.mesh_file is not None:
                out.append(load_mesh(shape_out.mesh_file))
    return out


def main(argv: list[str] | None = None) -> None:
    parser = harness.parser(__doc__, repeats=3)
    parser.add_argument("--n", type=int, default=60, help="draws to take accepted meshes from")
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--catalogue", type=Path, help="take the meshes of this catalogue")
    args = parser.parse_args(argv)
    run = harness.Run("shape_checks", args)

    if args.catalogue:
        meshes = [load_mesh(p) for p in sorted((args.catalogue / "meshes").glob("*.ply"))]
    else:
        meshes = sample_meshes(args.n, args.seed)
    if not meshes:
        raise SystemExit("error: no meshes to measure (no accepted shape)")
    faces = [m.n_faces for m in meshes]
    run.say(
        f"{len(meshes)} meshes, {min(faces)}-{max(faces)} faces (median {int(np.median(faces))});"
        f" best of {args.repeats}"
    )

    # the quick metrics are measured before either version runs (shared input, as in the sampler)
    inputs = []
    for m in meshes:
        lo, hi = m.vertices.min(axis=0), m.vertices.max(axis=0)
        box = tuple(float(x) for pair in zip(lo, hi, strict=True) for x in pair)
        inputs.append(quick_metrics(m, box))
    checks: dict[str, tuple[Callable[..., Any], Callable[..., Any]]] = {
        "shape": (old_shape, shape_metrics),
        "quality": (old_quality, quality_metrics),
        "descriptor": (old_descriptor, descriptor),
        "thumbnail": (old_thumbnail, new_thumbnail),
    }
    # warm up (numba compiles or loads its cache)
    old_shape(meshes[0], inputs[0])
    shape_metrics(meshes[0], (), quick=inputs[0])
    old_thumbnail(meshes[0])
    new_thumbnail(meshes[0])
    totals = {name: [0.0, 0.0] for name in checks}
    same = {name: 0 for name in checks}
    for m, quick in zip(meshes, inputs, strict=True):
        metrics: dict[str, Any] = {}
        for name, (old, new) in checks.items():
            if name == "shape":
                calls = (partial(old, m, quick), partial(new, m, (), quick=quick))
            elif name == "quality":
                calls = (partial(old, m, metrics), partial(new, m, metrics))
            else:
                calls = (partial(old, m), partial(new, m))
            # old and new take turns, so load changes hit both alike
            timings = harness.take_turns({"old": calls[0], "new": calls[1]}, args.repeats)
            t_old, r_old = timings["old"].best, timings["old"].result
            t_new, r_new = timings["new"].best, timings["new"].result
            totals[name][0] += t_old
            totals[name][1] += t_new
            if name == "shape":
                metrics = dict(r_new)
            if name == "thumbnail":
                r_old = np.asarray(Image.open(io.BytesIO(r_old)))
                r_new = np.asarray(Image.open(io.BytesIO(r_new)))
            if name in ("descriptor", "thumbnail"):
                same[name] += bool(np.array_equal(r_old, r_new))
            else:
                same[name] += r_old == r_new
    k = len(meshes)
    run.say(f"\n{'check':12s} {'old ms':>8s} {'new ms':>8s} {'ratio':>7s}  identical")
    for name, (t_old, t_new) in totals.items():
        what = "pixels" if name == "thumbnail" else "values"
        run.say(
            f"{name:12s} {1000 * t_old / k:8.1f} {1000 * t_new / k:8.1f} "
            f"{t_old / t_new:6.2f}x  {same[name]}/{k} {what}"
        )
    t_old = sum(t for t, _ in totals.values())
    t_new = sum(t for _, t in totals.values())
    run.say(f"{'total':12s} {1000 * t_old / k:8.1f} {1000 * t_new / k:8.1f} {t_old / t_new:6.2f}x")
    run.record(
        meshes=k,
        seconds={
            "old": {n: t[0] for n, t in totals.items()},
            "new": {n: t[1] for n, t in totals.items()},
        },
        identical=same,
    )
    run.save()


if __name__ == "__main__":
    main()
