"""How a shape reads in outline: does any view of it show more than the outline of a lump?

A person judges a thumbnail first by its silhouette: arms, lobes, tunnels one sees through,
a waist. A ball or a box with dents, a gem whose ornament only grazes its facets, a lens — every
view of them is a convex outline. :func:`outline_fill` measures that: the mesh is projected
orthographically along :data:`VIEWS` (the three axes and the four body diagonals) onto a square
of :data:`PIXELS` pixels, its silhouette rasterised (a pixel is covered when its centre lies in a
projected triangle; a hole one sees through stays empty), and the silhouette's area is divided
by the area of its convex hull (over the covered pixels' corners). The metric ``outline`` is the
smallest of those fills: near 1 when every view is a convex blot, lower when some view shows an
arm, a notch or a hole (a star 0.55-0.65, a carved body 0.75-0.87, dented lumps 0.88-0.95 on the
sampler's shapes; docs/guide/filters.md).

The projection and the coverage tests are a fixed sequence of IEEE operations (no fused
multiply-adds: :mod:`surfgen.generator.jit.options`), and the hull is computed on integer pixel
corners, so the measure is the same on every CPU.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from surfgen.generator.jit.options import KERNEL
from surfgen.generator.mesh.mesh import Mesh

PIXELS = 96  # the silhouette's square, in pixels a side
# View directions (unit vectors, rows): along x, y, z and the four body diagonals.
_D = 1.0 / math.sqrt(3.0)
VIEWS = np.array(
    [
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [_D, _D, _D],
        [_D, _D, -_D],
        [_D, -_D, _D],
        [-_D, _D, _D],
    ]
)
_UP = np.array([0.3, 0.5, 0.8])  # any direction along no view: fixes each view's image axes


def _image_axes() -> np.ndarray:
    """``(V, 2, 3)``: two orthonormal image axes per view (perpendicular to it). The length is
    summed in Python floats, not by ``np.linalg.norm`` (a BLAS dot, whose rounding may depend
    on the CPU's kernel): the same axes on every machine."""
    out = np.empty((len(VIEWS), 2, 3))
    for i, d in enumerate(VIEWS):
        u = np.cross(d, _UP)
        u /= math.sqrt(
            float(u[0]) * float(u[0]) + float(u[1]) * float(u[1]) + float(u[2]) * float(u[2])
        )
        out[i, 0], out[i, 1] = u, np.cross(d, u)
    return out


IMAGE_AXES = _image_axes()


def outline_fills(mesh: Mesh, pixels: int = PIXELS) -> np.ndarray:
    """``(V,)``: for each of :data:`VIEWS`, the silhouette's area / its convex hull's area
    (module doc); an empty mesh gives ones."""
    v = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    f = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    if f.shape[0] == 0:
        return np.ones(len(VIEWS))
    used = np.zeros(len(v), dtype=np.bool_)
    used[f.ravel()] = True
    p = v[used]
    centre = (p.max(axis=0) + p.min(axis=0)) / 2.0
    radius = float(np.sqrt(((p - centre) ** 2).sum(axis=1)).max()) or 1.0
    return _fills(v, f, centre, pixels / (2.02 * radius), IMAGE_AXES, pixels)


def outline_fill(mesh: Mesh, pixels: int = PIXELS) -> float:
    """The metric ``outline``: the smallest of :func:`outline_fills` (module doc)."""
    return float(outline_fills(mesh, pixels).min())


@numba.njit(**KERNEL)
def _fills(v, f, centre, scale, axes, n):
    """The fill of each view (:func:`outline_fills`): project, rasterise, hull."""
    out = np.empty(axes.shape[0])
    px = np.empty(v.shape[0])
    py = np.empty(v.shape[0])
    half = n / 2.0
    for view in range(axes.shape[0]):
        for i in range(v.shape[0]):
            x = v[i, 0] - centre[0]
            y = v[i, 1] - centre[1]
            z = v[i, 2] - centre[2]
            px[i] = (x * axes[view, 0, 0] + y * axes[view, 0, 1] + z * axes[view, 0, 2]) * scale
            py[i] = (x * axes[view, 1, 0] + y * axes[view, 1, 1] + z * axes[view, 1, 2]) * scale
            px[i] += half
            py[i] += half
        mask = _rasterise(px, py, f, n)
        out[view] = _fill(mask)
    return out


@numba.njit(**KERNEL)
def _rasterise(px, py, f, n):
    """``(n, n)`` bool: the pixels whose centre lies in (or on) a projected triangle."""
    mask = np.zeros((n, n), dtype=np.bool_)
    for t in range(f.shape[0]):
        ax, ay = px[f[t, 0]], py[f[t, 0]]
        bx, by = px[f[t, 1]], py[f[t, 1]]
        cx, cy = px[f[t, 2]], py[f[t, 2]]
        det = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)
        if det == 0.0:
            continue  # seen edge-on: its neighbours cover its pixels
        sign = 1.0 if det > 0.0 else -1.0
        # the pixels whose centre (i + 0.5, j + 0.5) is inside the triangle's bounding box
        i0 = max(int(math.ceil(min(ax, bx, cx) - 0.5)), 0)
        i1 = min(int(math.floor(max(ax, bx, cx) - 0.5)), n - 1)
        j0 = max(int(math.ceil(min(ay, by, cy) - 0.5)), 0)
        j1 = min(int(math.floor(max(ay, by, cy) - 0.5)), n - 1)
        for i in range(i0, i1 + 1):
            x = i + 0.5
            for j in range(j0, j1 + 1):
                if mask[i, j]:
                    continue
                y = j + 0.5
                # the three edge functions, each of the sign of det inside (or 0 on an edge)
                e0 = ((bx - x) * (cy - y) - (cx - x) * (by - y)) * sign
                e1 = ((cx - x) * (ay - y) - (ax - x) * (cy - y)) * sign
                e2 = ((ax - x) * (by - y) - (bx - x) * (ay - y)) * sign
                if e0 >= 0.0 and e1 >= 0.0 and e2 >= 0.0:
                    mask[i, j] = True
    return mask


