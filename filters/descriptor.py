"""Shape descriptors for near-duplicate detection: D2, D1 and normal-direction distributions.

A descriptor is a fixed-length float64 vector computed from the surface alone, invariant to
translation and uniform scale, and deterministic for a given mesh (the sampling uses a fixed
seed). It concatenates five histograms, each summing to 1:

- D2 (Osada et al. 2002): distances between random pairs of points on the surface, divided by
  their mean, ``D2_BINS`` bins over ``[0, RANGE]``;
- D1: distances from the surface's area centroid to random surface points, divided by their
  mean, ``D1_BINS`` bins over ``[0, RANGE]``;
- for each axis x, y, z: the area-weighted distribution of ``|n_k|``, the normal's component
  along that axis, ``NORMAL_BINS`` bins over ``[0, 1]`` (exact, over all faces).

D2 and D1 alone hardly tell apart the many random shapes that fill their box (their caps
dominate); the normal distributions do, which is why they are in. Shapes are compared in the
frame of their formula, so a shape turned 90 degrees is *not* a duplicate of itself.

Points are drawn uniformly by area (faces chosen by area, then uniform barycentrics), so two
meshes of one surface at different grid resolutions get close descriptors. The distance
(:func:`descriptor_distance`) is the mean absolute difference of cumulative histograms (a 1-D
earth mover's distance, which does not jump when mass moves to a neighbouring bin), averaged
with weight 1/3 for D2, 1/3 for D1 and 1/9 per normal axis: 0 for equal distributions, at most 1.

Measured on random catalogue shapes (grid 32 against 48, or the box shifted by 0.02): the same
shape 0.001-0.013 (90% below 0.010), distinct shapes 0.012-0.3 (99% above 0.02), so
:data:`DEFAULT_THRESHOLD` = 0.012. Shapes made of staircases (stair constituents) change more
between grids than that and are then not caught.
"""

from __future__ import annotations

import json
import logging

import numpy as np

from surfgen.generator.errors import MeshError
from surfgen.generator.mesh import Mesh

log = logging.getLogger(__name__)

DESCRIPTOR_VERSION = 1
D2_BINS = 64
D1_BINS = 32
NORMAL_BINS = 8
RANGE = 3.0  # histograms cover [0, RANGE] mean distances; the rare longer ones go in the last bin
POINTS = 4096
PAIRS = 65536
SEED = 20240613  # fixed: the descriptor is a function of the mesh alone
DEFAULT_THRESHOLD = 0.012
SIZE = D2_BINS + D1_BINS + 3 * NORMAL_BINS
# (start, stop, weight) of each histogram in the vector; the weights sum to 1.
_BLOCKS = (
    (0, D2_BINS, 1 / 3),
    (D2_BINS, D2_BINS + D1_BINS, 1 / 3),
    *(
        (D2_BINS + D1_BINS + k * NORMAL_BINS, D2_BINS + D1_BINS + (k + 1) * NORMAL_BINS, 1 / 9)
        for k in range(3)
    ),
)


def descriptor(mesh: Mesh) -> np.ndarray:
    """The descriptor of ``mesh``: float64 ``(SIZE,)``, five histograms each summing to 1.

    Deterministic given the mesh (same vertices and faces, same vector); invariant to
    translation and uniform scale. Raises :class:`MeshError` if the mesh has no area.
    """
    tri = mesh.vertices[mesh.faces]  # (F, 3, 3)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    doubled = np.linalg.norm(cross, axis=1)
    areas = 0.5 * doubled
    total = float(areas.sum())
    if mesh.n_faces == 0 or not np.isfinite(total) or total <= 0.0:
        raise MeshError("cannot describe a mesh without area")
    rng = np.random.default_rng(SEED)
    points = _surface_points(tri, areas, total, rng)
    centroid = (areas[:, None] * tri.mean(axis=1)).sum(axis=0) / total
    i, j = rng.integers(0, POINTS, size=(2, PAIRS))
    d2 = np.linalg.norm(points[i] - points[j], axis=1)
    d1 = np.linalg.norm(points - centroid, axis=1)
    normals = np.abs(cross) / np.maximum(doubled, np.finfo(np.float64).tiny)[:, None]
    parts = [_histogram(d2, D2_BINS), _histogram(d1, D1_BINS)]
    for k in range(3):
        counts, _ = np.histogram(normals[:, k], bins=NORMAL_BINS, range=(0.0, 1.0), weights=areas)
        parts.append(counts / total)
    return np.concatenate(parts)


