"""The scalar kernels of surfgen's exp, log, pow, log10, sinh, cosh, tanh, asinh, acosh, atanh
and cbrt (:mod:`surfgen.generator.elementary.explog` has the algorithms and the public rows,
scalars and arrays): bit casts, exact (error-free) helpers, the double-double cores, and the
numpy twin of every kernel (the same code object re-bound to numpy helpers: the same bits).
"""

from __future__ import annotations

import math
import types as _pytypes

import numpy as np
from numba import njit
from numba.core.dispatcher import Dispatcher

from surfgen.generator.elementary import explog_exact
from surfgen.generator.elementary.explog_exact import (
    _f2i,
    _f2i_np,
    _fast_two_sum,
    _i2f,
    _i2f_np,
    _ldexp2,
    _rint52,
    _scale_dd,
    _sel,
    _sign_of,
    _trunc,
    _two_prod,
    _two_sum,
)
from surfgen.generator.elementary.explog_tables import (
    EQ0,
    EQ1,
    EQ2,
    EQ3,
    EQ4,
    EQ5,
    EQ6,
    EQ7,
    EQ8,
    EQ9,
    INF,
    INV_LN2,
    INV_LN10_H,
    INV_LN10_L,
    LC6H,
    LC6L,
    LC7H,
    LC7L,
    LC9H,
    LC9L,
    LC10H,
    LC10L,
    LC11H,
    LC11L,
    LH0,
    LH1,
    LH2,
    LH3,
    LH4,
    LK0,
    LK1,
    LK2,
    LK3,
    LK4,
    LN2_FULL_H,
    LN2_FULL_L,
    LN2_H,
    LN2_L,
    MASK26,
    MASK27,
    NAN,
    SHIFT,
    SHIFT_BITS,
    SQRT_HALF_BITS,
    SS0,
    SS1,
    SS2,
    SS3,
    SS4,
    SS5,
    SS6,
    THIRD,
    TINY_NORMAL,
    TT0,
    TT1,
    TT2,
    TT3,
    TT4,
    TT5,
    TT6,
    TWO28,
    TWO52,
    TWO53,
    TWO54,
    TWO_M28,
    TWO_THIRDS,
)
from surfgen.generator.jit.options import FORCE_INLINE

# ----------------------------------------------------------------------------- cores


@njit(**FORCE_INLINE)
def _log_reduce(xh, xl, tail):
    """x = 2^ef * c * (1 + s)/(1 - s): returns ef, jf = 8c and s = sh + sl (sh: 26 bits).

    xh > 0 finite (subnormals included). ``tail`` is a constant at each call site (the dead
    branches fold away once inlined): with it, xl is a tail |xl| <= ulp(xh), used only
    when 2^-1000 < xh < 2^1000; without it xl is ignored."""
    sub = xh < TINY_NORMAL
    xh = xh * _sel(sub, TWO54, 1.0)
    ix = _f2i(xh)
    e = (ix - SQRT_HALF_BITS) >> 52
    m = _i2f(ix - (e << 52))  # m in [sqrt(1/2), sqrt 2)
    ef = (_i2f(e + SHIFT_BITS) - SHIFT) - _sel(sub, 54.0, 0.0)  # float(e), no conversion
    jf = (m * 8.0 + TWO52) - TWO52  # rint(8m) in 6..11
    c = jf * 0.125
    f = m - c  # exact: |f| <= 1/16, a multiple of ulp(m)
    dh, dl = _fast_two_sum(c, m)  # exact: exponent(c) >= exponent(m) for every centre
    ml = 0.0
    if tail:
        ec = _sel(e > 1000, 1000, _sel(e < -1000, -1000, e))
        ml = xl * _i2f((1023 - ec) << 52)  # the tail scaled like m
        dl = dl + ml
    inv = 1.0 / dh
    # s = (f + ml)/(m + c + ml) = sh + sl; sh has 26 bits, so sh*dht and sh*(dh - dht) are
    # exact and f - sh*dht is exact (Sterbenz).
    sh = _trunc(f * inv, MASK26)
    dht = _trunc(dh, MASK27)
    rem = ((f - sh * dht) - sh * (dh - dht)) - sh * dl
    if tail:
        rem = rem + ml
    return ef, jf, sh, rem * inv


