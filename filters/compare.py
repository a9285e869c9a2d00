"""How different two shapes are: inside-sample IoU on a common grid and Hausdorff distance.

Both measures compare shapes *as sampled*, which is what the paper's sensitivity claims are
about (Figure 3's I3, I4 and I5 are one formula sampled on three grids):

- :func:`inside_iou` reads each field as the trilinear interpolant of its samples (the function
  marching cubes triangulates the zero set of), with non-finite samples outside as in
  :func:`surfgen.generator.mesh.mesh.extract_mesh`, and everything outside a field's box outside too.
  Both interpolants are sampled on one grid over the union of the boxes; the IoU is
  |A ∩ B| / |A ∪ B| of the inside samples (1.0 when both are empty).
- :func:`hausdorff` is the symmetric Hausdorff distance between two meshes, estimated from
  area-uniform surface samples (seeded, so it is deterministic) and their nearest neighbours
  in the other sample set; its error is about the spacing of the samples.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates
from scipy.spatial import cKDTree

from surfgen.generator.eval.grid import Box, Field, Grid
from surfgen.generator.mesh.mesh import Mesh, face_areas

OUTSIDE = 1e300  # what a non-finite sample becomes before interpolation: far outside


def union_box(*boxes: Box) -> Box:
    """The smallest box holding every box."""
    lo = np.min([b.lo for b in boxes], axis=0)
    hi = np.max([b.hi for b in boxes], axis=0)
    return Box(tuple(float(v) for v in lo), tuple(float(v) for v in hi))


def inside_samples(field: Field, grid: Grid, level: float = 0.0) -> np.ndarray:
    """Boolean ``grid.shape`` array: where the trilinear interpolant of ``field`` is < level.

    Points of ``grid`` outside ``field``'s box are outside.
    """
    values = np.where(np.isfinite(field.values), field.values - level, OUTSIDE)
    src = field.grid
    axes = grid.axes()
    coords = []
    valid = np.ones(grid.shape, dtype=bool)
    for k, (axis, lo, hi, n) in enumerate(
        zip(axes, src.box.lo, src.box.hi, src.shape, strict=True)
    ):
        t = (axis - lo) / (hi - lo) * (n - 1)
        shape = [1, 1, 1]
        shape[k] = -1
        inside_box = (axis >= lo) & (axis <= hi)
        valid &= inside_box.reshape(shape)
        coords.append(np.broadcast_to(t.reshape(shape), grid.shape))
    sampled = map_coordinates(values, np.stack(coords), order=1, mode="nearest", prefilter=False)
    return valid & (sampled < 0.0)


def inside_iou(a: Field, b: Field, grid_size: int, level: float = 0.0) -> float:
    """IoU of the inside samples of ``a`` and ``b`` on a ``grid_size``³ grid over both boxes."""
    grid = Grid.from_sizes(union_box(a.grid.box, b.grid.box), grid_size)
    ia, ib = inside_samples(a, grid, level), inside_samples(b, grid, level)
    union = int(np.count_nonzero(ia | ib))
    if union == 0:
        return 1.0
    return float(np.count_nonzero(ia & ib)) / union


def surface_samples(mesh: Mesh, n: int, seed: int = 0) -> np.ndarray:
    """``(n, 3)`` points uniform by area on ``mesh`` (seeded: the same points every time)."""
    rng = np.random.default_rng(seed)
    areas = face_areas(mesh)
    total = areas.sum()
    if mesh.n_faces == 0 or not total > 0:
        return np.asarray(mesh.vertices[:1], dtype=np.float64).reshape(-1, 3)
    faces = rng.choice(mesh.n_faces, size=n, p=areas / total)
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    tri = mesh.vertices[mesh.faces[faces]]
    return tri[:, 0] + u[:, None] * (tri[:, 1] - tri[:, 0]) + v[:, None] * (tri[:, 2] - tri[:, 0])


def hausdorff(a: Mesh, b: Mesh, samples: int = 20000, seed: int = 0) -> float:
    """Symmetric Hausdorff distance between ``a`` and ``b`` (box units), from surface samples."""
    pa = np.vstack([surface_samples(a, samples, seed), a.vertices])
    pb = np.vstack([surface_samples(b, samples, seed + 1), b.vertices])
    d_ab = cKDTree(pb).query(pa)[0].max()
    d_ba = cKDTree(pa).query(pb)[0].max()
    return float(max(d_ab, d_ba))


__all__ = [
    "hausdorff",
    "inside_iou",
    "inside_samples",
    "surface_samples",
    "union_box",
]
