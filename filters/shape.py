"""Shape quality: does a shape stand free, how solid is it, which symmetries does its mesh have,
how far does it depart from its envelope?

- ``free_standing``: no area of the mesh lies on the box's faces (no caps: the box does not cut it);
- ``solidity``: enclosed volume / volume of the convex hull (1 for a convex body, less for a
  carved, lobed or holed one);
- ``symmetry``: the order of the group of axis permutations and reflections (the 48 signed
  permutations of x, y, z, about the surface's area centroid) that map the *mesh* onto itself
  within a tolerance — measured on surface points, not read from how the formula was built;
  ``symmetry_permutations`` counts the distinct axis permutations among them (1: none but the
  identity; 3: a cyclic symmetry; 6: all), ``symmetry_mirrors`` the mirrors x -> -x, y -> -y,
  z -> -z among them, ``symmetries`` lists them (``y-zx`` maps (x, y, z) to (y, -z, x));
- ``departure``: how far the surface departs from its envelope (sculptures): the volume between
  them (symmetric difference of the insides, on the grid) / the envelope's volume.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numba
import numpy as np
from scipy.spatial import ConvexHull, QhullError

from surfgen.filters.geometry import (
    bucket_points,
    column_bounds,
    first_edge_lengths,
    surface_samples,
    used_mask,
    weighted_centres,
)
from surfgen.generator.jit.options import CHECKED, read_only
from surfgen.generator.mesh.mesh import Mesh, face_areas

SYMMETRY_POINTS = 1024  # surface points tested per element
SYMMETRY_SEED = 20251201  # fixed: the measure is a function of the mesh alone
# A point maps onto the surface when its image is within this many mean edge lengths of a
# vertex; an element is a symmetry when this holds for SYMMETRY_SHARE of the points.
SYMMETRY_TOLERANCE = 1.0
SYMMETRY_SHARE = 0.98
SIGNED_PERMUTATIONS = tuple(
    (perm, signs)
    for perm in itertools.permutations(range(3))
    for signs in itertools.product((1, -1), repeat=3)
)


def element_label(perm: tuple[int, ...], signs: tuple[int, ...]) -> str:
    """``(x, y, z) -> (s0 v[perm0], s1 v[perm1], s2 v[perm2])`` written as e.g. ``y-zx``."""
    return "".join(("-" if s < 0 else "") + "xyz"[p] for p, s in zip(perm, signs, strict=True))


def _surface_points(mesh: Mesh, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points uniform by area on the mesh and its area centroid."""
    v, f = mesh.vertices, mesh.faces
    areas = face_areas(mesh)
    total = float(areas.sum())
    centroid = weighted_centres(v, f, areas).sum(axis=0) / total
    rng = np.random.default_rng(SYMMETRY_SEED)
    pts = surface_samples(v, f, areas, total, rng, n)[0]
    return pts, centroid


def mesh_symmetries(
    mesh: Mesh, tolerance: float = SYMMETRY_TOLERANCE, share: float = SYMMETRY_SHARE
) -> list[str]:
    """Labels of the signed axis permutations (about the area centroid) that map the mesh onto
    itself: a surface point's image must lie within ``tolerance`` mean edge lengths of a vertex,
    for ``share`` of the points. The identity ``xyz`` is always first."""
    if mesh.n_faces == 0:
        return []
    pts, centroid = _surface_points(mesh, SYMMETRY_POINTS)
    v = mesh.vertices
    f = mesh.faces
    cloud = v[used_vertices(mesh)] - centroid
    edge = float(first_edge_lengths(v, f).mean())
    limit = tolerance * max(edge, 1e-12)
    pts = np.ascontiguousarray(pts - centroid)
    allowed = int((1.0 - share) * len(pts))  # misses allowed
    start, order, origin, cell, dims = _cell_index(cloud, limit)
    ok = _symmetric(
        pts, cloud, start, order, origin, cell, dims, limit * limit, _PERMS, _SIGNS, allowed
    )
    return [
        element_label(perm, signs)
        for (perm, signs), hit in zip(SIGNED_PERMUTATIONS, ok, strict=True)
        if hit
    ]


_PERMS = np.array([perm for perm, _ in SIGNED_PERMUTATIONS], dtype=np.int64)
_SIGNS = np.array([signs for _, signs in SIGNED_PERMUTATIONS], dtype=np.float64)


def used_vertices(mesh: Mesh) -> np.ndarray:
    """``(V,)`` bool: the vertices some face uses (``np.unique(faces)`` as a mask, same order)."""
    return used_mask(mesh.faces, mesh.n_vertices)


def _cell_index(
    cloud: np.ndarray, limit: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, np.ndarray]:
    """Bucket ``cloud`` (N, 3) into cubic cells at least ``limit`` wide: every point within
    ``limit`` of a query lies in the query's cell or one of its 26 neighbours. Returns the
    cells' start offsets into ``order`` (points sorted by cell), the grid's origin, the cell
    width and the grid's dimensions."""
    # read-only as the meshes' vertices are: one compiled signature
    lo, hi = column_bounds(read_only(cloud), np.ones(len(cloud), dtype=np.bool_))
    extent = hi - lo
    # A little wider than the limit: rounding in the division cannot push a neighbour two
    # cells away.
    cell = limit * 1.001
    # A surface fills few of the cells: about as many cells as points keeps the table small
    # (wider cells only add candidates, never lose one).
    while np.prod(np.floor(extent / cell) + 1) > max(4 * len(cloud), 4096):
        cell *= 1.25
    dims = (np.floor(extent / cell) + 1).astype(np.int64)
    start, order = bucket_points(cloud, lo, cell, dims)  # every point is >= lo
    return start, order, lo, cell, dims