@njit(**FORCE_INLINE)
def _log_centre(jf):
    """log(jf/8) = ch + cl, ch on the 2^-42 grid of e * LN2_H (their sum is exact)."""
    is6 = jf == 6.0
    is7 = jf == 7.0
    is9 = jf == 9.0
    is10 = jf == 10.0
    is11 = jf == 11.0
    ch = _sel(
        is6, LC6H, _sel(is7, LC7H, _sel(is9, LC9H, _sel(is10, LC10H, _sel(is11, LC11H, 0.0))))
    )
    cl = _sel(
        is6, LC6L, _sel(is7, LC7L, _sel(is9, LC9L, _sel(is10, LC10L, _sel(is11, LC11L, 0.0))))
    )
    return ch, cl


@njit(**FORCE_INLINE)
def _log_dd(xh, xl, tail):
    """log(xh + xl) as a double-double (hi, lo), relative error about 2^-68 (see
    _log_reduce for the arguments)."""
    ef, jf, sh, sl = _log_reduce(xh, xl, tail)
    # 2 atanh(s) = (2/3) s G(s^2), G(w) = 3 + w + w^2 H(w); s^2 = q + dq with q = sh^2
    # exact (52 bits), so G(s^2) = 3 + q + r, r = dq + w^2 H(w), w = q + dq.
    q = sh * sh
    dq = (2.0 * sh + sl) * sl
    w = q + dq
    w2 = w * w
    r = dq + w2 * ((LH0 + w * LH1) + w2 * ((LH2 + w * LH3) + w2 * LH4))
    gh = _trunc((3.0 + q) + r, MASK27)
    gl = ((3.0 - gh) + q) + r  # (3 - gh) + q is exact
    u = sh * gh  # exact: 26 + 27 bits
    v = sh * gl + sl * (gh + gl)
    # (u + v)/3 with an exact remainder: 3*yh = p + pe exactly, u - p exact (Sterbenz).
    yh = u * THIRD
    p, pe = _fast_two_sum(2.0 * yh, yh)
    yl = (((u - p) - pe) + v) * THIRD
    ch, cl = _log_centre(jf)
    s1 = ef * LN2_H + ch  # exact; 0 or |s1| > 0.117 > |2 yh|: Fast2Sum below is exact
    s2, e2 = _fast_two_sum(s1, 2.0 * yh)
    lo = e2 + ((ef * LN2_L + cl) + 2.0 * yl)
    return _fast_two_sum(s2, lo)


@njit(**FORCE_INLINE)
def _log1(x):
    """log(x) rounded (about 0.5 ulp) for x > 0 finite: _log_dd's reduction, the series
    beyond 2s in plain double (it is below 2^-10 of the result)."""
    ef, jf, sh, sl = _log_reduce(x, 0.0, False)
    sf = sh + sl
    w = sf * sf
    w2 = w * w
    t = (sf * w) * (TWO_THIRDS + w * ((LK0 + w * LK1) + w2 * ((LK2 + w * LK3) + w2 * LK4)))
    ch, cl = _log_centre(jf)
    s1 = ef * LN2_H + ch
    s2, e2 = _fast_two_sum(s1, 2.0 * sh)
    return s2 + (e2 + ((ef * LN2_L + cl) + (2.0 * sl + t)))


