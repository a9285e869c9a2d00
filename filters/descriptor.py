"""Shape descriptors for near-duplicate detection: form, placement and relief.

A descriptor is a fixed-length float64 vector computed from the surface alone, invariant to
translation and uniform scale, and deterministic for a given mesh (the sampling uses a fixed
seed). Shapes are compared in the frame of their formula, so a shape turned 90 degrees is *not*
a duplicate of itself. It has three channels, each compared on its own:

- **form** (``FORM_SIZE`` values): five histograms, each summing to 1 — D2 (Osada et al. 2002:
  distances between random pairs of surface points over their mean, ``D2_BINS`` bins over
  ``[0, RANGE]``), D1 (distances from the area centroid, ``D1_BINS`` bins) and, per axis, the
  area-weighted distribution of ``|n_k|`` (``NORMAL_BINS`` bins). Compared by the mean absolute
  difference of cumulative histograms (a 1-D earth mover's distance) weighted 1/3, 1/3, 1/9 x 3.
  This was the whole descriptor of version 1; it tells box-filling shapes apart but barely sees
  *where* a body is carved or *whether* it is;
- **placement** (``PLACE_SIZE`` values): the distance from each node of a ``PLACE_GRID``³ lattice
  over ``[-PLACE_EXTENT, PLACE_EXTENT]``³ to the nearest surface point, in units of the surface's
  RMS radius about its centroid, clipped at ``PLACE_CLIP`` (only the region near the surface
  speaks). Compared by the mean absolute difference: where the two surfaces are, node by node —
  the same envelope carved in two places differs here;
- **relief** (``RELIEF_BINS`` values): the distribution over the surface of how much the normal
  turns within the cells of a lattice of ``RELIEF_CELL`` RMS radii (``sqrt(1 - |mean normal|)``,
  the mean weighted by area, over every face), a histogram by area summing to 1. Compared by the
  1-D earth mover's distance: a smooth body, a carved one and a rough one differ here even when
  their outlines agree.

:func:`descriptor_distances` divides each channel's distance by its own scale
(:data:`CHANNEL_SCALES`) and returns the **largest**: two shapes are near duplicates
(distance < :data:`DEFAULT_THRESHOLD` = 1) only when they are close in every respect.

The scales were calibrated on the 200 accepted shapes of ``surfgen sample --n 200 --seed 7``
(default mix): each shape's catalogue mesh (64³) against the same formula meshed on a 48³ grid,
points drawn with another seed; a scale is the 95th percentile of those same-shape distances, so
about 88 % of the pairs pass all three (the ones that do not carve detail a 48³ grid loses).
Pairs under 1 in the same catalogue were looked at: lattices of one pattern and period, two
rounded boxes with one groove, rough balls of one envelope — to the eye the same shape.
"""

from __future__ import annotations

import base64
import functools
import json
import logging
import math

import numba
import numpy as np
from scipy.spatial import cKDTree

from surfgen.filters.geometry import surface_samples, weighted_centres
from surfgen.generator.errors import MeshError
from surfgen.generator.jit.options import CHECKED
from surfgen.generator.mesh.mesh import Mesh, face_cross

log = logging.getLogger(__name__)

