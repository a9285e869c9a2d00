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
from typing import Any

import numpy as np

from surfgen.generator.mesh import Mesh, face_areas

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
    tri = mesh.vertices[mesh.faces]
    areas = face_areas(mesh)
    total = float(areas.sum())
    centroid = (areas[:, None] * tri.mean(axis=1)).sum(axis=0) / total
    rng = np.random.default_rng(SYMMETRY_SEED)
    faces = np.minimum(
        np.searchsorted(np.cumsum(areas), rng.random(n) * total, side="right"), len(areas) - 1
    )
    r1, r2 = rng.random((2, n))
    s = np.sqrt(r1)
    a, b, c = tri[faces, 0], tri[faces, 1], tri[faces, 2]
    pts = (1 - s)[:, None] * a + (s * (1 - r2))[:, None] * b + (s * r2)[:, None] * c
    return pts, centroid


def mesh_symmetries(
    mesh: Mesh, tolerance: float = SYMMETRY_TOLERANCE, share: float = SYMMETRY_SHARE
) -> list[str]:
    """Labels of the signed axis permutations (about the area centroid) that map the mesh onto
    itself: a surface point's image must lie within ``tolerance`` mean edge lengths of a vertex,
    for ``share`` of the points. The identity ``xyz`` is always first."""
    from scipy.spatial import cKDTree

    if mesh.n_faces == 0:
        return []
    pts, centroid = _surface_points(mesh, SYMMETRY_POINTS)
    used = np.unique(mesh.faces)
    tree = cKDTree(mesh.vertices[used] - centroid)
    v = mesh.vertices
    f = mesh.faces
    edge = float(np.linalg.norm(v[f[:, 1]] - v[f[:, 0]], axis=1).mean())
    limit = tolerance * max(edge, 1e-12)
    pts = pts - centroid
    found = []
    allowed = int((1.0 - share) * len(pts))  # misses allowed
    for perm, signs in SIGNED_PERMUTATIONS:
        image = pts[:, perm] * np.array(signs, dtype=np.float64)
        # Most elements fail on the first points: test those first (same answer, less time).
        dist, _ = tree.query(image[:128], k=1, distance_upper_bound=limit)
        misses = int(np.count_nonzero(~np.isfinite(dist)))
        if misses > allowed:
            continue
        dist, _ = tree.query(image[128:], k=1, distance_upper_bound=limit)
        if misses + int(np.count_nonzero(~np.isfinite(dist))) <= allowed:
            found.append(element_label(perm, signs))
    return found


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
    from scipy.spatial import ConvexHull, QhullError

    if volume is None or mesh.n_faces == 0:
        return None
    used = mesh.vertices[np.unique(mesh.faces)]
    try:
        hull = ConvexHull(used).volume
    except (QhullError, ValueError):  # flat or degenerate
        return None
    return float(abs(volume) / hull) if hull > 0 else None


def quality_metrics(mesh: Mesh, metrics: dict[str, Any]) -> dict[str, Any]:
    """``free_standing``, ``solidity`` and the symmetry metrics of an accepted mesh, given its
    other metrics (``box_fraction``, ``volume``)."""
    out: dict[str, Any] = {
        "free_standing": bool(metrics.get("box_fraction", 1.0) == 0.0),
        "solidity": solidity(mesh, metrics.get("volume")),
    }
    out.update(symmetry_metrics(mesh))
    return out
