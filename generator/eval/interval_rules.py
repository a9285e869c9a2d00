"""Interval rules of the tape's opcodes on one box: scalar numba helpers, inlined into the
loops of :mod:`surfgen.generator.eval.interval_kernels`.

An interval value is a triple ``(lo, hi, nan)``: every value the fast evaluator computes for
that operation over the box is NaN or lies in the closed interval ``[lo, hi]`` (``±inf``
allowed as values and bounds); ``nan`` is False only when no value can be NaN. ``lo > hi``
(:data:`EMPTY_LO`, :data:`EMPTY_HI`) is the empty interval: every value is NaN. ``lo`` and
``hi`` are never NaN themselves.

Rounding: the exact IEEE operations (``+ - * /``, sqrt, floor, min, fmod...) round
monotonically, so their bounds are the operation at the right endpoints, with no widening.
surfgen's elementary functions are within 0.77 ulp of the exact function
(docs/reference/elementary.md), so on a monotone piece the value at an interior point
exceeds the value at the piece's end by at most about 1.5 ulp: :func:`up` and :func:`down`
widen by at least 4 ulp (``2^-49`` relative) plus a few subnormals; the closed-form round
trips are within half an ulp plus ``2^-100`` absolute: :func:`up_rt` adds ``1e-27``.
See docs/reference/intervals.md.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from surfgen.generator.eval.row_operations import EPS
from surfgen.generator.jit.options import KERNEL as RULE

INF = math.inf
PI = math.pi
HALF_PI = math.pi / 2
TWO_PI = 2.0 * math.pi
REL = 2.0**-49  # relative widening of an elementary function's value: >= 4 ulp
TINY = 2.0**-1060  # absolute widening: subnormal results (a few thousand subnormal ulps)
RT_ABS = 1e-27  # the round trips' absolute error is below 2^-100 (about 8e-31)
HUGE_ARG = 2.0**50  # beyond this a periodic function's argument gets its whole range
EMPTY_LO, EMPTY_HI = INF, -INF  # the empty interval: every value NaN


@njit(**RULE)
def up(v):
    """``v`` widened upwards by 4 ulp or more (``±inf`` unchanged)."""
    if abs(v) < INF:
        return v + abs(v) * REL + TINY
    return v


@njit(**RULE)
def down(v):
    """``v`` widened downwards by 4 ulp or more (``±inf`` unchanged)."""
    if abs(v) < INF:
        return v - abs(v) * REL - TINY
    return v


@njit(**RULE)
def up_rt(v):
    return up(v) + RT_ABS


@njit(**RULE)
def down_rt(v):
    return down(v) - RT_ABS


@njit(**RULE)
def is_finite(v):
    return abs(v) < INF


@njit(**RULE)
def may_hit(lo, hi, off, per):
    """Whether a point ``off + j*per`` (j integer, ``off`` and ``per`` real multiples of pi
    given as doubles) may lie in ``[lo, hi]``: True when in doubt (a slack of ``1e-12`` periods
    and more for large arguments, far above the rounding of the quotients)."""
    if not (abs(lo) <= HUGE_ARG and abs(hi) <= HUGE_ARG):
        return True
    if hi - lo >= per:
        return True
    t0 = (lo - off) / per
    t1 = (hi - off) / per
    s = 1e-12 * (1.0 + max(abs(t0), abs(t1)))
    return np.floor(t1 + s) >= np.ceil(t0 - s)


# ----------------------------------------------------------------------------- arithmetic


@njit(**RULE)
def hull4(c0, c1, c2, c3):
    """Hull of four corner values, NaN corners left out: ``(lo, hi, any_nan)``. For an
    operation monotone in each operand (``+ - *``, ``/`` away from 0) the hull of the corners
    is the range over the box. A NaN corner of ``+`` or ``-`` (``inf - inf``) needs an infinite
    operand that is one value, ``[inf, inf]``: the other corners hold every other value. A
    NaN corner of ``*`` (``0 * inf``) or ``/`` (``inf / inf``) can hide the value 0 (``0 * x``,
    ``x / inf`` for every finite x): :func:`mul_rule` and :func:`div_rule` add it."""
    lo = INF
    hi = -INF
    bad = False
    for c in (c0, c1, c2, c3):
        if c != c:
            bad = True
        else:
            lo = min(lo, c)
            hi = max(hi, c)
    return lo, hi, bad


@njit(**RULE)
def contains0(lo, hi):
    return lo <= 0.0 and hi >= 0.0


@njit(**RULE)
def has_inf(lo, hi):
    return not (abs(lo) < INF and abs(hi) < INF)


@njit(**RULE)
def add_rule(alo, ahi, blo, bhi):
    return hull4(alo + blo, alo + bhi, ahi + blo, ahi + bhi)


@njit(**RULE)
def sub_rule(alo, ahi, blo, bhi):
    return hull4(alo - blo, alo - bhi, ahi - blo, ahi - bhi)


@njit(**RULE)
def mul_rule(alo, ahi, blo, bhi):
    lo, hi, bad = hull4(alo * blo, alo * bhi, ahi * blo, ahi * bhi)
    # 0 * inf where 0 lies inside an operand, not at a corner
    bad = bad or (contains0(alo, ahi) and has_inf(blo, bhi))
    bad = bad or (contains0(blo, bhi) and has_inf(alo, ahi))
    if bad:  # 0 * inf: 0 * x = 0 for the finite x beside it
        lo, hi = min(lo, 0.0), max(hi, 0.0)
    return lo, hi, bad


@njit(**RULE)
def div_rule(alo, ahi, blo, bhi):
    """``a / b``: ``(lo, hi, nan_0_0, nan_inf_inf)``. A divisor interval that holds 0 (of
    either sign: ``-0`` is not told apart) gives the whole line."""
    zz = contains0(alo, ahi) and contains0(blo, bhi)
    ii = has_inf(alo, ahi) and has_inf(blo, bhi)
    if contains0(blo, bhi):
        return -INF, INF, zz, ii
    lo, hi, bad = hull4(alo / blo, alo / bhi, ahi / blo, ahi / bhi)
    if bad:  # inf / inf: x / inf = 0 for the finite x beside it
        lo, hi = min(lo, 0.0), max(hi, 0.0)
    return lo, hi, zz, ii or bad


@njit(**RULE)
def square_rule(lo, hi):
    """``u*u``: exact rounding, even."""
    a = lo * lo
    b = hi * hi
    if lo <= 0.0 and hi >= 0.0:
        return 0.0, max(a, b)
    return min(a, b), max(a, b)


@njit(**RULE)
def recip_rule(lo, hi):
    """``1/u`` (never NaN from a number)."""
    if lo <= 0.0 and hi >= 0.0:
        return -INF, INF
    return 1.0 / hi, 1.0 / lo


@njit(**RULE)
def abs_rule(lo, hi):
    if lo >= 0.0:
        return lo, hi
    if hi <= 0.0:
        return -hi, -lo
    return 0.0, max(-lo, hi)


@njit(**RULE)
def sign_rule(lo, hi):
    """numpy's sign: -1, 0 (at ±0), +1."""
    a = -1.0 if lo < 0.0 else (0.0 if lo == 0.0 else 1.0)
    b = -1.0 if hi < 0.0 else (0.0 if hi == 0.0 else 1.0)
    return a, b


