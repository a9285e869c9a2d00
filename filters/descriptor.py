"""Shape descriptors for near-duplicate detection: D2 and D1 shape distributions.

A descriptor is a fixed-length float64 vector computed from the surface alone, invariant to
translation and uniform scale, and deterministic for a given mesh (the sampling uses a fixed
seed). It concatenates two histograms, each summing to 1:

- D2 (Osada et al. 2002): distances between random pairs of points on the surface, divided by
  their mean, ``D2_BINS`` bins over ``[0, RANGE]``;
- D1: distances from the surface's area centroid to random surface points, divided by their
  mean, ``D1_BINS`` bins over ``[0, RANGE]``.

Points are drawn uniformly by area (faces chosen by area, then uniform barycentrics), so two
meshes of one surface at different grid resolutions get close descriptors. The distance
(:func:`descriptor_distance`) is the mean absolute difference of the cumulative histograms,
averaged over the two parts: 0 for equal shapes, at most 1; it is a 1-D earth mover's distance
in units of ``RANGE`` and so does not jump when mass moves to a neighbouring bin.

Typical values (grid 32-64): a shape and its translation 0, the same shape on a finer grid
0.002-0.01, distinct random shapes 0.02-0.3. :data:`DEFAULT_THRESHOLD` sits between.
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
RANGE = 3.0  # histograms cover [0, RANGE] mean distances; the rare longer ones go in the last bin
POINTS = 4096
PAIRS = 65536
SEED = 20240613  # fixed: the descriptor is a function of the mesh alone
DEFAULT_THRESHOLD = 0.012
SIZE = D2_BINS + D1_BINS


def descriptor(mesh: Mesh) -> np.ndarray:
    """The D2+D1 descriptor of ``mesh``: float64 ``(SIZE,)``, two histograms each summing to 1.

    Deterministic given the mesh (same vertices and faces, same vector); invariant to
    translation and uniform scale. Raises :class:`MeshError` if the mesh has no area.
    """
    tri = mesh.vertices[mesh.faces]  # (F, 3, 3)
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    total = float(areas.sum())
    if mesh.n_faces == 0 or not np.isfinite(total) or total <= 0.0:
        raise MeshError("cannot describe a mesh without area")
    rng = np.random.default_rng(SEED)
    points = _surface_points(tri, areas, total, rng)
    centroid = (areas[:, None] * tri.mean(axis=1)).sum(axis=0) / total
    i, j = rng.integers(0, POINTS, size=(2, PAIRS))
    d2 = np.linalg.norm(points[i] - points[j], axis=1)
    d1 = np.linalg.norm(points - centroid, axis=1)
    return np.concatenate([_histogram(d2, D2_BINS), _histogram(d1, D1_BINS)])


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
    parts = []
    for lo, hi in ((0, D2_BINS), (D2_BINS, SIZE)):
        cdf_a = np.cumsum(a[lo:hi])
        cdf_o = np.cumsum(others[:, lo:hi], axis=1)
        parts.append(np.abs(cdf_o - cdf_a).mean(axis=1))
    return 0.5 * (parts[0] + parts[1])


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
