"""The interpreter's operations on one value and on one row, as numba functions: the scalar
helpers of its cheap loops (signs, ``min``/``max`` as numpy's, fparser's comparisons and logic),
``pow`` with the ``x^c`` convention, the series of eqs. (2)-(4) and the segment sums of the
piecewise constituents.

The interpreter (:mod:`surfgen.generator.eval.interpreter`) inlines the scalar helpers into its
loops; the row operations here run behind the row table, each compiled once as a C function of
its own (:mod:`surfgen.generator.eval.row_functions`). They are a module of their own so that
both import them and neither imports the other. Every operation computes what the reference
(:mod:`surfgen.generator.eval.reference`) computes, in the same order: the same bits.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from surfgen.generator.elementary import REGISTRY as _E
from surfgen.generator.eval.opcodes import (
    OP_AND,
    OP_EQ,
    OP_FMOD,
    OP_LE,
    OP_LT,
    OP_NE,
    OP_OR,
    OP_PICK,
    OP_PICKN,
)
from surfgen.generator.jit.options import INLINE, KERNEL

EPS = 1e-12  # logic.EPS: fparser's comparison tolerance

# pow's rows (:func:`power_vs` and its kin apply the x^c convention to them).
_pow_vv = _E["pow"].row_vv
_pow_vs = _E["pow"].row_vs
_pow_sv = _E["pow"].row_sv

# ----------------------------------------------------------------------------- scalar helpers


@njit(**INLINE)
def unsigned(i):
    """Index ``i`` (never negative) as unsigned: numba checks a signed index for a negative
    value to wrap around, a compare and a select at every load of a gather."""
    return np.uint64(i)


@njit(**INLINE)
def usign(u):
    """constituents.unit_sign: +1 for u >= 0 (also -0), -1 below, NaN for NaN."""
    if u >= 0.0:
        return 1.0
    if u < 0.0:
        return -1.0
    return u


@njit(**INLINE)
def sign(u):
    """np.sign: sign(+-0) = +0, NaN stays NaN."""
    if u > 0.0:
        return 1.0
    if u < 0.0:
        return -1.0
    if u == 0.0:
        return 0.0
    return u


@njit(**INLINE)
def minimum(a, b):
    """np.minimum: NaN propagates; for equal operands (+0, -0) numpy returns the second."""
    if a < b or a != a:
        return a
    return b


@njit(**INLINE)
def maximum(a, b):
    if a > b or a != a:
        return a
    return b


@njit(**INLINE)
def ratio1(a, b):
    q = a / b
    if a == 0.0 and b == 0.0:
        return 1.0
    return q


@njit(**INLINE)
def truth(v):
    """logic.truth: |v| >= 0.5, NaN false."""
    return abs(v) >= 0.5


@njit(**INLINE)
def is_logic2(op):
    return (OP_LT <= op <= OP_OR) or op == OP_PICK or op == OP_PICKN or op == OP_FMOD  # noqa: SIM109 (numba)


@njit(**INLINE)
def logic2(op, a, b):
    """The two-operand operations of logic.py, value for value."""
    if op == OP_LT:
        return 1.0 if a < b - EPS else 0.0
    if op == OP_LE:
        return 1.0 if a <= b + EPS else 0.0
    if op == OP_EQ:
        return 1.0 if abs(a - b) <= EPS else 0.0
    if op == OP_NE:
        return 1.0 if abs(a - b) > EPS else 0.0
    if op == OP_AND:
        return 1.0 if truth(a) and truth(b) else 0.0
    if op == OP_OR:
        return 1.0 if truth(a) or truth(b) else 0.0
    if op == OP_PICK:
        return b if truth(a) else 0.0
    if op == OP_PICKN:
        return 0.0 if truth(a) else b
    return np.fmod(a, b)  # OP_FMOD (C fmod: exact)


@njit(**INLINE)
def trunc(u):
    return np.floor(u) if u >= 0.0 else np.ceil(u)


@njit(**INLINE)
def _pow_rule(u, e, p):
    """The ``x^c`` convention (elementary.POW_SHORTCUTS) applied to ``p = pow(u, e)``:
    branch-free selects, so the loop that applies it vectorises."""
    r = p
    r = u * u if e == 2.0 else r
    r = math.sqrt(u) if e == 0.5 else r
    r = 1.0 / u if e == -1.0 else r
    r = u if e == 1.0 else r
    return 1.0 if e == 0.0 else r


@njit(**INLINE)
def power_vs(W, d, a, s, n):
    """W[d] = W[a]^s: the shortcut loop for s in POW_SHORTCUTS, else surfgen's pow."""
    if s == 2.0 or s == 0.5 or s == -1.0 or s == 1.0 or s == 0.0:
        for k in range(n):
            u = W[a, k]
            W[d, k] = _pow_rule(u, s, u)
    else:
        _pow_vs(W, d, a, s, n)


@njit(**INLINE)
def power_vv(W, d, a, b, n):
    """W[d] = W[a]^W[b] (d differs from a and b: the compiler never writes in place)."""
    _pow_vv(W, d, a, b, n)
    for k in range(n):
        W[d, k] = _pow_rule(W[a, k], W[b, k], W[d, k])