@njit(**RULE)
def usign_rule(lo, hi):
    """+1 for u >= 0 (-0 too), -1 below."""
    return (1.0 if lo >= 0.0 else -1.0), (1.0 if hi >= 0.0 else -1.0)


@njit(**RULE)
def trunc1(v):
    return np.floor(v) if v >= 0.0 else np.ceil(v)


# ----------------------------------------------------------------------------- logic


@njit(**RULE)
def can_true(lo, hi):
    """Whether ``|v| >= 0.5`` for some v of ``[lo, hi]`` (False for the empty interval)."""
    return lo <= hi and (lo <= -0.5 or hi >= 0.5)


@njit(**RULE)
def can_false(lo, hi, nan):
    """Whether ``|v| < 0.5`` or NaN (false) for some value."""
    return nan or (lo <= hi and lo < 0.5 and hi > -0.5)


@njit(**RULE)
def bool_interval(t, f):
    """The interval of a 0/1 result that can be true (``t``) and/or false (``f``)."""
    if t and f:
        return 0.0, 1.0
    if t:
        return 1.0, 1.0
    if f:
        return 0.0, 0.0
    return EMPTY_LO, EMPTY_HI


@njit(**RULE)
def compare_rule(op, alo, ahi, an, blo, bhi, bn, lt_op, le_op, eq_op, ne_op):
    """lt, le, eq, ne (fparser's tolerance EPS): a 0/1 value, never NaN."""
    empty = alo > ahi or blo > bhi
    nan = an or bn
    if empty:
        return 0.0, 0.0
    if op == lt_op:  # a < b - EPS
        t = alo < bhi - EPS
        f = nan or ahi >= blo - EPS
        return bool_interval(t, f)
    if op == le_op:  # a <= b + EPS
        t = alo <= bhi + EPS
        f = nan or ahi > blo + EPS
        return bool_interval(t, f)
    dlo, dhi, dbad = sub_rule(alo, ahi, blo, bhi)
    mlo, mhi = abs_rule(dlo, dhi)
    if dlo > dhi:  # every difference NaN (inf - inf)
        mlo, mhi = EMPTY_LO, EMPTY_HI
    if op == eq_op:  # |a - b| <= EPS
        t = mlo <= EPS and mlo <= mhi
        f = nan or dbad or mhi > EPS
        return bool_interval(t, f)
    # ne: |a - b| > EPS
    t = mhi > EPS and mlo <= mhi
    f = nan or dbad or mlo <= EPS
    return bool_interval(t, f)