@njit(**FORCE_INLINE)
def _exp_dd(zh, zl):
    """exp(zh + zl) = (ph + pl) * 2^k with ph + pl in [0.7, 1.42] to about 2^-59.

    |zl| <= 2^-24 |zh| (the reduced argument then stays within the fit interval). zh is clamped to [-746, 711] (the result then overflows or underflows
    the same way); NaN gives NaN ph."""
    zc = _sel(zh > 711.0, 711.0, zh)
    zc = _sel(zc < -746.0, -746.0, zc)
    zl = _sel(zc == zh, zl, 0.0)
    t = zc * INV_LN2 + SHIFT
    kf = t - SHIFT
    k = _f2i(t) - SHIFT_BITS
    r0 = zc - kf * LN2_H  # exact: kf has <= 11 bits, LN2_H 42, and r0 is a multiple of ulp
    rh, rl = _two_sum(r0, zl - kf * LN2_L)
    rt = _trunc(rh, MASK26)
    r2h = rt * rt  # exact; r2h + r2l = rh^2 to about 2^-80
    r2l = (rh - rt) * (rh + rt)
    # Q(rh) by Estrin's scheme: a shorter dependency chain than Horner's.
    r2 = rh * rh
    r4 = r2 * r2
    q01 = EQ0 + rh * EQ1
    q23 = EQ2 + rh * EQ3
    q45 = EQ4 + rh * EQ5
    q67 = EQ6 + rh * EQ7
    q89 = EQ8 + rh * EQ9
    qr = (q01 + r2 * q23) + r4 * ((q45 + r2 * q67) + r4 * q89)
    a1, a2 = _fast_two_sum(1.0, rh)
    b1, b2 = _fast_two_sum(a1, 0.5 * r2h)
    lo = (a2 + b2) + ((0.5 * r2l + (rh * r2) * qr) + (rl + rl * rh))
    ph, pl = _fast_two_sum(b1, lo)
    return ph, pl, k


# ----------------------------------------------------------------------------- functions


@njit(**FORCE_INLINE)
def _exp(x):
    ph, pl, k = _exp_dd(x, 0.0)
    return _sel(x != x, NAN, _scale_dd(ph, pl, k))


@njit(**FORCE_INLINE)
def _log(x):
    ok = (x > 0.0) & (x < INF)
    r = _log1(_sel(ok, x, 1.0))
    r = _sel(x == 0.0, -INF, _sel(x == INF, INF, r))
    return _sel((x < 0.0) | (x != x), NAN, r)


@njit(**FORCE_INLINE)
def _log10(x):
    ok = (x > 0.0) & (x < INF)
    lh, ll = _log_dd(_sel(ok, x, 1.0), 0.0, False)
    p, pe = _two_prod(lh, INV_LN10_H)
    r = p + (pe + (lh * INV_LN10_L + ll * INV_LN10_H))
    r = _sel(x == 0.0, -INF, _sel(x == INF, INF, r))
    return _sel((x < 0.0) | (x != x), NAN, r)


@njit(**FORCE_INLINE)
def _pow_general(x, y):
    """C pow by exp(y log|x|) (every x and y)."""
    ax = abs(x)
    ay = abs(y)
    lh, ll = _log_dd(_sel((ax > 0.0) & (ax < INF), ax, 1.0), 0.0, False)
    lh = _sel(ax == 0.0, -INF, _sel(ax == INF, INF, lh))
    # z = y * log|x| = zh + zl: with yh and lt of 26 bits, yh*lt and (y - yh)*lt are exact;
    # the tails (about 2^-25 |z|) go to zl, which exp reduces with the rest of its argument.
    yh = _trunc(y, MASK26)
    lt = _trunc(lh, MASK26)
    zh = _sel(abs(lh) < INF, yh * lt, y * lh)  # yh may be 0 (subnormal y): 0 * inf is NaN
    zl = _sel(abs(zh) < 2048.0, ((y - yh) * lt + y * (lh - lt)) + y * ll, 0.0)
    ph, pl, k = _exp_dd(zh, zl)
    r = _scale_dd(ph, pl, k)
    # Integer / odd-integer exponents (every |y| >= 2^52 is an even integer).
    yb = _sel(ay < TWO52, y, 0.0)
    nonint = (ay < TWO52) & (_rint52(yb) != y)
    hb = _sel(ay < TWO53, y * 0.5, 0.0)
    yodd = (nonint == False) & (ay < TWO53) & (_rint52(hb) != hb)  # noqa: E712
    r = _sel((_f2i(x) < 0) & yodd, -r, r)
    r = _sel((x < 0.0) & (x > -INF) & nonint, NAN, r)
    r = _sel((x != x) | (y != y), NAN, r)
    r = _sel((ax == 1.0) & (ay == INF), 1.0, r)  # pow(-1, ±inf) = 1
    return _sel((x == 1.0) | (y == 0.0), 1.0, r)  # pow(1, y) = pow(x, ±0) = 1, NaN included