DESCRIPTOR_VERSION = 2
D2_BINS = 64
D1_BINS = 32
NORMAL_BINS = 8
RANGE = 3.0  # histograms cover [0, RANGE] mean distances; the rare longer ones go in the last bin
POINTS = 4096
PAIRS = 65536
SEED = 20240613  # fixed: the descriptor is a function of the mesh alone
FORM_SIZE = D2_BINS + D1_BINS + 3 * NORMAL_BINS
PLACE_GRID = 12
PLACE_EXTENT = 1.8  # RMS radii: a cube's corners are at 1.73
PLACE_CLIP = 0.8
PLACE_SIZE = PLACE_GRID**3
RELIEF_CELL = 0.2  # RMS radii
RELIEF_BINS = 16
SIZE = FORM_SIZE + PLACE_SIZE + RELIEF_BINS
# Each channel's distance is divided by its scale (docs/guide/curation.md, Near duplicates: calibration), then the largest counts.
CHANNEL_SCALES = {"form": 0.0151, "placement": 0.0240, "relief": 0.1162}
DEFAULT_THRESHOLD = 1.0
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
    """The descriptor of ``mesh``: float64 ``(SIZE,)`` — form, placement, relief (module doc).

    Deterministic given the mesh (same vertices and faces, same vector); invariant to
    translation and uniform scale. Raises :class:`MeshError` if the mesh has no area.
    """
    v = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    f = np.ascontiguousarray(mesh.faces)
    # One pass over the faces (numba, module geometry's arithmetic: the numbers numpy gave).
    cross, doubled = _cross_products(v, f)
    areas = 0.5 * doubled
    total = float(areas.sum())
    if mesh.n_faces == 0 or not np.isfinite(total) or total <= 0.0:
        raise MeshError("cannot describe a mesh without area")
    rng = np.random.default_rng(SEED)
    points = surface_samples(v, f, areas, total, rng, POINTS)[0]
    centroid = weighted_centres(v, f, areas).sum(axis=0) / total
    i, j = rng.integers(0, POINTS, size=(2, PAIRS))
    d2 = _pair_distances(points, i, j)
    d1 = np.linalg.norm(points - centroid, axis=1)
    parts = [_histogram(d2, D2_BINS), _histogram(d1, D1_BINS)]
    scale = np.maximum(doubled, np.finfo(np.float64).tiny)
    for k in range(3):
        counts, _ = np.histogram(
            np.abs(cross[:, k] / scale), bins=NORMAL_BINS, range=(0.0, 1.0), weights=areas
        )
        parts.append(counts / total)
    radius = float(np.sqrt(np.mean(d1**2)))
    if not radius > 0:
        raise MeshError("cannot describe a mesh without extent")
    parts.append(_placement(cKDTree((points - centroid) / radius)))
    centres = _centres(v, f, centroid, radius)
    parts.append(_relief(centres, 0.5 * cross, areas))
    return np.concatenate(parts)