@numba.njit(**CHECKED)
def _near(
    x: float,
    y: float,
    z: float,
    cloud: np.ndarray,
    start: np.ndarray,
    order: np.ndarray,
    lo: np.ndarray,
    cell: float,
    dims: np.ndarray,
    limit2: float,
) -> bool:
    """Whether a point of ``cloud`` lies at squared distance < ``limit2`` from (x, y, z): the
    test of scipy's ``cKDTree.query(..., distance_upper_bound=limit)`` (squares summed x, y, z)."""
    fx = (x - lo[0]) / cell
    fy = (y - lo[1]) / cell
    fz = (z - lo[2]) / cell
    # Beyond a cell outside the grid nothing is near (the negated test also rejects NaN).
    if not (-2.0 < fx < dims[0] + 1.0 and -2.0 < fy < dims[1] + 1.0 and -2.0 < fz < dims[2] + 1.0):
        return False
    cx = int(math.floor(fx))
    cy = int(math.floor(fy))
    cz = int(math.floor(fz))
    k0 = max(cz - 1, 0)
    k1 = min(cz + 1, dims[2] - 1)
    if k0 > k1:
        return False
    # The query's own column of cells first: a point that has a near vertex mostly has it there.
    for a in range(3):
        i = cx + (a + 1) % 3 - 1  # cx, cx + 1, cx - 1
        if i < 0 or i >= dims[0]:
            continue
        for b in range(3):
            j = cy + (b + 1) % 3 - 1
            if j < 0 or j >= dims[1]:
                continue
            base = (i * dims[1] + j) * dims[2]
            for s in range(start[base + k0], start[base + k1 + 1]):
                p = order[s]
                dx = x - cloud[p, 0]
                dy = y - cloud[p, 1]
                dz = z - cloud[p, 2]
                if dx * dx + dy * dy + dz * dz < limit2:
                    return True
    return False


@numba.njit(**CHECKED)
def _symmetric(
    pts: np.ndarray,
    cloud: np.ndarray,
    start: np.ndarray,
    order: np.ndarray,
    lo: np.ndarray,
    cell: float,
    dims: np.ndarray,
    limit2: float,
    perms: np.ndarray,
    signs: np.ndarray,
    allowed: int,
) -> np.ndarray:
    """Per element (``perms``, ``signs`` (E, 3)): do at most ``allowed`` of the images of
    ``pts`` miss the cloud? Stops counting an element as soon as it has failed."""
    out = np.zeros(perms.shape[0], dtype=np.bool_)
    for e in range(perms.shape[0]):
        misses = 0
        for i in range(pts.shape[0]):
            x = pts[i, perms[e, 0]] * signs[e, 0]
            y = pts[i, perms[e, 1]] * signs[e, 1]
            z = pts[i, perms[e, 2]] * signs[e, 2]
            if not _near(x, y, z, cloud, start, order, lo, cell, dims, limit2):
                misses += 1
                if misses > allowed:
                    break
        out[e] = misses <= allowed
    return out


def symmetry_metrics(mesh: Mesh) -> dict[str, Any]:
    """``symmetry`` (group order), ``symmetry_permutations``, ``symmetry_mirrors``,
    ``symmetries`` (labels) of :func:`mesh_symmetries`."""
    found = mesh_symmetries(mesh)
    perms = {"".join(c for c in label if c != "-") for label in found}
    mirrors = {"-xyz", "x-yz", "xy-z"} & set(found)
    return {
        "symmetry": len(found),
        "symmetry_permutations": len(perms),
        "symmetry_mirrors": len(mirrors),
        "symmetries": " ".join(found),
    }


def solidity(mesh: Mesh, volume: float | None) -> float | None:
    """Enclosed volume / convex hull volume (None when the mesh encloses no volume)."""
    if volume is None or mesh.n_faces == 0:
        return None
    used = mesh.vertices[used_vertices(mesh)]
    try:
        hull = ConvexHull(used).volume
    except (QhullError, ValueError):  # flat or degenerate
        return None
    return float(abs(volume) / hull) if hull > 0 else None


def quality_metrics(mesh: Mesh, metrics: dict[str, Any]) -> dict[str, Any]:
    """``free_standing``, ``solidity`` and the symmetry metrics of an accepted mesh, given its
    other metrics (``box_fraction``, ``volume``; ``solidity`` when already measured)."""
    measured = (
        metrics["solidity"] if "solidity" in metrics else solidity(mesh, metrics.get("volume"))
    )
    out: dict[str, Any] = {
        "free_standing": bool(metrics.get("box_fraction", 1.0) == 0.0),
        "solidity": measured,
    }
    out.update(symmetry_metrics(mesh))
    return out