# Exponents 1.5 and 3 (the eq. (13) sampler's lambda and mu besides the x^c shortcuts 2, 0.5,
# -1, 1, 0: every pow left in the per-point block of its formulas) by exact products instead of
# exp(y log|x|): about a quarter of the operations, within 0.5 ulp + 2^-100 (relative) of the
# exact power. Used where |x| is 0, inf, NaN or in [2^-300, 2^300], so that no product below
# overflows or underflows; other x take the general path.
POW_EXACT_LO = 2.0**-300
POW_EXACT_HI = 2.0**300


@njit(**FORCE_INLINE)
def _pow_exact_lane(x, y):
    """True where pow(x, y) is computed by :func:`_pow_exact` (y is 1.5 or 3)."""
    ax = abs(x)
    odd = ((ax > 0.0) & (ax < POW_EXACT_LO)) | ((ax > POW_EXACT_HI) & (ax < INF))
    return ((y == 1.5) | (y == 3.0)) & (odd == False)  # noqa: E712


@njit(**FORCE_INLINE)
def _pow15(x):
    """x^1.5 = x sqrt(x) for x = 0, inf, NaN or |x| in [2^-300, 2^300] (C99 values included).

    s = sqrt(x) rounded; x - s^2 = res exactly (s^2 by Dekker's product, x - q by Sterbenz), so
    sqrt(x) = s + res/(2s) + O(2^-106 s), and x sqrt(x) = x*s + x res/(2s), where x*s is an exact
    Dekker product and x/(2s) = s/2 to 2^-53: one final rounding."""
    ok = (x > 0.0) & (x < INF)
    xs = _sel(ok, x, 1.0)
    s = math.sqrt(xs)
    q, qe = _two_prod(s, s)
    res = (xs - q) - qe
    p, pe = _two_prod(xs, s)
    r = p + (pe + (0.5 * s) * res)
    r = _sel(x == 0.0, 0.0, r)  # pow(±0, 1.5) = +0
    r = _sel(abs(x) == INF, INF, r)  # pow(±inf, 1.5) = +inf
    return _sel(((x < 0.0) & (x > -INF)) | (x != x), NAN, r)


@njit(**FORCE_INLINE)
def _pow3(x):
    """x^3 for x = ±0, ±inf, NaN or |x| in [2^-300, 2^300]: x*x = q + qe and q*x = p + pe
    exactly (Dekker), x^3 = p + pe + qe*x with one final rounding."""
    ax = abs(x)
    ok = (ax > 0.0) & (ax < INF)
    xs = _sel(ok, x, 1.0)
    q, qe = _two_prod(xs, xs)
    p, pe = _two_prod(q, xs)
    r = p + (pe + qe * xs)
    return _sel(ok, r, _sel(x != x, NAN, x))  # ±0, ±inf: themselves (odd power)


@njit(**FORCE_INLINE)
def _pow_exact(x, y):
    return _sel(y == 3.0, _pow3(x), _pow15(x))


@njit(**FORCE_INLINE)
def _pow(x, y):
    """C pow: exact products for y in {1.5, 3} (:func:`_pow_exact_lane`), else exp(y log|x|)."""
    return _sel(_pow_exact_lane(x, y), _pow_exact(x, y), _pow_general(x, y))


@njit(**FORCE_INLINE)
def _sinh(x):
    ax = abs(x)
    w = ax * ax
    small = ax + ax * (
        w * (SS0 + w * (SS1 + w * (SS2 + w * (SS3 + w * (SS4 + w * (SS5 + w * SS6))))))
    )
    ph, pl, k = _exp_dd(_sel(ax < 711.0, ax, 711.0), 0.0)
    # 1/(ph + pl) as a double-double.
    qh = 1.0 / ph
    p, pe = _two_prod(qh, ph)
    ql = (((1.0 - p) - pe) - pl * qh) * qh
    ah = _ldexp2(ph, k - 1)
    al = _ldexp2(pl, k - 1)
    bh = _ldexp2(qh, -k - 1)
    bl = _ldexp2(ql, -k - 1)
    s, e = _two_sum(ah, -bh)
    big = _sel(s < INF, s + ((e + al) - bl), INF)  # the tail of an overflow is NaN
    r = _sign_of(x, _sel(ax < 0.25, small, big))
    return _sel(x != x, NAN, r)


