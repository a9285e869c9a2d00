"""Checks of interval bounds shared by the tests of :mod:`surfgen.generator.eval.intervals`
and of :mod:`surfgen.generator.eval.interval_regroup`: random boxes, points in them, and the
soundness of bounds against the fast evaluator at those points."""

from __future__ import annotations

import numpy as np

from surfgen.generator.eval.intervals import tree_bounds
from surfgen.generator.eval.tape import points_evaluator


def random_boxes(rng: np.random.Generator, lo, hi, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Boxes of every size inside ``[lo, hi]`` (some flat, some a point, some from 0)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c = rng.uniform(lo, hi, (k, 3))
    w = (hi - lo) * rng.uniform(0, 1, (k, 3)) ** 3 * 0.4
    w[rng.random((k, 3)) < 0.08] = 0.0
    blo, bhi = c - w, c + w
    zero = rng.random((k, 3)) < 0.05
    blo[zero] = np.minimum(blo[zero], 0.0)
    bhi[zero] = np.maximum(bhi[zero], 0.0)
    return blo, bhi


def box_points(rng: np.random.Generator, blo, bhi, m: int = 12) -> np.ndarray:
    """The 8 corners, the centre and ``m`` random points of each box: ``(K, 9 + m, 3)``."""
    corners = np.array([[(i >> a) & 1 for a in range(3)] for i in range(8)], float)
    u = np.concatenate([corners, np.full((1, 3), 0.5)])[None].repeat(len(blo), 0)
    u = np.concatenate([u, rng.uniform(0, 1, (len(blo), m, 3))], axis=1)
    pts = blo[:, None] + u * (bhi - blo)[:, None]
    return np.clip(pts, blo[:, None], bhi[:, None])  # blo + (bhi - blo) may round past bhi


def assert_sound(tree, params, blo, bhi, rng, bounds=None) -> np.ndarray:
    """Every value of the fast evaluator at the boxes' points is NaN or inside the bounds, and
    finite where the bounds say so; returns the values."""
    flo, fhi, finite = bounds if bounds is not None else tree_bounds(tree, params, blo, bhi)
    pts = box_points(rng, blo, bhi)
    v = points_evaluator(tree, params)(*(pts[..., a].ravel() for a in range(3)))
    v = v.reshape(pts.shape[:2])
    out = ~np.isnan(v) & ((v < flo[:, None]) | (v > fhi[:, None]))
    nonfinite = finite[:, None] & ~np.isfinite(v)
    for bad, what in ((out, "outside its bounds"), (nonfinite, "not finite in a finite box")):
        if bad.any():
            k, j = np.argwhere(bad)[0]
            raise AssertionError(
                f"F{tuple(pts[k, j])} = {v[k, j]!r} {what}: box {blo[k].tolist()}.."
                f"{bhi[k].tolist()}, bounds [{flo[k]!r}, {fhi[k]!r}], finite {finite[k]}"
            )
    return v