def _surface_points(
    tri: np.ndarray, areas: np.ndarray, total: float, rng: np.random.Generator
) -> np.ndarray:
    """``POINTS`` points uniform by area on the triangles ``tri`` (F, 3, 3): ``(POINTS, 3)``."""
    cumulative = np.cumsum(areas)
    faces = np.searchsorted(cumulative, rng.random(POINTS) * total, side="right")
    faces = np.minimum(faces, len(areas) - 1)
    r1, r2 = rng.random((2, POINTS))
    s = np.sqrt(r1)
    a, b, c = tri[faces, 0], tri[faces, 1], tri[faces, 2]
    return (1 - s)[:, None] * a + (s * (1 - r2))[:, None] * b + (s * r2)[:, None] * c


def _histogram(distances: np.ndarray, bins: int) -> np.ndarray:
    mean = float(distances.mean())
    scaled = distances / mean if mean > 0 else np.zeros_like(distances)
    counts, _ = np.histogram(np.minimum(scaled, RANGE), bins=bins, range=(0.0, RANGE))
    return counts / counts.sum()


def descriptor_distance(a: np.ndarray, b: np.ndarray) -> float:
    """How far apart two descriptors are, in [0, 1] (0: the same shape distribution)."""
    return float(descriptor_distances(a, np.asarray(b)[None, :])[0])


def descriptor_distances(a: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Distances from descriptor ``a`` ``(SIZE,)`` to each row of ``others`` ``(K, SIZE)``: ``(K,)``.

    Raises :class:`ValueError` if the lengths differ (descriptors of another version).
    """
    a = np.asarray(a, dtype=np.float64)
    others = np.atleast_2d(np.asarray(others, dtype=np.float64))
    if a.shape != (SIZE,) or others.ndim != 2 or others.shape[1] != SIZE:
        raise ValueError(f"descriptors must have {SIZE} values, got {a.shape} and {others.shape}")
    total = np.zeros(others.shape[0])
    for lo, hi, weight in _BLOCKS:
        cdf_a = np.cumsum(a[lo:hi])
        cdf_o = np.cumsum(others[:, lo:hi], axis=1)
        total += weight * np.abs(cdf_o - cdf_a).mean(axis=1)
    return total


def is_near_duplicate(a: np.ndarray, b: np.ndarray, threshold: float = DEFAULT_THRESHOLD) -> bool:
    """Whether descriptors ``a`` and ``b`` are closer than ``threshold``."""
    return descriptor_distance(a, b) < threshold


def descriptor_to_text(values: np.ndarray) -> str:
    """Compact JSON for the catalogue's ``descriptor`` column (version and rounded values)."""
    rounded = [round(float(v), 6) for v in np.asarray(values).ravel()]
    return json.dumps({"v": DESCRIPTOR_VERSION, "d": rounded}, separators=(",", ":"))


def descriptor_from_text(text: str | None) -> np.ndarray | None:
    """The descriptor stored by :func:`descriptor_to_text`, or None if absent or of another
    version or size (then it must be computed again)."""
    if not text:
        return None
    try:
        data = json.loads(text)
    except json.JSONDecodeError:
        log.warning("ignoring an unreadable stored descriptor")
        return None
    if not isinstance(data, dict) or data.get("v") != DESCRIPTOR_VERSION:
        return None
    values = np.asarray(data.get("d", []), dtype=np.float64)
    return values if values.shape == (SIZE,) else None