@njit(**FORCE_INLINE)
def _cosh(x):
    ax = abs(x)
    ph, pl, k = _exp_dd(_sel(ax < 711.0, ax, 711.0), 0.0)
    qh = 1.0 / ph
    p, pe = _two_prod(qh, ph)
    ql = (((1.0 - p) - pe) - pl * qh) * qh
    ah = _ldexp2(ph, k - 1)
    al = _ldexp2(pl, k - 1)
    bh = _ldexp2(qh, -k - 1)
    bl = _ldexp2(ql, -k - 1)
    s, e = _two_sum(ah, bh)
    return _sel(x != x, NAN, _sel(s < INF, s + ((e + al) + bl), INF))


@njit(**FORCE_INLINE)
def _tanh(x):
    ax = abs(x)
    w = ax * ax
    small = ax + ax * (
        w * (TT0 + w * (TT1 + w * (TT2 + w * (TT3 + w * (TT4 + w * (TT5 + w * TT6))))))
    )
    # 1 - 2/(e^{2|x|} + 1) in double-double.
    ph, pl, k = _exp_dd(_sel(ax < 40.0, 2.0 * ax, 80.0), 0.0)
    eh = _ldexp2(ph, k)
    el = _ldexp2(pl, k)
    sh, sl = _fast_two_sum(eh, 1.0)
    sl = sl + el
    qh = 2.0 / sh
    p, pe = _two_prod(qh, sh)
    ql = (((2.0 - p) - pe) - qh * sl) / sh
    th, tl = _fast_two_sum(1.0, -qh)
    big = th + (tl - ql)
    r = _sign_of(x, _sel(ax < 0.125, small, big))
    return _sel(x != x, NAN, r)


@njit(**FORCE_INLINE)
def _sqrt_dd(uh, ul):
    """sqrt(uh + ul) as a double-double, uh > 0."""
    rh = math.sqrt(uh)
    p, pe = _two_prod(rh, rh)
    rl = (((uh - p) - pe) + ul) / (2.0 * rh)
    return rh, rl


@njit(**FORCE_INLINE)
def _asinh(x):
    ax = abs(x)
    big = ax > TWO28
    a = _sel(big, 1.0, ax)  # also sanitises inf and NaN
    # X = a + sqrt(a^2 + 1) as a double-double.
    s2h, s2l = _two_prod(a, a)
    uh, ul = _two_sum(s2h, 1.0)
    rh, rl = _sqrt_dd(uh, ul + s2l)
    xh, xl = _two_sum(a, rh)
    xh, xl = _fast_two_sum(xh, xl + rl)
    # Large |x|: log(2|x|) = log|x| + ln 2.
    xh = _sel(big & (ax < INF), ax, xh)
    xl = _sel(big, 0.0, xl)
    lh, ll = _log_dd(xh, xl, True)
    s, e = _two_sum(lh, _sel(big, LN2_FULL_H, 0.0))
    r = s + ((e + ll) + _sel(big, LN2_FULL_L, 0.0))
    r = _sel(ax < TWO_M28, ax, _sel(ax == INF, INF, r))
    return _sel(x != x, NAN, _sign_of(x, r))


@njit(**FORCE_INLINE)
def _acosh(x):
    big = x > TWO28
    a = _sel((x >= 1.0) & (big == False), x, 1.0)  # noqa: E712
    # X = a + sqrt(a^2 - 1); a^2 - 1 is exact as a double-double near 1.
    s2h, s2l = _two_prod(a, a)
    uh, ul = _two_sum(s2h, -1.0)
    ul = ul + s2l
    uz = uh == 0.0
    rh, rl = _sqrt_dd(_sel(uz, 1.0, uh), ul)
    rh = _sel(uz, 0.0, rh)
    rl = _sel(uz, 0.0, rl)
    xh, xl = _fast_two_sum(a, rh)
    xh, xl = _fast_two_sum(xh, xl + rl)
    xh = _sel(big & (x < INF), x, xh)
    xl = _sel(big, 0.0, xl)
    lh, ll = _log_dd(xh, xl, True)
    s, e = _two_sum(lh, _sel(big, LN2_FULL_H, 0.0))
    r = s + ((e + ll) + _sel(big, LN2_FULL_L, 0.0))
    r = _sel(x == INF, INF, r)
    return _sel((x < 1.0) | (x != x), NAN, r)


