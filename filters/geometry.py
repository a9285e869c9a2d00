"""One-pass numba kernels behind the per-shape checks (metrics, curvature, symmetry, descriptor).

Every accepted candidate of a sampling run is measured several ways; numpy did each measure with
several whole-array temporaries (fancy-indexed ``(F, 3, 3)`` triangles, cross products, norms).
These kernels compute the same per-face and per-corner numbers in one pass, with the *same
floating-point operations in the same order* as the numpy expressions they replace, so every
stored metric stays bit for bit what it was. What numpy sums (pairwise summation over faces) is
still summed by numpy: the kernels hand it the per-face terms. The orders were checked against
numpy on a million random rows each (``tests/filters/test_geometry.py`` keeps the comparison):

- ``np.linalg.norm(e, axis=1)`` is ``sqrt((x*x + y*y) + z*z)``;
- ``np.einsum("ij,ij->i", a, b)`` on rows of three is ``(a0*b0 + a2*b2) + a1*b1``;
- ``np.cross`` is the textbook component formula; ``tri.mean(axis=1)`` is ``((a + b) + c) / 3``;
- ``np.bincount(idx, weights)`` adds the weights in index order, one after the other.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from surfgen.generator.elementary.trig import acos_scalar
from surfgen.generator.jit.options import CHECKED


@numba.njit(**CHECKED)
def _dot(ax: float, ay: float, az: float, bx: float, by: float, bz: float) -> float:
    """``np.einsum("ij,ij->i")`` on one row of three: its pairing, not left to right."""
    return (ax * bx + az * bz) + ay * by


@numba.njit(**CHECKED)
def used_mask(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """``(V,)`` bool: the vertices some face uses (``np.unique(faces)`` as a mask, same order)."""
    out = np.zeros(n_vertices, dtype=np.bool_)
    for t in range(faces.shape[0]):
        for k in range(3):
            out[faces[t, k]] = True
    return out


def pick_faces(cumulative: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """The face of each key along the faces' cumulative areas — points uniform by area pick
    their faces this way: ``np.searchsorted(cumulative, keys, side="right")`` clamped to the
    last face, the same indices, with the keys searched in increasing order (each binary
    search then walks on from the last: twice as fast for the filters' thousands of keys)."""
    order = np.argsort(keys)
    faces = np.empty(keys.shape[0], dtype=np.intp)
    faces[order] = np.searchsorted(cumulative, keys[order], side="right")
    return np.minimum(faces, len(cumulative) - 1)


def surface_samples(
    v: np.ndarray,
    f: np.ndarray,
    weights: np.ndarray,
    total: float,
    rng: np.random.Generator,
    n: int,
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points uniform by area on the faces ``f`` of ``v`` (``weights``: each face's area,
    or any one multiple of it; ``total`` their sum), and the face of each: ``((n, 3), (n,))``.
    Draws ``rng.random(n)`` for the faces (:func:`pick_faces`), then ``rng.random((2, n))`` for
    the points' barycentric coordinates (the square-root rule)."""
    faces = pick_faces(np.cumsum(weights), rng.random(n) * total)
    r1, r2 = rng.random((2, n))
    s = np.sqrt(r1)
    corners = f[faces]
    a, b, c = v[corners[:, 0]], v[corners[:, 1]], v[corners[:, 2]]
    return (1 - s)[:, None] * a + (s * (1 - r2))[:, None] * b + (s * r2)[:, None] * c, faces


@numba.njit(**CHECKED)
def weighted_centres(v: np.ndarray, f: np.ndarray, areas: np.ndarray) -> np.ndarray:
    """``areas[:, None] * v[f].mean(axis=1)`` ``(F, 3)``: summed over faces (by numpy) and
    divided by the total area it is the area centroid."""
    out = np.empty((f.shape[0], 3))
    for t in range(f.shape[0]):
        i0, i1, i2 = f[t, 0], f[t, 1], f[t, 2]
        for k in range(3):
            out[t, k] = areas[t] * ((v[i0, k] + v[i1, k] + v[i2, k]) / 3.0)
    return out


@numba.njit(**CHECKED)
def first_edge_lengths(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """``np.linalg.norm(v[f[:, 1]] - v[f[:, 0]], axis=1)``."""
    out = np.empty(f.shape[0])
    for t in range(f.shape[0]):
        x = v[f[t, 1], 0] - v[f[t, 0], 0]
        y = v[f[t, 1], 1] - v[f[t, 0], 1]
        z = v[f[t, 1], 2] - v[f[t, 0], 2]
        out[t] = math.sqrt(x * x + y * y + z * z)
    return out


@numba.njit(**CHECKED)
def volume_terms(v: np.ndarray, f: np.ndarray, o: np.ndarray) -> np.ndarray:
    """``einsum("ij,ij->i", a - o, cross(b - o, c - o))`` per face (six times its signed cone
    volume from ``o``)."""
    out = np.empty(f.shape[0])
    for t in range(f.shape[0]):
        i0, i1, i2 = f[t, 0], f[t, 1], f[t, 2]
        ax, ay, az = v[i0, 0] - o[0], v[i0, 1] - o[1], v[i0, 2] - o[2]
        bx, by, bz = v[i1, 0] - o[0], v[i1, 1] - o[1], v[i1, 2] - o[2]
        cx, cy, cz = v[i2, 0] - o[0], v[i2, 1] - o[1], v[i2, 2] - o[2]
        nx = by * cz - bz * cy
        ny = bz * cx - bx * cz
        nz = bx * cy - by * cx
        out[t] = _dot(ax, ay, az, nx, ny, nz)
    return out


@numba.njit(**CHECKED)
def corner_cosines(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Cosine of the angle at each face corner ``(F, 3)``, unclipped: corner k sees edge
    ``k -> k+1`` and the reversed edge ``k+2 -> k``, ``-(e_k . e_j) / (|e_k| |e_j| + 1e-300)``."""
    out = np.empty((f.shape[0], 3))
    e = np.empty((3, 3))
    n = np.empty(3)
    for t in range(f.shape[0]):
        for k in range(3):
            a = f[t, k]
            b = f[t, (k + 1) % 3]
            x = v[b, 0] - v[a, 0]
            y = v[b, 1] - v[a, 1]
            z = v[b, 2] - v[a, 2]
            e[k, 0] = x
            e[k, 1] = y
            e[k, 2] = z
            n[k] = math.sqrt(x * x + y * y + z * z)
        for k in range(3):
            j = (k + 2) % 3
            d = _dot(e[k, 0], e[k, 1], e[k, 2], e[j, 0], e[j, 1], e[j, 2])
            out[t, k] = -d / (n[k] * n[j] + 1e-300)
    return out


@numba.njit(**CHECKED)
def corner_angle_sums(v: np.ndarray, f: np.ndarray, n_vertices: int) -> np.ndarray:
    """Per vertex, the sum of the angles at its face corners, added in face order (like
    ``np.bincount(f.ravel(), weights=angles.ravel())``): the ``acos`` of
    :func:`corner_cosines` clipped to [-1, 1]. The ``acos`` is surfgen's own
    (``generator/elementary``: the same bits on every CPU), not numpy's ``arccos``, which runs
    SIMD code of its own on AVX-512 CPUs and so differs from one machine to another."""
    cos = corner_cosines(v, f)
    out = np.zeros(n_vertices)
    for t in range(f.shape[0]):
        for k in range(3):
            c = cos[t, k]
            if c < -1.0:
                c = -1.0
            elif c > 1.0:
                c = 1.0
            out[f[t, k]] += acos_scalar(c)
    return out


@numba.njit(**CHECKED)
def find_root(parent: np.ndarray, a: int) -> int:
    """The root of ``a`` in the union-find forest ``parent``, halving the path on the way."""
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@numba.njit(**CHECKED)
def join_sets(parent: np.ndarray, a: int, b: int) -> None:
    """Union of the sets of ``a`` and ``b`` (the lower root stays a root)."""
    a = find_root(parent, a)
    b = find_root(parent, b)
    if a < b:
        parent[b] = a
    elif b < a:
        parent[a] = b


@numba.njit(**CHECKED)
def edge_counts(faces: np.ndarray, n_vertices: int) -> tuple[int, int, int, bool, bool, int, int]:
    """The edges of a mesh and what they join, from its ``3F`` half-edges bucketed on their
    lower vertex (a vertex has a handful: a short sort each), no global sort:

    - distinct undirected edges, edges with one face, edges with more than two, and whether
      every two-face edge is walked once in each direction;
    - whether a face repeats a vertex;
    - the components of faces joined through shared edges, and the vertices whose faces make
      more than one fan (faces around a vertex joined through the edges at it): pymeshlab's
      ``connected_components_number`` and ``non_two_manifold_vertices``, which are these
      numbers wherever no edge has more than two faces and no face repeats a vertex (vcg walks
      each vertex's fan through face-face adjacency and compares its size with the vertex's
      face count; a face's orientation does not enter). Elsewhere they are not those numbers:
      :func:`surfgen.filters.metrics.measure_mesh` asks pymeshlab there.
    """
    n_faces = faces.shape[0]
    m = n_faces * 3
    start = np.zeros(n_vertices + 1, dtype=np.int64)
    for t in range(n_faces):
        for k in range(3):
            a = faces[t, k]
            b = faces[t, (k + 1) % 3]
            start[min(a, b) + 1] += 1
    for i in range(n_vertices):
        start[i + 1] += start[i]
    fill = start[:-1].copy()
    other = np.empty(m, dtype=np.int64)
    half = np.empty(m, dtype=np.int64)  # 3t + k: face t's edge from corner k to k + 1
    for t in range(n_faces):
        for k in range(3):
            a = faces[t, k]
            b = faces[t, (k + 1) % 3]
            lo = min(a, b)
            other[fill[lo]] = max(a, b)
            half[fill[lo]] = 3 * t + k
            fill[lo] += 1
    face_root = np.arange(n_faces)
    corner_root = np.arange(m)  # corner 3t + k: vertex faces[t, k] in face t
    count = 0
    boundary = 0
    nonmanifold = 0
    oriented = True
    degenerate = False
    for i in range(n_vertices):
        s, e = start[i], start[i + 1]
        # insertion sort of this vertex's few half-edges by their other end
        for p in range(s + 1, e):
            key = other[p]
            h = half[p]
            q = p - 1
            while q >= s and other[q] > key:
                other[q + 1] = other[q]
                half[q + 1] = half[q]
                q -= 1
            other[q + 1] = key
            half[q + 1] = h
        p = s
        while p < e:
            q = p
            fw = 0
            while q < e and other[q] == other[p]:
                h = half[q]
                fw += faces[h // 3, h % 3] < other[q]  # walked from the lower vertex
                q += 1
            c = q - p
            count += 1
            if other[p] == i:
                degenerate = True
            if c == 1:
                boundary += 1
            elif c > 2:
                nonmanifold += 1
            else:
                if fw != 1:
                    oriented = False
                t1, k1 = divmod(half[p], 3)
                t2, k2 = divmod(half[p + 1], 3)
                join_sets(face_root, t1, t2)
                # each end's corners in the two faces: one fan
                a1, b1 = 3 * t1 + k1, 3 * t1 + (k1 + 1) % 3
                a2, b2 = 3 * t2 + k2, 3 * t2 + (k2 + 1) % 3
                if faces[t1, k1] == faces[t2, k2]:  # both faces walk it the same way
                    join_sets(corner_root, a1, a2)
                    join_sets(corner_root, b1, b2)
                else:
                    join_sets(corner_root, a1, b2)
                    join_sets(corner_root, b1, a2)
            p = q
    components = 0
    for t in range(n_faces):
        components += find_root(face_root, t) == t
    fan = np.full(n_vertices, -1, dtype=np.int64)  # a vertex's first fan, -2 once counted
    pinched = 0
    for c in range(m):
        v = faces[c // 3, c % 3]
        r = find_root(corner_root, c)
        if fan[v] == -1:
            fan[v] = r
        elif fan[v] >= 0 and fan[v] != r:
            fan[v] = -2
            pinched += 1
    return count, boundary, nonmanifold, oriented, degenerate, components, pinched


@numba.njit(**CHECKED)
def column_bounds(a: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``a[mask].min(axis=0)`` and ``.max(axis=0)`` of an ``(N, 3)`` array in one pass (numpy's
    column reductions of a row-major array walk it three values at a time: 10x slower). NaN
    propagates as in numpy; an empty selection gives ``+inf`` and ``-inf``."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    nan = np.zeros(3, dtype=np.bool_)
    for i in range(a.shape[0]):
        if not mask[i]:
            continue
        for k in range(3):
            x = a[i, k]
            if x < lo[k]:
                lo[k] = x
            if x > hi[k]:
                hi[k] = x
            if x != x:
                nan[k] = True
    for k in range(3):
        if nan[k]:
            lo[k] = np.nan
            hi[k] = np.nan
    return lo, hi


@numba.njit(**CHECKED)
def cell_of(p: float, lo: np.ndarray, cell: float, dims: np.ndarray, k: int) -> int:
    """The cell of coordinate ``p`` on axis ``k`` of a lattice of ``dims`` cells of width
    ``cell`` from ``lo``, clamped into the lattice (points outside count in its border cells)."""
    c = int(math.floor((p - lo[k]) / cell))
    return min(max(c, 0), dims[k] - 1)


@numba.njit(**CHECKED)
def bucket_points(
    pts: np.ndarray, lo: np.ndarray, cell: float, dims: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Counting sort of the points ``(N, 3)`` by lattice cell (:func:`cell_of`, clamped):
    ``order[start[c]:start[c + 1]]`` are cell ``c``'s, ``c = (cx * dims[1] + cy) * dims[2] + cz``."""
    n = pts.shape[0]
    ids = np.empty(n, dtype=np.int64)
    for i in range(n):
        cx = cell_of(pts[i, 0], lo, cell, dims, 0)
        cy = cell_of(pts[i, 1], lo, cell, dims, 1)
        cz = cell_of(pts[i, 2], lo, cell, dims, 2)
        ids[i] = (cx * dims[1] + cy) * dims[2] + cz
    return counting_sort(ids, dims[0] * dims[1] * dims[2])


@numba.njit(**CHECKED)
def counting_sort(ids: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Items by their bucket ``ids`` (``0 <= id < size``), stable: ``order[start[c]:start[c +
    1]]`` are bucket ``c``'s, in their own order."""
    n = ids.shape[0]
    start = np.zeros(size + 1, dtype=np.int64)
    for i in range(n):
        start[ids[i] + 1] += 1
    for c in range(size):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, dtype=np.int64)
    for i in range(n):
        order[fill[ids[i]]] = i
        fill[ids[i]] += 1
    return start, order