@numba.njit(**KERNEL)
def _fill(mask):
    """Covered pixels / the area of the convex hull of their corners (1 when none is covered).

    The hull of the rows' extreme corners (each row's first and last covered pixel), by
    Andrew's monotone chain on integers: exact."""
    n = mask.shape[0]
    xs = np.empty(4 * n, dtype=np.int64)
    ys = np.empty(4 * n, dtype=np.int64)
    m = 0
    covered = 0
    for i in range(n):
        lo, hi = -1, -1
        for j in range(n):
            if mask[i, j]:
                covered += 1
                if lo < 0:
                    lo = j
                hi = j
        if lo >= 0:  # the corners (i, lo), (i, hi + 1), (i + 1, lo), (i + 1, hi + 1)
            for di in (0, 1):
                xs[m], ys[m] = i + di, lo
                xs[m + 1], ys[m + 1] = i + di, hi + 1
                m += 2
    if covered == 0:
        return 1.0
    # points sorted by (x, y): rows come in order; within a row pair, sort the few by y
    order = np.argsort(xs[:m] * (4 * n) + ys[:m])
    hx = np.empty(2 * m + 1, dtype=np.int64)
    hy = np.empty(2 * m + 1, dtype=np.int64)
    k = 0
    for s in range(m):  # lower hull
        x, y = xs[order[s]], ys[order[s]]
        while k >= 2 and _cross(hx[k - 2], hy[k - 2], hx[k - 1], hy[k - 1], x, y) <= 0:
            k -= 1
        hx[k], hy[k] = x, y
        k += 1
    lower = k + 1
    for s in range(m - 2, -1, -1):  # upper hull
        x, y = xs[order[s]], ys[order[s]]
        while k >= lower and _cross(hx[k - 2], hy[k - 2], hx[k - 1], hy[k - 1], x, y) <= 0:
            k -= 1
        hx[k], hy[k] = x, y
        k += 1
    twice = 0  # shoelace over the closed hull (its last point repeats the first)
    for s in range(k - 1):
        twice += hx[s] * hy[s + 1] - hx[s + 1] * hy[s]
    return covered / (abs(twice) / 2.0)


@numba.njit(**KERNEL)
def _cross(ox, oy, ax, ay, bx, by):
    return (ax - ox) * (by - oy) - (ay - oy) * (bx - ox)
