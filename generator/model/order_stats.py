"""numpy's ``quantile`` (method "linear") and ``median`` of a float64 array, bit for bit, in one
``np.partition`` each.

The families call them on small samples many times a draw (periods, ornament strengths, strut
thickness, d): numpy's own functions spend tens of microseconds a call in their generic
machinery (axes, methods, weights, NaN bookkeeping), longer than the partition itself on
these sizes. The arithmetic here is numpy's, step for step: the virtual index ``(n - 1) q``,
its floor and the next order statistic (both the last one at or past the end), the weight
``gamma = index - floor`` and ``a + (b - a) gamma``, or ``b - (b - a)(1 - gamma)`` from
``gamma`` 0.5 on; a median is numpy's mean of the middle order statistic or of the two middle
ones (a sum from +0.0, divided); a NaN anywhere gives NaN. Other dtypes and empty arrays go to
numpy. ``tests/generator/model/test_order_stats.py`` compares them with numpy bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def quantiles(values: np.ndarray, qs: Sequence[float]) -> tuple[np.float64, ...]:
    """``np.quantile(values, qs)`` (all of ``values``), as a tuple of float64 scalars."""
    a = np.asarray(values)
    if a.dtype != np.float64 or a.size == 0:
        return tuple(np.atleast_1d(np.quantile(a, qs)))
    a = a.reshape(-1)
    n = a.size
    picks = []
    for q in qs:
        v = (n - 1) * float(q)
        if v >= n - 1 or v != v:  # at or past the last (numpy's index -1)
            lo = hi = n - 1
            gamma = v + 1.0
        elif v < 0:
            lo = hi = 0
            gamma = v
        else:
            lo = int(math.floor(v))
            hi = lo + 1
            gamma = v - lo
        picks.append((lo, hi, gamma))
    part = np.partition(a, sorted({n - 1, *(p[0] for p in picks), *(p[1] for p in picks)}))
    if part[n - 1] != part[n - 1]:  # NaN sorts last
        return tuple(np.float64(np.nan) for _ in picks)
    out = []
    for lo, hi, gamma in picks:
        x, y = part[lo], part[hi]
        diff = y - x
        out.append(y - diff * (1.0 - gamma) if gamma >= 0.5 else x + diff * gamma)
    return tuple(np.float64(r) for r in out)


def quantile(values: np.ndarray, q: float) -> np.floating:
    """``np.quantile(values, q)`` for one ``q`` (another dtype's in its own precision, as numpy
    computes a scalar ``q``)."""
    a = np.asarray(values)
    if a.dtype != np.float64 or a.size == 0:
        return np.quantile(a, q)
    return quantiles(a, (q,))[0]


def median(values: np.ndarray) -> np.floating:
    """``np.median(values)`` (all of ``values``)."""
    a = np.asarray(values)
    if a.dtype != np.float64 or a.size == 0:
        return np.median(a)
    a = a.reshape(-1)
    n = a.size
    h = n // 2
    part = np.partition(a, [h - 1, h, n - 1] if n % 2 == 0 and n > 1 else [h, n - 1])
    if part[n - 1] != part[n - 1]:
        return np.float64(np.nan)
    # numpy's mean of the middle one or two: a sum from +0.0 (so -0.0 comes out +0.0), divided
    if n % 2:
        return np.float64(0.0 + part[h])
    return np.float64((0.0 + part[h - 1] + part[h]) / 2.0)