@njit(**INLINE)
def power_sv(W, d, s, b, n):
    _pow_sv(W, d, s, b, n)
    for k in range(n):
        W[d, k] = _pow_rule(s, W[b, k], W[d, k])


@njit(**KERNEL)
def series_exact(x, r, p):
    """sum_{i=-p}^{p} (1 - us(x-a) us(x-b)) (x - a), a = r(i-1), b = r i: as the reference."""
    total = 0.0
    for i in range(-p, p + 1):
        a = r * (i - 1)
        b = r * i
        total = total + (1.0 - usign(x - a) * usign(x - b)) * (x - a)
    return total


@njit(**KERNEL)
def series(x, r, p):
    """The same sum in O(1): the selectors are 2 on [a, b), so one term survives and every
    other term adds a zero, which leaves the sum bit-identical (see constituents.py)."""
    if x != x or abs(x) > 1e307:  # NaN, inf (0*inf) and overflow of x - a: the slow way
        return series_exact(x, r, p)
    q = x / r
    if q < -(p + 2.0) or q > p + 2.0:
        return 0.0
    i0 = int(np.floor(q)) + 1
    for i in range(i0 - 1, i0 + 2):
        if -p <= i <= p:
            a = r * (i - 1)
            if a <= x and x < r * i:
                return 0.0 + 2.0 * (x - a)  # +0 + ...: the sum's sign of zero (x = -0)
    return 0.0


# ----------------------------------------------------------------------------- row operations
#
# Every operation reads and writes rows of the register file W (n_vector, tile) by index:
# creating array views per instruction costs reference counting that, per row of a few
# hundred points, is as expensive as the arithmetic.


@njit(**INLINE)
def segsum_row(W, d, a, n, consts, base):
    """W[d] = 0.5 * sum over segments of selector * line, in the reference's order."""
    kind = consts[base]
    nseg = int(consts[base + 1])
    for k in range(n):
        x = W[a, k]
        total = 0.0
        for s in range(nseg):
            q = base + 2 + 6 * s
            sel = 1.0 - usign(x - consts[q]) * usign(x - consts[q + 1])
            if kind == 0.0:  # fcc: ((y1-y0) x + y0 x1 - y1 x0) / (x1 - x0)
                line = (consts[q + 2] * x + consts[q + 3] - consts[q + 4]) / consts[q + 5]
            else:  # fcc8: slope x + intercept
                line = consts[q + 2] * x + consts[q + 3]
            total = total + sel * line
        W[d, k] = 0.5 * total


@njit(**INLINE)
def _series_special(x):
    """The lanes :func:`series` takes the slow way: NaN, inf and |x| > 1e307."""
    return not (abs(x) <= 1e307)


@njit(**INLINE)
def _series_lanes(x, r, inv_r, fp):
    """:func:`series` without a branch, for the other lanes (the loop that calls it vectorises):
    three candidate segments around x/r, their index as a float (exact: out of [-p, p] a
    candidate is dropped whatever its value), the same operations as ``series`` on the one
    that holds x. At most one does: the segments [r(i-1), r i) tile the line, each bound the
    same product for both its segments. So which candidates are tried changes nothing as long
    as the one holding x is among them: x times 1/r (a multiplication instead of a division)
    is within a few ulps of x/r, and the window of three covers an index off by one. Far from
    [-p, p] (``series``'s early exit) no candidate is in range, so the sum is 0 there too."""
    i = np.floor(x * inv_r)
    out = _series_candidate(x, r, fp, i, 0.0)
    out = _series_candidate(x, r, fp, i + 1.0, out)
    return _series_candidate(x, r, fp, i + 2.0, out)


@njit(**INLINE)
def _series_candidate(x, r, fp, i, out):
    """``2(x - a) + 0`` when segment i, [a, b) = [r(i-1), r i), holds x and -p <= i <= p (as
    :func:`series` computes it), else ``out``: a select."""
    lo = r * (i - 1.0)
    hit = (i >= -fp) & (i <= fp) & (lo <= x) & (x < r * i)
    return (0.0 + 2.0 * (x - lo)) if hit else out


@njit(**INLINE)
def series_row(W, d, a, n, consts, base):
    r = consts[base]
    p = int(consts[base + 1])
    if consts[base + 2] != 0.0:
        for k in range(n):
            W[d, k] = series_exact(W[a, k], r, p)
        return
    # NaN, inf and huge lanes are rare: count them, save them (d may equal a), run the
    # branch-free loop over the row, then patch them the slow way.
    cnt = 0
    for k in range(n):
        cnt += 1 if _series_special(W[a, k]) else 0
    if cnt > 0:
        idx = np.empty(cnt, np.int64)
        val = np.empty(cnt, np.float64)
        j = 0
        for k in range(n):
            if _series_special(W[a, k]):
                idx[j] = k
                val[j] = W[a, k]
                j += 1
    fp = float(p)
    inv_r = 1.0 / r
    for k in range(n):
        W[d, k] = _series_lanes(W[a, k], r, inv_r, fp)
    if cnt > 0:
        for j in range(cnt):
            W[d, idx[j]] = series(val[j], r, p)
