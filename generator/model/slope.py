"""``|grad a|`` of samples on a grid, as numpy computes it, bit for bit, in one pass.

The families judge their draws on small grids (24^3: the ornament's features and strength, the
finest period of a constituent's argument, an envelope's slope at its surface) through
``np.sqrt(sum(g**2 for g in np.gradient(a, *steps)))``: eight temporaries of the grid's size
and numpy's generic ``gradient`` machinery, about 0.35 ms a call at 24^3, and a draw makes
a dozen such calls. :func:`gradient_norm` repeats numpy's arithmetic point by point: central
differences ``(a[i+1] - a[i-1]) / (2 h)`` inside, one-sided ``(a[1] - a[0]) / h`` and
``(a[n-1] - a[n-2]) / h`` at the ends (numpy's ``edge_order=1``), the squares summed in the
order of the axes (``0 + gx^2`` is ``gx^2``), then the square root: IEEE operations in the same
order, so the same bits, NaN and infinities included. ``tests/generator/model/test_slope.py``
compares it with numpy bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numba import njit

from surfgen.generator.jit.options import KERNEL, read_only


def gradient_norm(a: np.ndarray, steps: float | Sequence[float]) -> np.ndarray:
    """``np.sqrt(sum(g**2 for g in np.gradient(a, *steps)))`` for a 3-d float64 ``a`` with at
    least 2 samples per axis, bit for bit; ``steps``: the spacing of each axis, or one for all.
    Other arrays go to numpy (which raises what it raises)."""
    given = (steps,) if np.ndim(steps) == 0 else tuple(steps)
    h = tuple(float(s) for s in given) * (3 if len(given) == 1 else 1)
    a = np.asarray(a)
    if a.ndim != 3 or a.dtype != np.float64 or min(a.shape) < 2 or len(h) != 3:
        with np.errstate(invalid="ignore", over="ignore"):
            return np.sqrt(sum(g**2 for g in np.gradient(a, *given)))
    a = read_only(np.ascontiguousarray(a))  # one compiled signature, and no copy
    out = np.empty(a.shape)
    _gradient_norm(a, h[0], h[1], h[2], out)
    return out


@njit(**KERNEL)
def _gradient_norm(a, h0, h1, h2, out):
    n0, n1, n2 = a.shape
    d0, d1, d2 = 2.0 * h0, 2.0 * h1, 2.0 * h2
    for i in range(n0):
        i_lo, i_hi = max(i - 1, 0), min(i + 1, n0 - 1)
        for j in range(n1):
            j_lo, j_hi = max(j - 1, 0), min(j + 1, n1 - 1)
            for k in range(n2):
                k_lo, k_hi = max(k - 1, 0), min(k + 1, n2 - 1)
                # central inside; one-sided at an end: (a[1] - a[0]) / h, (a[n-1] - a[n-2]) / h
                if i == 0 or i == n0 - 1:
                    g0 = (a[i_hi, j, k] - a[i_lo, j, k]) / h0
                else:
                    g0 = (a[i_hi, j, k] - a[i_lo, j, k]) / d0
                if j == 0 or j == n1 - 1:
                    g1 = (a[i, j_hi, k] - a[i, j_lo, k]) / h1
                else:
                    g1 = (a[i, j_hi, k] - a[i, j_lo, k]) / d1
                if k == 0 or k == n2 - 1:
                    g2 = (a[i, j, k_hi] - a[i, j, k_lo]) / h2
                else:
                    g2 = (a[i, j, k_hi] - a[i, j, k_lo]) / d2
                out[i, j, k] = math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)  # in numpy's order
