"""The interval rules that run over whole rows of boxes: the functions whose rule needs an
elementary function at the ends of the input intervals (monotone ones, the periodic ones and
those with poles or jumps, pow, atan2) and the constituents' piecewise sums (series, segment
sums). :mod:`surfgen.generator.eval.interval_kernels` dispatches to them.

Registers: ``L[r]``, ``H[r]`` (bounds) and ``N[r]`` (1 where a value may be NaN), column k for
box k. The function values at the ends are the very rows of the point interpreter
(:func:`surfgen.generator.eval.row_calls.far_row` on rows of the scratch ``T``): the same bits.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.eval.interval_rules import (
    EMPTY_HI,
    EMPTY_LO,
    INF,
    PI,
    TWO_PI,
    atan2_corners_ok,
    contains0,
    down,
    down_rt,
    has_inf,
    hull,
    hull4,
    is_int,
    is_odd,
    may_hit,
    recip_rule,
    square_rule,
    up,
    up_rt,
)
from surfgen.generator.eval.row_calls import SLOT, far_row
from surfgen.generator.jit.options import KERNEL

S_ATAN2, S_POW = SLOT["atan2_vv"], SLOT["pow_vv"]


@njit(**KERNEL)
def put(L, H, N, d, k, lo, hi, nan):
    L[d, k] = lo
    H[d, k] = hi
    N[d, k] = 1 if nan else 0


@njit(**KERNEL)
def ends(slot, L, H, a, T, n, consts, clo, chi):
    """T[2] = f(lo clamped to [clo, chi]), T[3] = f(hi clamped), f the row of ``slot``."""
    for k in range(n):
        T[0, k] = min(max(L[a, k], clo), chi)
        T[1, k] = min(max(H[a, k], clo), chi)
    far_row(slot, T, 2, 0, 0, 0.0, n, consts, 0)
    far_row(slot, T, 3, 1, 0, 0.0, n, consts, 0)


@njit(**KERNEL)
def monotone(slot, L, H, N, d, a, n, consts, T, dlo, dhi, increasing):
    """A function monotone on its domain ``[dlo, dhi]`` (NaN outside it)."""
    ends(slot, L, H, a, T, n, consts, dlo, dhi)
    for k in range(n):
        lo = L[a, k]
        hi = H[a, k]
        if lo > dhi or hi < dlo or lo > hi:
            put(L, H, N, d, k, EMPTY_LO, EMPTY_HI, True)
            continue
        nan = N[a, k] != 0 or lo < dlo or hi > dhi
        if increasing:
            put(L, H, N, d, k, down(T[2, k]), up(T[3, k]), nan)
        else:
            put(L, H, N, d, k, down(T[3, k]), up(T[2, k]), nan)


@njit(**KERNEL)
def wave(slot, L, H, N, d, a, n, consts, T, off_max, off_min, vmin, vmax, rt):
    """A continuous periodic function (sin, cos, asin(sin), acos(cos)): its maxima at
    ``off_max + 2 pi j``, its minima at ``off_min + 2 pi j``, monotone between; NaN at ±inf."""
    ends(slot, L, H, a, T, n, consts, -INF, INF)
    for k in range(n):
        lo = L[a, k]
        hi = H[a, k]
        nan = N[a, k] != 0 or has_inf(lo, hi)
        f0 = min(T[2, k], T[3, k])
        f1 = max(T[2, k], T[3, k])
        olo = down_rt(f0) if rt else down(f0)
        ohi = up_rt(f1) if rt else up(f1)
        if may_hit(lo, hi, off_max, TWO_PI):
            ohi = vmax
        if may_hit(lo, hi, off_min, TWO_PI):
            olo = vmin
        put(L, H, N, d, k, olo, ohi, nan)


@njit(**KERNEL)
def jumps(slot, L, H, N, d, a, n, consts, T, off, vmin, vmax, increasing, rt):
    """A function monotone between jumps (or poles) at ``off + pi j``: tan, cot, atan(tan),
    acot(cot); ``[vmin, vmax]`` where a jump may fall inside; NaN at ±inf."""
    ends(slot, L, H, a, T, n, consts, -INF, INF)
    for k in range(n):
        lo = L[a, k]
        hi = H[a, k]
        nan = N[a, k] != 0 or has_inf(lo, hi)
        if may_hit(lo, hi, off, PI):
            put(L, H, N, d, k, vmin, vmax, nan)
            continue
        f0 = T[2, k] if increasing else T[3, k]
        f1 = T[3, k] if increasing else T[2, k]
        if rt:
            put(L, H, N, d, k, down_rt(f0), up_rt(f1), nan)
        else:
            put(L, H, N, d, k, down(f0), up(f1), nan)


@njit(**KERNEL)
def series_rows(L, H, N, d, a, n, consts, base):
    """The sum of eqs. (2)-(4) (row_operations.series): ``2 (x - r(i-1))`` on the segment
    ``[r(i-1), r i)`` that holds x, ``-p <= i <= p``; 0 elsewhere."""
    r = consts[base]
    p = consts[base + 1]
    exact = consts[base + 2] != 0.0
    top = up(2.0 * r + 4.0 * abs(r * (p + 1.0)) * 2.0**-52)
    left = r * (-p - 1.0)
    right = r * p
    for k in range(n):
        lo = L[a, k]
        hi = H[a, k]
        nan = N[a, k] != 0 or not (max(abs(lo), abs(hi)) <= 1e307)
        if exact:
            put(L, H, N, d, k, -INF, INF, True)
            continue
        if hi < left or lo >= right:
            put(L, H, N, d, k, 0.0, 0.0, nan)
            continue
        done = False
        if not nan:
            i0 = np.floor(lo / r) + 1.0
            for i in (i0 - 1.0, i0, i0 + 1.0):
                a0 = r * (i - 1.0)
                b0 = r * i
                if -p <= i and i <= p and a0 <= lo and lo < b0 and hi < b0:
                    put(L, H, N, d, k, 0.0 + 2.0 * (lo - a0), 0.0 + 2.0 * (hi - a0), nan)
                    done = True
                    break
        if not done:
            put(L, H, N, d, k, 0.0, top, nan)


@njit(**KERNEL)
def line(consts, q, kind, x):
    if kind == 0.0:
        return (consts[q + 2] * x + consts[q + 3] - consts[q + 4]) / consts[q + 5]
    return consts[q + 2] * x + consts[q + 3]


@njit(**KERNEL)
def segsum_rows(L, H, N, d, a, n, consts, base):
    """Segment sums (fcc, fcc8): half the selected segment's line ``0.5 (0 + 2 line(x))`` on
    ``[x0, x1)``, 0 outside every segment; NaN where some line is not finite (``0 * inf``)."""
    kind = consts[base]
    nseg = int(consts[base + 1])
    first = consts[base + 2]
    last = consts[base + 2 + 6 * (nseg - 1) + 1]
    gaps = False
    for s in range(nseg - 1):
        q = base + 2 + 6 * s
        if consts[q + 1] != consts[q + 6]:
            gaps = True
    for k in range(n):
        lo = L[a, k]
        hi = H[a, k]
        nan = N[a, k] != 0
        olo = INF
        ohi = -INF
        if lo < first or hi >= last or gaps:
            olo = 0.0
            ohi = 0.0
        for s in range(nseg):
            q = base + 2 + 6 * s
            v0 = line(consts, q, kind, lo)
            v1 = line(consts, q, kind, hi)
            if not (abs(v0) < INF and abs(v1) < INF):
                nan = True
            x0 = max(lo, consts[q])
            x1 = min(hi, consts[q + 1])
            if x0 <= x1 and lo < consts[q + 1] and hi >= consts[q]:
                w0 = 0.5 * (0.0 + 2.0 * line(consts, q, kind, x0))
                w1 = 0.5 * (0.0 + 2.0 * line(consts, q, kind, x1))
                if w0 != w0 or w1 != w1:
                    nan = True
                    olo, ohi = -INF, INF
                else:
                    olo, ohi = hull(olo, ohi, min(w0, w1), max(w0, w1))
        put(L, H, N, d, k, olo, ohi, nan)


@njit(**KERNEL)
def pow_const(L, H, N, d, a, e, T, k):
    """Box k of ``u^e`` with a constant exponent e: T[4], T[5] hold pow at the ends of u
    (clamped to 0 from below for a non-integer e)."""
    lo = L[a, k]
    hi = H[a, k]
    an = N[a, k] != 0
    if e == 0.0:  # the x^c convention: 1 whatever u, NaN too
        put(L, H, N, d, k, 1.0, 1.0, False)
        return
    if lo > hi:
        put(L, H, N, d, k, EMPTY_LO, EMPTY_HI, True)
        return
    if e == 1.0:
        put(L, H, N, d, k, lo, hi, an)
        return
    if e == 2.0:
        s0, s1 = square_rule(lo, hi)
        put(L, H, N, d, k, s0, s1, an)
        return
    if e == -1.0:
        r0, r1 = recip_rule(lo, hi)
        put(L, H, N, d, k, r0, r1, an)
        return
    if e == 0.5:
        if hi < 0.0:
            put(L, H, N, d, k, EMPTY_LO, EMPTY_HI, True)
        else:
            put(L, H, N, d, k, np.sqrt(max(lo, 0.0)), np.sqrt(hi), an or lo < 0.0)
        return
    p0 = T[4, k]
    p1 = T[5, k]
    if not (abs(e) < INF):
        put(L, H, N, d, k, 0.0, INF, an)
        return
    z = contains0(lo, hi)
    if is_int(e) and not is_odd(e):  # even: |u|^e
        if e > 0.0:
            o0 = 0.0 if z else min(p0, p1)
            put(L, H, N, d, k, down(o0), up(max(p0, p1)), an)
        else:
            o1 = INF if z else max(p0, p1)
            put(L, H, N, d, k, down(min(p0, p1)), up(o1), an)
        return
    if is_odd(e):
        if e > 0.0:
            put(L, H, N, d, k, down(p0), up(p1), an)
        elif z:
            put(L, H, N, d, k, -INF, INF, an)
        else:
            put(L, H, N, d, k, down(p1), up(p0), an)
        return
    # a non-integer exponent: NaN below 0 but at -inf; T[4] is pow at max(lo, 0)
    nan = an or lo < 0.0
    olo = INF
    ohi = -INF
    if hi >= 0.0:
        if e > 0.0:
            olo, ohi = down(p0), up(p1)
        else:
            olo, ohi = down(p1), up(p0)
    if lo == -INF:
        v = INF if e > 0.0 else 0.0
        olo, ohi = hull(olo, ohi, v, v)
    put(L, H, N, d, k, olo, ohi, nan)


@njit(**KERNEL)
def pow_rows(L, H, N, d, a, b, n, consts, T):
    """``u^e`` (surfgen's pow with the x^c convention)."""
    for k in range(n):
        lo = L[a, k]
        hi = H[a, k]
        const_e = L[b, k] == H[b, k] and N[b, k] == 0
        e = L[b, k]
        if const_e and not is_int(e) and abs(e) < INF:
            lo = max(lo, 0.0)  # the non-integer exponent's NaN side is handled apart
            hi = max(hi, 0.0)
        T[0, k] = lo
        T[1, k] = hi
        T[2, k] = L[b, k]
        T[3, k] = H[b, k]
    far_row(S_POW, T, 4, 0, 2, 0.0, n, consts, 0)
    far_row(S_POW, T, 5, 1, 2, 0.0, n, consts, 0)
    far_row(S_POW, T, 6, 0, 3, 0.0, n, consts, 0)
    far_row(S_POW, T, 7, 1, 3, 0.0, n, consts, 0)
    for k in range(n):
        alo = L[a, k]
        ahi = H[a, k]
        blo = L[b, k]
        bhi = H[b, k]
        if blo == bhi and N[b, k] == 0:
            pow_const(L, H, N, d, a, blo, T, k)
            continue
        if alo > ahi or blo > bhi:  # pow(NaN, 0) = pow(1, NaN) = 1
            put(L, H, N, d, k, 1.0, 1.0, True)
            continue
        nan = N[a, k] != 0 or N[b, k] != 0
        if alo >= 0.0:
            olo, ohi, bad = hull4(T[4, k], T[5, k], T[6, k], T[7, k])
            olo = down(olo)
            ohi = up(ohi)
            if alo == 0.0 and blo < 0.0:  # pow(-0, -odd) = -inf; 1/-0 too
                olo = -INF
            if nan:
                olo, ohi = hull(olo, ohi, 1.0, 1.0)
            put(L, H, N, d, k, olo, ohi, nan or bad)
        else:
            put(L, H, N, d, k, -INF, INF, True)


@njit(**KERNEL)
def atan2_rows(L, H, N, d, a, b, n, consts, T):
    for k in range(n):
        T[0, k] = L[a, k]
        T[1, k] = H[a, k]
        T[2, k] = L[b, k]
        T[3, k] = H[b, k]
    far_row(S_ATAN2, T, 4, 0, 2, 0.0, n, consts, 0)
    far_row(S_ATAN2, T, 5, 0, 3, 0.0, n, consts, 0)
    far_row(S_ATAN2, T, 6, 1, 2, 0.0, n, consts, 0)
    far_row(S_ATAN2, T, 7, 1, 3, 0.0, n, consts, 0)
    for k in range(n):
        nan = N[a, k] != 0 or N[b, k] != 0
        if atan2_corners_ok(L[a, k], H[a, k], L[b, k], H[b, k]):
            lo, hi, bad = hull4(T[4, k], T[5, k], T[6, k], T[7, k])
            put(L, H, N, d, k, down(lo), up(hi), nan or bad)
        else:
            put(L, H, N, d, k, down(-PI), up(PI), nan)