@njit(**FORCE_INLINE)
def _atanh(x):
    ax = abs(x)
    a = _sel(ax < 1.0, ax, 0.0)
    # X = (1 + a)/(1 - a) as a double-double; atanh = log(X)/2.
    nh, nl = _fast_two_sum(1.0, a)
    dh, dl = _fast_two_sum(1.0, -a)
    qh = nh / dh
    p, pe = _two_prod(qh, dh)
    ql = (((nh - p) - pe) + (nl - qh * dl)) / dh
    xh, xl = _fast_two_sum(qh, ql)
    lh, ll = _log_dd(xh, xl, True)
    r = 0.5 * lh
    r = _sel(ax < TWO_M28, ax, _sel(ax == 1.0, INF, r))
    r = _sign_of(x, r)
    return _sel((ax > 1.0) | (x != x), NAN, r)


@njit(**FORCE_INLINE)
def _cbrt(x):
    ax = abs(x)
    ok = (ax > 0.0) & (ax < INF)
    lh, ll = _log_dd(_sel(ok, ax, 1.0), 0.0, False)
    # (lh + ll)/3 with an exact remainder, then exp.
    zh = lh * THIRD
    p, pe = _fast_two_sum(2.0 * zh, zh)
    zl = (((lh - p) - pe) + ll) * THIRD
    ph, pl, k = _exp_dd(zh, zl)
    r = _sign_of(x, _ldexp2(ph, k))
    return _sel(ok, r, _sel(x != x, NAN, x))


# ----------------------------------------------------------------------------- numpy twins

_NP_GLOBALS: dict = {}


def _numpy_twin(fn):
    """The Python source of a numba kernel re-bound to numpy helpers: same operations."""
    py = fn.py_func
    return _pytypes.FunctionType(
        py.__code__, _NP_GLOBALS, py.__name__, py.__defaults__, py.__closure__
    )


# Every private numba kernel and helper, this module's and the exact helpers' (which call each
# other: _two_prod calls _split), gets a numpy twin under the same name; every constant either
# reads is there too.
_SCOPE = {**vars(explog_exact), **globals()}
_KERNELS = [
    name
    for name, obj in _SCOPE.items()
    if name.startswith("_") and isinstance(obj, Dispatcher) and name not in ("_f2i", "_i2f")
]

_NP_GLOBALS.update({k: v for k, v in _SCOPE.items() if k.isupper()})
_NP_GLOBALS.update({name: _numpy_twin(_SCOPE[name]) for name in _KERNELS})
_NP_GLOBALS.update(
    {
        "_sel": np.where,
        "_f2i": _f2i_np,
        "_i2f": _i2f_np,
        "math": _pytypes.SimpleNamespace(sqrt=np.sqrt),
    }
)

_CHUNK = 16384  # elements per numpy pass: temporaries stay in cache (L2)


def _apply1(kernel, x) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    flat = np.ascontiguousarray(arr).reshape(-1)
    out = np.empty_like(flat)
    with np.errstate(all="ignore"):
        for i in range(0, flat.size, _CHUNK):
            out[i : i + _CHUNK] = kernel(flat[i : i + _CHUNK])
    return out.reshape(arr.shape)


def _apply2(kernel, x, y) -> np.ndarray:
    a, b = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    fa = np.ascontiguousarray(a).reshape(-1)
    fb = np.ascontiguousarray(b).reshape(-1)
    out = np.empty_like(fa)
    with np.errstate(all="ignore"):
        for i in range(0, fa.size, _CHUNK):
            out[i : i + _CHUNK] = kernel(fa[i : i + _CHUNK], fb[i : i + _CHUNK])
    return out.reshape(a.shape)
