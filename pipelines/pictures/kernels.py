"""The numba kernels of the software renderer (:mod:`surfgen.pipelines.pictures.raster`).

The z-buffer rasteriser (:func:`_rasterise`: the nearest triangle and its perspective-correct
barycentrics per pixel), the projection, the shading pass (two-sided Blinn-Phong under the
camera's lights, :func:`_shade`), face and crease-aware corner normals, and the 2x2 downsampling
in linear light.  Arrays and scalars in, arrays out: the raster module validates and prepares.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from surfgen.generator.jit.options import KERNEL

# Light strengths (the directions are in raster.py, normalised there and passed in).
_KEY_STRENGTH = 0.78
_FILL_STRENGTH = 0.30
_SKY_AMBIENT = 0.22  # hemisphere ambient: normals pointing up get the sky, down the ground
_GROUND_AMBIENT = 0.10
_SPECULAR_STRENGTH = 0.16
_SPECULAR_EXPONENT = 24  # applied by squarings in _shade


@numba.njit(**KERNEL)
def _rasterise(
    sx: np.ndarray,
    sy: np.ndarray,
    inv_depth: np.ndarray,
    faces: np.ndarray,
    width: int,
    height: int,
    depth_buffer: np.ndarray,
    face_buffer: np.ndarray,
    bary_buffer: np.ndarray,
) -> None:
    """Z-buffer the triangles ``faces`` (F, 3) of screen points ``(sx, sy)`` into the buffers.

    ``depth_buffer`` (H, W) holds 1/depth (0 = empty, larger = nearer); ``face_buffer`` (H, W)
    the nearest face (-1 = empty); ``bary_buffer`` (H, W, 2) its perspective-correct barycentrics
    of vertices 1 and 2. Pixel centres are at half-integers. Edges are inclusive with a tiny
    tolerance so triangles sharing an edge leave no cracks; both windings are drawn.
    """
    for t in range(faces.shape[0]):
        i0 = faces[t, 0]
        i1 = faces[t, 1]
        i2 = faces[t, 2]
        x0 = sx[i0]
        y0 = sy[i0]
        x1 = sx[i1]
        y1 = sy[i1]
        x2 = sx[i2]
        y2 = sy[i2]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if not abs(area) > 1e-12:  # also skips NaN
            continue
        inv_area = 1.0 / area
        c0 = max(int(math.ceil(min(x0, x1, x2) - 0.5)), 0)
        c1 = min(int(math.floor(max(x0, x1, x2) - 0.5)), width - 1)
        r0 = max(int(math.ceil(min(y0, y1, y2) - 0.5)), 0)
        r1 = min(int(math.floor(max(y0, y1, y2) - 0.5)), height - 1)
        if c0 > c1 or r0 > r1:
            continue
        w0 = inv_depth[i0]
        w1 = inv_depth[i1]
        w2 = inv_depth[i2]
        eps = -1e-7
        for r in range(r0, r1 + 1):
            py = r + 0.5
            for c in range(c0, c1 + 1):
                px = c + 0.5
                b0 = ((x1 - px) * (y2 - py) - (x2 - px) * (y1 - py)) * inv_area
                b1 = ((x2 - px) * (y0 - py) - (x0 - px) * (y2 - py)) * inv_area
                b2 = 1.0 - b0 - b1
                if b0 < eps or b1 < eps or b2 < eps:
                    continue
                q0 = b0 * w0
                q1 = b1 * w1
                q2 = b2 * w2
                z = q0 + q1 + q2
                if z > depth_buffer[r, c]:
                    depth_buffer[r, c] = z
                    face_buffer[r, c] = t
                    bary_buffer[r, c, 0] = q1 / z
                    bary_buffer[r, c, 1] = q2 / z


@numba.njit(**KERNEL)
def _project(
    vertices: np.ndarray,
    rotation: np.ndarray,
    camera_distance: float,
    focal: float,
    centre: float,
    sx: np.ndarray,
    sy: np.ndarray,
    inv_depth: np.ndarray,
) -> None:
    """Perspective-project ``vertices`` (V, 3) into pixel coordinates ``sx``, ``sy`` (V,).

    ``rotation`` (3, 3) maps world to camera axes (right, up, back); the camera sits at
    ``camera_distance`` on the back axis. ``inv_depth`` (V,) gets 1 / distance along the view.
    """
    for i in range(vertices.shape[0]):
        x = vertices[i, 0]
        y = vertices[i, 1]
        z = vertices[i, 2]
        cx = rotation[0, 0] * x + rotation[0, 1] * y + rotation[0, 2] * z
        cy = rotation[1, 0] * x + rotation[1, 1] * y + rotation[1, 2] * z
        cz = rotation[2, 0] * x + rotation[2, 1] * y + rotation[2, 2] * z
        w = 1.0 / (camera_distance - cz)
        inv_depth[i] = w
        sx[i] = centre + focal * cx * w
        sy[i] = centre - focal * cy * w


@numba.njit(**KERNEL)
def _highlight(ndh: float) -> float:
    """Blinn-Phong term ``_SPECULAR_STRENGTH * ndh**24`` by squarings (x^8 x^8 x^8): a fifth
    of the cost of ``pow`` per pixel, within 1e-14 of it relatively, far below the 1/4095
    step of the colour table (thumbnails unchanged, pixel for pixel, on the seed-7 sample)."""
    p2 = ndh * ndh
    p4 = p2 * p2
    p8 = p4 * p4
    return _SPECULAR_STRENGTH * (p8 * p8 * p8)


@numba.njit(**KERNEL)
def _shade(
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
                spec = _highlight(ndh)
            w = wall[t]
            for ch in range(3):
                if w > 0:
                    base = wall_colours[w, ch]
                else:
                    base = front_lut[k, ch] if front else back_lut[k, ch]
                out[r, c, ch] = base * diffuse + spec


@numba.njit(**KERNEL)
def _bounds(vertices: np.ndarray, faces: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Bounding box ``lo``, ``hi`` (3,) of the vertices that faces use (unused ones may be junk).

    Returns False if one of them is not finite. Indices must be valid.
    """
    for k in range(3):
        lo[k] = np.inf
        hi[k] = -np.inf
    for t in range(faces.shape[0]):
        for j in range(3):
            i = faces[t, j]
            for k in range(3):
                x = vertices[i, k]
                if not math.isfinite(x):
                    return False
                lo[k] = min(lo[k], x)
                hi[k] = max(hi[k], x)
    return True


