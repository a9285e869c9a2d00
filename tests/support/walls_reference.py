"""The walls' classification before issue 11's cost work (kept to compare against).

Step 1 without the third-difference test, then for every suspect the secant point and two
rounds of three points over the whole edge (seven points an edge the secant does not show to be
a root), decided by ``_decide`` (from ``walls_main.py``, main's classifier before the second
cost work).  ``benchmarks/walls_cost.py`` times both against the classification now and
reports where their kinds differ.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numba import njit

from surfgen.generator.eval.grid import Field
from surfgen.generator.eval.row_operations import (
    sign as _sign,  # np.sign (the samples here are finite)
)
from surfgen.generator.eval.tape import PointsEvaluator, points_evaluator
from surfgen.generator.formula.expr import Expr
from surfgen.generator.mesh.mesh import ROOT
from surfgen.generator.mesh.refine import _decide
from tests.support.walls_main import (  # the frozen copy of main's classifier before walls2
    SECANT_ROOT,
    SEPARATION_T,
    SMOOTH_RATIO,
    UNKNOWN,
    _points_minus_level,
)

ROUNDS = 2  # refinement rounds ...
POINTS = 3  # ... of this many points each: the bracket shrinks 4x per round


def reference_classify_edges(
    field: Field,
    tree: Expr,
    params: Mapping[str, float] | None,
    level: float,
    edges: np.ndarray,
) -> tuple[np.ndarray, int]:
    """Kind (ROOT, POLE, JUMP, or UNKNOWN) of each ``(axis, i, j, k)`` edge of ``edges`` (V, 4).

    Rows with axis -1, or whose samples are on the same side, are UNKNOWN.  Returns uint8
    ``(V,)`` kinds and the number of edges refined with the formula.
    """
    values = np.ascontiguousarray(field.values, dtype=np.float64).reshape(-1)
    shape = np.asarray(field.values.shape, dtype=np.int64)
    edges = np.ascontiguousarray(edges, dtype=np.int64)
    kinds, idx, fa, fb, ina = _crossings(values, shape, edges, float(level), SMOOTH_RATIO)
    if idx.size == 0:
        return kinds, 0
    points = points_evaluator(tree, params)
    kinds[idx] = _classify_suspects(
        points, level, field, edges[idx, 1:], edges[idx, 0], ina, fa, fb
    )
    return kinds, int(idx.size)


def _classify_suspects(
    points: PointsEvaluator,
    level: float,
    field: Field,
    ijk: np.ndarray,
    axis: np.ndarray,
    a_inside: np.ndarray,
    fa: np.ndarray,
    fb: np.ndarray,
) -> np.ndarray:
    """Kinds of the suspect edges (sample ``ijk``, one step along ``axis``): the secant step,
    then the refinement of those it does not show to be roots (see the module's docstring).

    One numba call (:func:`_classify_kernel`): the per-edge arithmetic (:func:`_secant_points`,
    :func:`_secant_roots`, :func:`_round_points`, :func:`_round_update`, :func:`_decide`) and the
    formula at the points of each step (:func:`surfgen.generator.eval.point_driver.eval_points`, the
    points evaluator's kernel), so no step pays Python's overhead; each step does, edge by
    edge, the operations the numpy version of this module did on arrays, so the kinds are the
    same.
    """
    prog, tile, active, rows = points.kernel_args()
    ax, ay, az = (np.ascontiguousarray(a, dtype=np.float64) for a in field.grid.axes())
    spacing = np.asarray(field.grid.spacing, dtype=np.float64)
    frac = np.arange(1, POINTS + 1) / (POINTS + 1)
    return _classify_kernel(
        prog,
        tile,
        active,
        rows,
        float(level),
        ax,
        ay,
        az,
        spacing,
        np.ascontiguousarray(ijk, dtype=np.int64),
        np.ascontiguousarray(axis, dtype=np.int64),
        np.ascontiguousarray(a_inside, dtype=np.bool_),
        np.ascontiguousarray(fa, dtype=np.float64),
        np.ascontiguousarray(fb, dtype=np.float64),
        frac,
    )


_NB = {"cache": True, "error_model": "numpy", "nogil": True}


@njit(**_NB)
def _secant_points(origin, step, fa, fb, sep):
    """The secant point ``t* = fa / (fa - fb)`` of each edge, clipped to [sep, 1 - sep], mid-edge
    where it is NaN; returns the ``(n, 3)`` points and whether t* was a number."""
    n = fa.size
    xyz = np.empty((n, 3))
    finite = np.empty(n, dtype=np.bool_)
    for e in range(n):
        t = fa[e] / (fa[e] - fb[e])
        finite[e] = t == t  # np.clip keeps NaN and takes +-inf to the bounds
        if not finite[e]:
            t = 0.5
        elif t < sep:
            t = sep
        elif t > 1.0 - sep:
            t = 1.0 - sep
        for k in range(3):
            xyz[e, k] = origin[e, k] + t * step[e, k]
    return xyz, finite


@njit(**_NB)
def _secant_roots(f, finite, fa, fb, ratio):
    """``|F(t*)| < ratio * min(|fa|, |fb|)`` (a NaN anywhere: not a root)."""
    n = f.size
    out = np.zeros(n, dtype=np.bool_)
    for e in range(n):
        a, b = abs(fa[e]), abs(fb[e])
        if a != a or b != b:
            continue
        out[e] = finite[e] and abs(f[e]) < ratio * min(a, b)
    return out


@njit(**_NB)
def _round_points(origin, step, now, frac):
    """The points at fractions ``lo + (hi - lo) * frac`` of each bracket: ``(n, m, 3)`` points
    and ``(n, m)`` fractions."""
    n = origin.shape[0]
    m = frac.size
    s = np.empty((n, m))
    xyz = np.empty((n, m, 3))
    for e in range(n):
        lo = now[e, 0]
        width = now[e, 1] - lo
        for q in range(m):
            s[e, q] = lo + width * frac[q]
            for k in range(3):
                xyz[e, q, k] = origin[e, k] + s[e, q] * step[e, k]
    return xyz, s


@njit(**_NB)
def _round_update(now, s, vals):
    """The new bracket of each edge: the first side change along ``[lo, s..., hi]``."""
    n, m = vals.shape
    out = np.empty_like(now)
    for e in range(n):
        prev_s, prev_f = now[e, 0], now[e, 2]
        prev_in = np.isfinite(prev_f) and prev_f < 0.0
        found = False
        for q in range(m + 1):
            if q < m:
                cur_s, cur_f = s[e, q], vals[e, q]
            else:
                cur_s, cur_f = now[e, 1], now[e, 3]
            cur_in = np.isfinite(cur_f) and cur_f < 0.0
            if cur_in != prev_in:
                out[e, 0], out[e, 1], out[e, 2], out[e, 3] = prev_s, cur_s, prev_f, cur_f
                out[e, 4] = 1.0 if prev_in else 0.0
                found = True
                break
            prev_s, prev_f, prev_in = cur_s, cur_f, cur_in
        if not found:  # cannot happen: the ends are on opposite sides (argmax would take 0)
            out[e, 0], out[e, 1], out[e, 2] = now[e, 0], s[e, 0], now[e, 2]
            out[e, 3] = vals[e, 0]
            out[e, 4] = 1.0 if np.isfinite(now[e, 2]) and now[e, 2] < 0.0 else 0.0
    return out


@njit(**_NB)
def _classify_kernel(
    prog, tile, active, rows, level, ax, ay, az, spacing, ijk, axis, a_inside, fa, fb, frac
):
    """:func:`_classify_suspects` in one call."""
    n = fa.size
    origin = np.empty((n, 3))
    step = np.empty((n, 3))
    for e in range(n):
        origin[e, 0] = ax[ijk[e, 0]]
        origin[e, 1] = ay[ijk[e, 1]]
        origin[e, 2] = az[ijk[e, 2]]
        for k in range(3):  # a row of the identity times the spacing, as numpy did
            step[e, k] = (1.0 if k == axis[e] else 0.0) * spacing[axis[e]]
    xyz, finite = _secant_points(origin, step, fa, fb, SEPARATION_T)
    f = _points_minus_level(prog, tile, active, rows, xyz, level)
    roots = _secant_roots(f, finite, fa, fb, SECANT_ROOT)
    out = np.full(n, ROOT, dtype=np.uint8)
    rest = np.flatnonzero(~roots)
    m = rest.size
    if m == 0:
        return out
    origin, step = origin[rest], step[rest]
    fa, fb = fa[rest], fb[rest]
    # bracket: lo, hi, f_lo, f_hi, lo_inside (1.0/0.0); after round one and after the last
    now = np.empty((m, 5))
    for e in range(m):
        now[e, 0], now[e, 1], now[e, 2], now[e, 3] = 0.0, 1.0, fa[e], fb[e]
        now[e, 4] = 1.0 if a_inside[rest[e]] else 0.0
    mid = now
    for rnd in range(ROUNDS):
        xyz3, s = _round_points(origin, step, now, frac)
        vals = _points_minus_level(prog, tile, active, rows, xyz3.reshape(m * POINTS, 3), level)
        now = _round_update(now, s, vals.reshape(m, POINTS))
        if rnd == 0:
            mid = now
    kinds = _decide(mid, now, fa, fb)
    for e in range(m):
        out[rest[e]] = kinds[e]
    return out


@njit(**_NB)
def _crossings(values, shape, edges, level, ratio):
    """Kinds of the vertices' edges from the samples alone, and the suspects.

    Rows with axis -1, at the grid's end, or whose samples are on the same side (inside is
    ``F < level``, finite) are UNKNOWN, the others ROOT.  A crossing is *suspect* unless both
    neighbours along its grid line exist and the secants look smooth (step 1 of the module's
    docstring): returns
    the kinds, and for the suspects their rows, ``fa``, ``fb`` (``F - level`` at the edge's
    samples) and whether sample a is inside.
    """
    n = edges.shape[0]
    kinds = np.full(n, UNKNOWN, dtype=np.uint8)
    rows = np.empty(n, dtype=np.int64)
    out_a = np.empty(n)
    out_b = np.empty(n)
    out_in = np.empty(n, dtype=np.bool_)
    strides = (shape[1] * shape[2], shape[2], 1)
    count = 0
    for v in range(n):
        axis = edges[v, 0]
        if axis < 0:
            continue
        pos = edges[v, 1 + axis]
        length = shape[axis]
        if pos + 1 >= length:
            continue
        step = strides[axis]
        ia = edges[v, 1] * strides[0] + edges[v, 2] * strides[1] + edges[v, 3]
        ib = ia + step
        fa = values[ia] - level
        fb = values[ib] - level
        ina = np.isfinite(fa) and fa < 0.0
        if ina == (np.isfinite(fb) and fb < 0.0):
            continue
        kinds[v] = ROOT
        smooth = False
        if pos >= 1 and pos + 2 < length:
            fm = values[ia - step] - level
            fp = values[ib + step] - level
            d = fb - fa
            dm = fa - fm
            dp = fp - fb
            smooth = (
                np.isfinite(dm + d + dp)
                and _sign(dm) == _sign(d)
                and _sign(dp) == _sign(d)
                and abs(d) <= ratio * max(abs(dm), abs(dp))
            )
        if not smooth:
            rows[count] = v
            out_a[count] = fa
            out_b[count] = fb
            out_in[count] = ina
            count += 1
    return kinds, rows[:count], out_a[:count], out_b[:count], out_in[:count]