@numba.njit(**CHECKED)
def _cross_products(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.cross(v1 - v0, v2 - v0)`` per face ``(F, 3)`` and its norm ``(F,)``."""
    cross = np.empty((f.shape[0], 3))
    norm = np.empty(f.shape[0])
    for t in range(f.shape[0]):
        x, y, z = face_cross(v, f[t, 0], f[t, 1], f[t, 2])
        cross[t, 0] = x
        cross[t, 1] = y
        cross[t, 2] = z
        norm[t] = math.sqrt(x * x + y * y + z * z)
    return cross, norm


@numba.njit(**CHECKED)
def _centres(v: np.ndarray, f: np.ndarray, centroid: np.ndarray, radius: float) -> np.ndarray:
    """``(v[f].mean(axis=1) - centroid) / radius``: face centres in RMS radii."""
    out = np.empty((f.shape[0], 3))
    for t in range(f.shape[0]):
        for k in range(3):
            mean = (v[f[t, 0], k] + v[f[t, 1], k] + v[f[t, 2], k]) / 3.0
            out[t, k] = (mean - centroid[k]) / radius
    return out


@numba.njit(**CHECKED)
def _pair_distances(points: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """``np.linalg.norm(points[i] - points[j], axis=1)`` without the two gathered copies."""
    out = np.empty(i.shape[0])
    for n in range(i.shape[0]):
        x = points[i[n], 0] - points[j[n], 0]
        y = points[i[n], 1] - points[j[n], 1]
        z = points[i[n], 2] - points[j[n], 2]
        out[n] = math.sqrt(x * x + y * y + z * z)
    return out


def _placement(tree: cKDTree) -> np.ndarray:
    """Distances from the nodes of the placement lattice to the nearest point, clipped and
    rounded to 8 bits (what the catalogue stores, so a stored descriptor equals a fresh one)."""
    # Nodes farther than the clip come back as inf (then clipped): the same values, and the
    # search around empty space stops early.
    dist, _ = tree.query(_placement_nodes(), distance_upper_bound=PLACE_CLIP)
    return _quantise(np.minimum(dist, PLACE_CLIP))


@functools.cache
def _placement_nodes() -> np.ndarray:
    axis = np.linspace(-PLACE_EXTENT, PLACE_EXTENT, PLACE_GRID)
    return np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)


def _quantise(place: np.ndarray) -> np.ndarray:
    return np.rint(np.clip(place, 0.0, PLACE_CLIP) / PLACE_CLIP * 255.0) * (PLACE_CLIP / 255.0)


def _relief(centres: np.ndarray, area_normals: np.ndarray, areas: np.ndarray) -> np.ndarray:
    """Histogram, weighted by area, of how far the normal turns within the cells of a
    ``RELIEF_CELL`` lattice: ``sqrt(1 - |sum of area * normal| / area)`` per cell (0 where the
    surface is flat at that scale, larger where it is curved, carved or rough). Faces are
    assigned by their centres (``centres`` in RMS radii about the centroid)."""
    cells, dims = _lattice_cells(centres, RELIEF_CELL)
    total, summed = _cell_sums(cells, dims, area_normals, areas)
    keep = total > 0
    spread = 1.0 - np.linalg.norm(summed[keep], axis=1) / total[keep]
    counts, _ = np.histogram(
        np.sqrt(np.clip(spread, 0.0, 1.0)), bins=RELIEF_BINS, range=(0, 1), weights=total[keep]
    )
    return counts / counts.sum()


@numba.njit(**CHECKED)
def _lattice_cells(centres: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """``floor(centres / width)`` as int64 ``(F, 3)``, shifted so the lowest cell is 0 on each
    axis, and the lattice's dimensions ``(3,)``."""
    cells = np.empty(centres.shape, dtype=np.int64)
    lo = np.full(3, np.iinfo(np.int64).max)
    hi = np.full(3, np.iinfo(np.int64).min)
    for t in range(centres.shape[0]):
        for k in range(3):
            c = np.int64(math.floor(centres[t, k] / width))
            cells[t, k] = c
            lo[k] = min(lo[k], c)
            hi[k] = max(hi[k], c)
    for t in range(centres.shape[0]):
        for k in range(3):
            cells[t, k] -= lo[k]
    return cells, hi - lo + 1


@numba.njit(**CHECKED)
def _cell_sums(
    cells: np.ndarray, dims: np.ndarray, area_normals: np.ndarray, areas: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per occupied cell, in the order of its flat index (as ``np.unique`` numbers them), the
    summed area ``(C,)`` and area normal ``(C, 3)``, added face by face as ``np.bincount``
    does. A dense table of the lattice replaces the sort."""
    size = dims[0] * dims[1] * dims[2]
    n = cells.shape[0]
    flat = np.empty(n, dtype=np.int64)
    rank = np.zeros(size, dtype=np.int64)
    for t in range(n):
        flat[t] = (cells[t, 0] * dims[1] + cells[t, 1]) * dims[2] + cells[t, 2]
        rank[flat[t]] = 1
    count = 0
    for c in range(size):
        if rank[c]:
            rank[c] = count
            count += 1
    total = np.zeros(count)
    summed = np.zeros((count, 3))
    for t in range(n):
        c = rank[flat[t]]
        total[c] += areas[t]
    for k in range(3):  # bincount per component, as the numpy version did
        for t in range(n):
            summed[rank[flat[t]], k] += area_normals[t, k]
    return total, summed


def _histogram(distances: np.ndarray, bins: int) -> np.ndarray:
    mean = float(distances.mean())
    scaled = distances / mean if mean > 0 else np.zeros_like(distances)
    counts, _ = np.histogram(np.minimum(scaled, RANGE), bins=bins, range=(0.0, RANGE))
    return counts / counts.sum()


def descriptor_distance(a: np.ndarray, b: np.ndarray) -> float:
    """How far apart two descriptors are, in units of the near-duplicate threshold (module doc)."""
    return float(descriptor_distances(a, np.asarray(b)[None, :])[0])


def channel_distances(a: np.ndarray, others: np.ndarray) -> dict[str, np.ndarray]:
    """Each channel's raw distance from ``a`` ``(SIZE,)`` to each row of ``others`` ``(K, SIZE)``.

    Raises :class:`ValueError` if the lengths differ (descriptors of another version).
    """
    a = np.asarray(a, dtype=np.float64)
    others = np.atleast_2d(np.asarray(others, dtype=np.float64))
    if a.shape != (SIZE,) or others.ndim != 2 or others.shape[1] != SIZE:
        raise ValueError(f"descriptors must have {SIZE} values, got {a.shape} and {others.shape}")
    hist_a, codes_a = _split(a[None, :])
    hist, codes = _split(others)
    return _channels(hist_a[0], codes_a[0], hist, codes)


def descriptor_distances(a: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Distances from descriptor ``a`` to each row of ``others``: the largest of the channel
    distances, each divided by its scale (:data:`CHANNEL_SCALES`); below 1: near duplicates."""
    return _scaled(channel_distances(a, others))


def nearest_distances(rows: np.ndarray) -> np.ndarray:
    """Each row's distance (:func:`descriptor_distances`, the same bits) to its nearest other
    row of ``rows`` ``(N, SIZE)``; ``inf`` when there is no other. The rows are split into
    cumulative histograms and codes once, not once per row: a report's 1000 shapes take a
    second, not twenty. Raises :class:`ValueError` for rows of another length."""
    rows = np.asarray(rows, dtype=np.float64)
    if rows.ndim != 2 or rows.shape[1] != SIZE:
        raise ValueError(f"descriptors must have {SIZE} values, got {rows.shape}")
    hist, codes = _split(rows)
    out = np.full(len(rows), np.inf)
    for i in range(len(rows)):
        dist = _scaled(_channels(hist[i], codes[i], hist, codes))
        dist[i] = np.inf
        out[i] = dist.min()
    return out


class DescriptorSet:
    """A growing set of keyed descriptors with a fast nearest-neighbour query: cumulative
    histograms are computed once per descriptor, the placement is kept as its 8-bit codes, rows
    grow by doubling. The sampler checks every accepted shape against all the ones before it.
    Same distances as :func:`descriptor_distances`, bit for bit."""

    def __init__(self) -> None:
        self.keys: list[str] = []
        self._hist = np.zeros((0, FORM_SIZE + RELIEF_BINS))
        self._codes = np.zeros((0, PLACE_SIZE), dtype=np.int16)
        self._sums = np.zeros((0, _N_SUMS))  # per row: _block_sums (for within's bounds)

    def __len__(self) -> int:
        return len(self.keys)

    def add(self, key: str, values: np.ndarray) -> None:
        n = len(self.keys)
        if n == len(self._hist):
            size = max(64, 2 * n)
            self._hist = np.concatenate([self._hist, np.zeros((size - n, self._hist.shape[1]))])
            self._codes = np.concatenate(
                [self._codes, np.zeros((size - n, PLACE_SIZE), dtype=np.int16)]
            )
            self._sums = np.concatenate([self._sums, np.zeros((size - n, _N_SUMS))])
        hist, codes = _split(np.asarray(values, dtype=np.float64)[None, :])
        self._hist[n], self._codes[n] = hist[0], codes[0]
        self._sums[n] = _block_sums(hist, codes)[0]
        self.keys.append(key)

    def nearest(self, values: np.ndarray) -> tuple[str | None, float]:
        """The key of the closest descriptor (the first one on a tie) and its distance, or
        ``(None, inf)`` for an empty set."""
        if not self.keys:
            return None, float("inf")
        hist, codes = _split(np.asarray(values, dtype=np.float64)[None, :])
        n = len(self.keys)
        dist = _scaled(_channels(hist[0], codes[0], self._hist[:n], self._codes[:n]))
        j = int(np.argmin(dist))
        return self.keys[j], float(dist[j])

    def within(self, values: np.ndarray, threshold: float) -> tuple[str | None, float]:
        """:meth:`nearest` when its distance is below ``threshold``, else ``(None, inf)``:
        the same key and distance, bit for bit, with only the rows that may lie within
        ``threshold`` measured. A channel's distance is a mean of ``|a - b|`` over a block of
        bins, at least ``|sum a - sum b|`` over the block's size (the placement's in integer
        codes, exactly), so a row whose bound reaches the threshold cannot be within it; the
        sampler's duplicate check then measures about 2 % of the catalogue's rows."""
        n = len(self.keys)
        if n == 0:
            return None, float("inf")
        hist, codes = _split(np.asarray(values, dtype=np.float64)[None, :])
        bound = _bounds(_block_sums(hist, codes)[0], self._sums[:n])
        # kept: bounds below the threshold (a margin far above the sums' rounding), and NaN
        # (a NaN distance wins nearest's argmin: it must be measured here too)
        rows = np.flatnonzero(~(bound > threshold + 1e-9 * max(1.0, abs(threshold))))
        if rows.size == 0:
            return None, float("inf")
        dist = _scaled(_channels(hist[0], codes[0], self._hist[rows], self._codes[rows]))
        j = int(np.argmin(dist))
        if not dist[j] < threshold:
            return None, float("inf")
        return self.keys[rows[j]], float(dist[j])


def _split(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows as (cumulative histograms: form blocks then relief; placement codes as int16)."""
    hist = np.concatenate([rows[:, :FORM_SIZE], rows[:, FORM_SIZE + PLACE_SIZE :]], axis=1)
    for lo, hi in (*((lo, hi) for lo, hi, _ in _BLOCKS), (FORM_SIZE, FORM_SIZE + RELIEF_BINS)):
        hist[:, lo:hi] = np.cumsum(hist[:, lo:hi], axis=1)
    codes = np.rint(rows[:, FORM_SIZE : FORM_SIZE + PLACE_SIZE] * (255.0 / PLACE_CLIP))
    return hist, codes.astype(np.int16)


# What DescriptorSet.within bounds a row's distance by: the sums of each form block, of the
# relief and of the placement's codes.
_N_SUMS = len(_BLOCKS) + 2


def _block_sums(hist: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """Per row of :func:`_split`'s output, ``(N, _N_SUMS)``: each form block's sum, the
    relief's, the placement codes' (an integer, exact in float64)."""
    out = np.empty((hist.shape[0], _N_SUMS))
    for b, (lo, hi, _) in enumerate(_BLOCKS):
        out[:, b] = hist[:, lo:hi].sum(axis=1)
    out[:, -2] = hist[:, FORM_SIZE:].sum(axis=1)
    out[:, -1] = codes.sum(axis=1, dtype=np.int64)
    return out


def _bounds(sums_a: np.ndarray, sums: np.ndarray) -> np.ndarray:
    """A lower bound of :func:`_scaled`'s distance from the row of ``sums_a`` to each row of
    ``sums`` (:func:`_block_sums`): a mean of ``|a - b|`` is at least ``|mean a - mean b|``."""
    gap = np.abs(sums - sums_a)
    form = np.zeros(sums.shape[0])
    for b, (lo, hi, weight) in enumerate(_BLOCKS):
        form += weight * gap[:, b] / (hi - lo)
    relief = gap[:, -2] / RELIEF_BINS
    placement = gap[:, -1] * (PLACE_CLIP / 255.0 / PLACE_SIZE)
    return _scaled({"form": form, "placement": placement, "relief": relief})


def _channels(
    hist_a: np.ndarray, codes_a: np.ndarray, hist: np.ndarray, codes: np.ndarray
) -> dict[str, np.ndarray]:
    form = np.zeros(hist.shape[0])
    for lo, hi, weight in _BLOCKS:
        form += weight * np.abs(hist[:, lo:hi] - hist_a[lo:hi]).mean(axis=1)
    # integer sums of code gaps: exact, and a sixth of the memory traffic of float64
    gaps = np.abs(codes - codes_a).sum(axis=1, dtype=np.int64)
    placement = gaps * (PLACE_CLIP / 255.0 / PLACE_SIZE)
    relief = np.abs(hist[:, FORM_SIZE:] - hist_a[FORM_SIZE:]).mean(axis=1)
    return {"form": form, "placement": placement, "relief": relief}


def _scaled(channels: dict[str, np.ndarray]) -> np.ndarray:
    return np.maximum.reduce([channels[k] / CHANNEL_SCALES[k] for k in CHANNEL_SCALES])


def is_near_duplicate(a: np.ndarray, b: np.ndarray, threshold: float = DEFAULT_THRESHOLD) -> bool:
    """Whether descriptors ``a`` and ``b`` are closer than ``threshold``."""
    return descriptor_distance(a, b) < threshold


def descriptor_to_text(values: np.ndarray) -> str:
    """Compact JSON for the catalogue's ``descriptor`` column: the version, the histograms
    rounded to 6 decimals and the placement as 8-bit codes in base64 (about 3.5 KB)."""
    values = np.asarray(values, dtype=np.float64).ravel()
    hist = np.concatenate([values[:FORM_SIZE], values[FORM_SIZE + PLACE_SIZE :]])
    codes = np.rint(values[FORM_SIZE : FORM_SIZE + PLACE_SIZE] / PLACE_CLIP * 255.0)
    data = {
        "v": DESCRIPTOR_VERSION,
        "d": [round(float(v), 6) for v in hist],
        "p": base64.b64encode(np.clip(codes, 0, 255).astype(np.uint8).tobytes()).decode("ascii"),
    }
    return json.dumps(data, separators=(",", ":"))


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
    try:
        hist = np.asarray(data.get("d", []), dtype=np.float64)
        codes = np.frombuffer(base64.b64decode(data.get("p", ""), validate=True), dtype=np.uint8)
    except (TypeError, ValueError):
        log.warning("ignoring an unreadable stored descriptor")
        return None
    if hist.shape != (FORM_SIZE + RELIEF_BINS,) or codes.shape != (PLACE_SIZE,):
        return None
    place = codes.astype(np.float64) * (PLACE_CLIP / 255.0)
    return np.concatenate([hist[:FORM_SIZE], place, hist[FORM_SIZE:]])