@numba.njit(**KERNEL)
def _face_normals(
    vertices: np.ndarray, faces: np.ndarray, weighted: np.ndarray, unit: np.ndarray
) -> np.ndarray:
    """Fill ``weighted`` (F, 3) with cross products (length 2 * area) and ``unit`` (F, 3).

    Counter-clockwise faces give outward normals. Returns a bool (F,) mask of faces with
    positive area; the others keep zero normals.
    """
    keep = np.zeros(faces.shape[0], dtype=np.bool_)
    for t in range(faces.shape[0]):
        i0 = faces[t, 0]
        ax = vertices[faces[t, 1], 0] - vertices[i0, 0]
        ay = vertices[faces[t, 1], 1] - vertices[i0, 1]
        az = vertices[faces[t, 1], 2] - vertices[i0, 2]
        bx = vertices[faces[t, 2], 0] - vertices[i0, 0]
        by = vertices[faces[t, 2], 1] - vertices[i0, 1]
        bz = vertices[faces[t, 2], 2] - vertices[i0, 2]
        nx = ay * bz - az * by
        ny = az * bx - ax * bz
        nz = ax * by - ay * bx
        length = math.sqrt(nx * nx + ny * ny + nz * nz)
        if not length > 1e-14:
            continue
        keep[t] = True
        weighted[t, 0] = nx
        weighted[t, 1] = ny
        weighted[t, 2] = nz
        unit[t, 0] = nx / length
        unit[t, 1] = ny / length
        unit[t, 2] = nz / length
    return keep


