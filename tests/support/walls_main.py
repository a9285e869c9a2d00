"""The walls' classification of main before the second cost work (issue 11, branch walls2),
frozen to compare against: the third-difference smoothness test, then for every suspect the
secant point ``t* = fa / (fa - fb)`` (kept 1 % of the edge from the samples), two bisections of
the part where the side changes and two more where it still ends at a sample, decided by
``_decide`` (a copy).  ``benchmarks/walls_cost.py`` times it against the classification now and
reports where their kinds differ.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numba import njit

from surfgen.generator.eval.grid import Field
from surfgen.generator.eval.point_driver import eval_points
from surfgen.generator.eval.tape import points_evaluator
from surfgen.generator.formula.expr import Expr
from surfgen.generator.mesh.mesh import ROOT
from surfgen.generator.mesh.refine import _decide  # unchanged since: shared, not copied
from surfgen.generator.mesh.walls import _crossings

ROOT_SHRINK = 0.6
ROOT_FLOOR = 1e-9
ROOT_KEPT = 0.25
POLE_GROWTH = 2.5
POLE_SCALE = 4.0
SMOOTH_RATIO = 2.0
SMOOTH_THIRD = 1.0
SECANT_ROOT = 0.25
SEPARATION_T = 0.01
BISECTIONS = 2
UNKNOWN = 255


def main_classify(
    field: Field,
    tree: Expr,
    params: Mapping[str, float] | None,
    level: float,
    edges: np.ndarray,
) -> tuple[np.ndarray, int, int]:
    """Kinds of the ``(axis, i, j, k)`` rows of ``edges``, the suspects and the points evaluated
    (``walls._classify`` as it was on main)."""
    values = np.ascontiguousarray(field.values, dtype=np.float64).reshape(-1)
    shape = np.asarray(field.values.shape, dtype=np.int64)
    edges = np.ascontiguousarray(edges, dtype=np.int64)
    kinds, idx, fa, fb, ina = _crossings(values, shape, edges, float(level), SMOOTH_RATIO)
    if idx.size == 0:
        return kinds, 0, 0
    prog, tile, active, rows = points_evaluator(tree, params).kernel_args()
    ax, ay, az = (np.ascontiguousarray(a, dtype=np.float64) for a in field.grid.axes())
    kinds[idx], points = _bisect_kernel(
        prog,
        tile,
        active,
        rows,
        float(level),
        ax,
        ay,
        az,
        np.asarray(field.grid.spacing, dtype=np.float64),
        np.ascontiguousarray(edges[idx, 1:]),
        np.ascontiguousarray(edges[idx, 0]),
        ina,
        fa,
        fb,
    )
    return kinds, int(idx.size), int(points)


_NB = {"cache": True, "error_model": "numpy", "nogil": True}


@njit(**_NB)
def _points_minus_level(prog, tile, active, rows, xyz, level):
    """F - level at the ``(n, 3)`` points ``xyz``."""
    px = np.ascontiguousarray(xyz[:, 0])
    py = np.ascontiguousarray(xyz[:, 1])
    pz = np.ascontiguousarray(xyz[:, 2])
    out = np.empty(px.size)
    if px.size:
        eval_points(prog, tile, active, rows, px, py, pz, out)
    for p in range(out.size):
        out[p] = out[p] - level
    return out


@njit(**_NB)
def _bisect(prog, tile, active, rows, level, origin, step, now, sel, times):
    """``times`` bisections of the brackets ``now[sel]`` (lo, hi, f_lo, f_hi, lo_inside), in
    place: each keeps the half where the side changes; one batch of points per bisection."""
    m = sel.size
    xyz = np.empty((m, 3))
    for _ in range(times):
        for r in range(m):
            e = sel[r]
            s = 0.5 * (now[e, 0] + now[e, 1])
            for k in range(3):
                xyz[r, k] = origin[e, k] + s * step[e, k]
        fm = _points_minus_level(prog, tile, active, rows, xyz, level)
        for r in range(m):
            e = sel[r]
            s = 0.5 * (now[e, 0] + now[e, 1])
            inside_m = np.isfinite(fm[r]) and fm[r] < 0.0
            if (now[e, 4] != 0.0) != inside_m:  # the side changes in the lower half
                now[e, 1], now[e, 3] = s, fm[r]
            else:
                now[e, 0], now[e, 2] = s, fm[r]
                now[e, 4] = 1.0 if inside_m else 0.0
    return m * times


@njit(**_NB)
def _bisect_kernel(
    prog, tile, active, rows, level, ax, ay, az, spacing, ijk, axis, a_inside, fa, fb
):
    """Kinds of suspect edges (steps 2 and 3 of the module's docstring): the secant point,
    two bisections of the part of the edge where the side changes, two more where that part
    still ends at a sample.  Returns the kinds and the number of points evaluated."""
    n = fa.size
    origin = np.empty((n, 3))
    step = np.zeros((n, 3))
    t = np.empty(n)
    xyz = np.empty((n, 3))
    for e in range(n):
        origin[e, 0] = ax[ijk[e, 0]]
        origin[e, 1] = ay[ijk[e, 1]]
        origin[e, 2] = az[ijk[e, 2]]
        step[e, axis[e]] = spacing[axis[e]]
        u = fa[e] / (fa[e] - fb[e])
        if u != u:
            u = 0.5
        t[e] = min(max(u, SEPARATION_T), 1.0 - SEPARATION_T)
        for k in range(3):
            xyz[e, k] = origin[e, k] + t[e] * step[e, k]
    fs = _points_minus_level(prog, tile, active, rows, xyz, level)
    out = np.full(n, ROOT, dtype=np.uint8)
    points = n
    # the brackets: lo, hi, f_lo, f_hi, lo_inside (1.0/0.0); the secant point splits the edge
    now = np.empty((n, 5))
    rest = np.empty(n, dtype=np.int64)
    m = 0
    for e in range(n):
        a, b = abs(fa[e]), abs(fb[e])
        finite = (
            fa[e] == fa[e]
            and fb[e] == fb[e]
            and (fa[e] / (fa[e] - fb[e])) == (fa[e] / (fa[e] - fb[e]))
        )
        if finite and abs(fs[e]) < SECANT_ROOT * min(a, b):
            continue  # a root
        inside_s = np.isfinite(fs[e]) and fs[e] < 0.0
        if a_inside[e] != inside_s:
            now[e, 0], now[e, 1], now[e, 2], now[e, 3] = 0.0, t[e], fa[e], fs[e]
            now[e, 4] = 1.0 if a_inside[e] else 0.0
        else:
            now[e, 0], now[e, 1], now[e, 2], now[e, 3] = t[e], 1.0, fs[e], fb[e]
            now[e, 4] = 1.0 if inside_s else 0.0
        rest[m] = e
        m += 1
    rest = rest[:m]
    before = now.copy()
    points += _bisect(prog, tile, active, rows, level, origin, step, now, rest, BISECTIONS)
    held = np.empty(m, dtype=np.int64)
    n_held = 0
    for r in range(m):
        e = rest[r]
        if now[e, 0] == 0.0 or now[e, 1] == 1.0:
            held[n_held] = e
            n_held += 1
            for k in range(5):
                before[e, k] = now[e, k]
    points += _bisect(prog, tile, active, rows, level, origin, step, now, held[:n_held], BISECTIONS)
    kinds = _decide(before[rest], now[rest], fa[rest], fb[rest])
    for r in range(m):
        out[rest[r]] = kinds[r]
    return out, points