@njit(**RULE)
def hull(alo, ahi, blo, bhi):
    """Union hull (the empty interval is the identity)."""
    return min(alo, blo), max(ahi, bhi)


# ----------------------------------------------------------------------------- fmod


@njit(**RULE)
def _fmod_piece(lo, hi, b, m):
    """fmod over ``[lo, hi]`` on one side of 0 with a constant divisor ``b`` (``m = |b|``)."""
    if hi - lo < m:  # at most one wrap: none when the remainders keep their order
        rl = np.fmod(lo, b)
        rh = np.fmod(hi, b)
        if rh >= rl:
            return rl, rh
    if lo >= 0.0:
        return 0.0, min(hi, m)
    return max(lo, -m), 0.0


@njit(**RULE)
def fmod_rule(alo, ahi, blo, bhi):
    """C fmod (exact, the sign of a, |r| < |b|): ``(lo, hi, nan)``."""
    nan = contains0(blo, bhi) or has_inf(alo, ahi)
    m = max(abs(blo), abs(bhi))
    if blo == bhi and blo != 0.0 and abs(blo) < INF and not has_inf(alo, ahi):
        if alo >= 0.0 or ahi <= 0.0:
            lo, hi = _fmod_piece(alo, ahi, blo, m)
        else:
            l1, h1 = _fmod_piece(alo, -0.0, blo, m)
            l2, h2 = _fmod_piece(0.0, ahi, blo, m)
            lo, hi = hull(l1, h1, l2, h2)
        return lo, hi, nan
    lo = 0.0 if alo >= 0.0 else max(alo, -m)
    hi = 0.0 if ahi <= 0.0 else min(ahi, m)
    return lo, hi, nan


# ----------------------------------------------------------------------------- atan2


@njit(**RULE)
def atan2_corners_ok(ylo, yhi, xlo, xhi):
    """Whether the box stays off atan2's branch cut (x <= 0, y = ±0): then atan2 is monotone
    in each operand and its corners bound it."""
    return xlo > 0.0 or ylo > 0.0 or yhi < 0.0


# ----------------------------------------------------------------------------- pow


@njit(**RULE)
def is_int(e):
    return abs(e) < INF and np.floor(e) == e


@njit(**RULE)
def is_odd(e):
    return is_int(e) and abs(e) < 2.0**53 and np.fmod(e, 2.0) != 0.0


@njit(**RULE)
def pow_pos_corners(p0, p1, p2, p3):
    """Hull of pow at the corners of a box of non-negative bases, widened."""
    lo, hi, bad = hull4(p0, p1, p2, p3)
    return down(lo), up(hi), bad


__all__ = [
    "EMPTY_HI",
    "EMPTY_LO",
    "HALF_PI",
    "INF",
    "PI",
    "TWO_PI",
    "abs_rule",
    "add_rule",
    "div_rule",
    "down",
    "down_rt",
    "fmod_rule",
    "hull",
    "may_hit",
    "mul_rule",
    "sub_rule",
    "up",
    "up_rt",
]