@numba.njit(**KERNEL)
def _corner_normals(
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

    Vertex by vertex: where every pair of the fan is within the crease angle (most vertices of
    a marching-cubes surface) all its corners take the one sum over the whole fan, added once in
    fan order — the same additions, hence the same bits, as summing it per corner.
    """
    start = np.zeros(n_vertices + 1, dtype=np.int64)
    for t in range(faces.shape[0]):
        for k in range(3):
            start[faces[t, k] + 1] += 1
    for i in range(n_vertices):
        start[i + 1] += start[i]
    fill = start[:-1].copy()
    incident = np.empty(3 * faces.shape[0], dtype=np.int64)  # faces around each vertex
    corner = np.empty(3 * faces.shape[0], dtype=np.int64)  # and which corner is the vertex
    for t in range(faces.shape[0]):
        for k in range(3):
            i = faces[t, k]
            incident[fill[i]] = t
            corner[fill[i]] = k
            fill[i] += 1
    for i in range(n_vertices):
        s = start[i]
        e = start[i + 1]
        smooth = True
        if e - s <= max_fan:
            for a in range(s, e):
                t = incident[a]
                for b in range(a + 1, e):
                    g = incident[b]
                    cos = (
                        unit[g, 0] * unit[t, 0] + unit[g, 1] * unit[t, 1] + unit[g, 2] * unit[t, 2]
                    )
                    if not cos >= cos_crease:
                        smooth = False
                        break
                if not smooth:
                    break
        if smooth:
            sx = 0.0
            sy = 0.0
            sz = 0.0
            for b in range(s, e):
                g = incident[b]
                sx += weighted[g, 0]
                sy += weighted[g, 1]
                sz += weighted[g, 2]
            length = math.sqrt(sx * sx + sy * sy + sz * sz)
            if length > 1e-300:
                for a in range(s, e):
                    t = incident[a]
                    k = corner[a]
                    out[t, k, 0] = sx / length
                    out[t, k, 1] = sy / length
                    out[t, k, 2] = sz / length
            continue
        for a in range(s, e):
            t = incident[a]
            sx = 0.0
            sy = 0.0
            sz = 0.0
            for b in range(s, e):
                g = incident[b]
                cos = unit[g, 0] * unit[t, 0] + unit[g, 1] * unit[t, 1] + unit[g, 2] * unit[t, 2]
                if cos >= cos_crease:
                    sx += weighted[g, 0]
                    sy += weighted[g, 1]
                    sz += weighted[g, 2]
            length = math.sqrt(sx * sx + sy * sy + sz * sz)
            if length > 1e-300:
                k = corner[a]
                out[t, k, 0] = sx / length
                out[t, k, 1] = sy / length
                out[t, k, 2] = sz / length


@numba.njit(**KERNEL)
def _downsample(
    colour: np.ndarray,
    covered: np.ndarray,
    factor: int,
    background: np.ndarray,
    srgb_table: np.ndarray,
    out: np.ndarray,
) -> None:
    """Average ``factor``² blocks of linear ``colour`` (H, W, 3) into sRGB uint8 ``out``.

    ``out`` is (h, w, 3), composited over linear ``background`` (3,), or (h, w, 4) with straight
    alpha = covered fraction if it has four channels. ``colour`` is read only where covered
    (elsewhere it may hold anything), so block sums are premultiplied. ``srgb_table`` maps ``round(linear * (n - 1))`` to sRGB.
    """
    last = srgb_table.shape[0] - 1
    weight = 1.0 / (factor * factor)
    rgba = out.shape[2] == 4
    for r in range(out.shape[0]):
        for c in range(out.shape[1]):
            alpha = 0.0
            acc0 = 0.0
            acc1 = 0.0
            acc2 = 0.0
            for dr in range(factor):
                for dc in range(factor):
                    rr = r * factor + dr
                    cc = c * factor + dc
                    if covered[rr, cc]:
                        alpha += weight
                        acc0 += colour[rr, cc, 0] * weight
                        acc1 += colour[rr, cc, 1] * weight
                        acc2 += colour[rr, cc, 2] * weight
            if rgba:
                scale = 1.0 / alpha if alpha > 0.0 else 0.0
                acc0 *= scale
                acc1 *= scale
                acc2 *= scale
                out[r, c, 3] = min(max(int(alpha * 255.0 + 0.5), 0), 255)
            else:
                rest = 1.0 - alpha
                acc0 += rest * background[0]
                acc1 += rest * background[1]
                acc2 += rest * background[2]
            out[r, c, 0] = srgb_table[min(max(int(acc0 * last + 0.5), 0), last)]
            out[r, c, 1] = srgb_table[min(max(int(acc1 * last + 0.5), 0), last)]
            out[r, c, 2] = srgb_table[min(max(int(acc2 * last + 0.5), 0), last)]
