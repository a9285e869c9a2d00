"""surfgen's own exp, log, pow and the functions built from them.

exp, log, pow (real exponents), log10, sinh, cosh, tanh, asinh, acosh, atanh, cbrt — each
written once as branch-free scalar arithmetic (``_exp``, ``_log``, ...) and run three ways:

- ``NAME_row(W, d, a, n)`` / ``NAME_scalar(x)``: numba, the kernel inlined into a loop that
  LLVM vectorises (no calls, selects instead of branches, no float<->int conversions);
- ``NAME_array(x)``: plain numpy, *the same Python function object's code* re-bound to numpy
  helpers (``_sel`` -> ``np.where``, bit casts -> ``.view``), hence the same IEEE operation
  sequence and the same bits on every CPU. No FMA anywhere (numpy has none): exact products
  use Veltkamp/Dekker splitting or operands truncated to 26/27 bits.

Every special value is handled by selects inside the kernel (there is no slow path): NaN,
±inf, ±0, subnormals, overflow, gradual underflow, and every C99 Annex F case of ``pow``.
Every NaN result is the canonical quiet NaN ``0x7ff8000000000000`` (NaN payloads would
otherwise depend on how the compiler orders commutative operands).

Algorithms (derived from the literature; coefficients from ``benchmarks/explog_coefficients.py``):

- ``log`` (double-double, relative error about 2^-68): x = 2^e m with m in [sqrt(1/2), sqrt 2),
  centre c = rint(8m)/8 (six values, log c from a select chain as double-double),
  f = m - c exact, s = f/(m + c) as sh + sl with sh truncated to 26 bits so that the products
  that form the remainder are exact, log(m/c) = 2 atanh(s) = (2/3) s G(s^2) with
  G(q) = 3 + q + q^2 H(q) (H: degree 4) kept as a 27-bit head plus an exact tail, then the
  division by 3 with an exact remainder. log returns the rounded head (about 0.5 ulp).
- ``exp`` of a double-double z (Cody–Waite): k = rint(z/ln2) by the 1.5*2^52 shifter,
  r = z - k ln2 with ln2 in 42 + 53 bits (the first product and difference are exact),
  e^r = 1 + r + r^2/2 + r^3 Q(r) (Q: degree 9) with r^2 exact, summed as a double-double,
  scaled by 2^k with two multiplications so that overflow and gradual underflow are IEEE's.
- ``pow(x, y) = exp(y log|x|)`` with y*log|x| as an exact Dekker product plus tails.
- log10 = log * (1/ln10 as double-double); sinh, cosh, tanh from the double-double exp
  (odd polynomials near 0 for sinh and tanh); asinh, acosh, atanh as log of a double-double
  argument; cbrt = exp(log|x| / 3) with the division by 3 kept exact.
"""

from __future__ import annotations

import math
import types as _pytypes

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

__all__ = [
    f"{name}_{kind}"
    for name in (
        "exp",
        "log",
        "log10",
        "sinh",
        "cosh",
        "tanh",
        "asinh",
        "acosh",
        "atanh",
        "cbrt",
    )
    for kind in ("row", "scalar", "array")
] + ["pow_row_vv", "pow_row_vs", "pow_row_sv", "pow_scalar", "pow_array"]

_OPTS = {"cache": True, "error_model": "numpy", "nogil": True}
# Kernels are inlined into the loops at numba IR level: LLVM vectorises only call-free bodies.
_INL = {**_OPTS, "forceinline": True}

# ----------------------------------------------------------------------------- constants

INF = math.inf
NAN = math.nan  # 0x7ff8000000000000
SHIFT = 6755399441055744.0  # 1.5 * 2^52: x + SHIFT rounds x to an integer held in the low bits
SHIFT_BITS = 0x4338000000000000
TWO52 = 4503599627370496.0
TWO53 = 9007199254740992.0
SPLITTER = 134217729.0  # 2^27 + 1 (Veltkamp)
MASK26 = -(1 << 27)  # keep sign, exponent and 25 explicit mantissa bits: 26 significant bits
MASK27 = -(1 << 26)
INV_LN2 = 1.4426950408889634
LN2_H = 0.6931471805598903  # ln 2 rounded to 42 bits: k * LN2_H is exact for |k| < 2^11
LN2_L = 5.497923018708371e-14
LN2_FULL_H = 0.6931471805599453
LN2_FULL_L = 2.3190468138462996e-17
INV_LN10_H = 0.4342944819032518
INV_LN10_L = 1.098319650216765e-17
THIRD = 0.3333333333333333
SQRT_HALF_BITS = 0x3FE6A09E667F3BCD
TINY_NORMAL = 2.2250738585072014e-308
TWO54 = 18014398509481984.0
TWO28 = 268435456.0
TWO_M28 = 3.725290298461914e-09
TWO996 = 2.0**996

# log(j/8), j = 6..11, as double-doubles.
LC6H, LC6L = -0.2876820724517809, -2.607160616442564e-17
LC7H, LC7L = -0.13353139262452263, 3.664457663660085e-18
LC9H, LC9L = 0.11778303565638346, -1.1971685747593677e-18
LC10H, LC10L = 0.22314355131420976, -9.091270597324799e-18
LC11H, LC11L = 0.3184537311185346, 2.7114779367326236e-17

# Q(r) = (e^r - 1 - r - r^2/2)/r^3 on |r| <= 0.3467, degree 9, |r^3 dQ| < 2^-60.3.
EQ0 = 0.16666666666666669
EQ1 = 0.041666666666666664
EQ2 = 0.008333333333330055
EQ3 = 0.0013888888888886548
EQ4 = 0.00019841269863088255
EQ5 = 2.4801587317169235e-05
EQ6 = 2.7557268406190795e-06
EQ7 = 2.7557282931125736e-07
EQ8 = 2.51004110820149e-08
EQ9 = 2.091125490208877e-09

# H(q) = (3 atanh(sqrt q)/sqrt q - 3 - q)/q^2 on q <= 0.04^2, degree 4, |q^2 dH| < 2^-73.
LH0 = 0.6
LH1 = 0.4285714285713001
LH2 = 0.3333333339754841
LH3 = 0.2727261493317481
LH4 = 0.23157106960641805

# S(w) = (sinh(sqrt w) - sqrt w)/w^1.5 on w <= 0.5^2, degree 6, |w^1.5 dS| < 2^-59.6.
SS0 = 0.16666666666666666
SS1 = 0.008333333333333333
SS2 = 0.00019841269841269893
SS3 = 2.755731922385946e-06
SS4 = 2.5052108529916113e-08
SS5 = 1.605895909905728e-10
SS6 = 7.671802234064814e-13

# T(w) = (tanh(sqrt w) - sqrt w)/w^1.5 on w <= 0.125^2, degree 6, |w^1.5 dT| < 2^-64.6.
TT0 = -0.3333333333333333
TT1 = 0.13333333333333322
TT2 = -0.053968253968151046
TT3 = 0.021869488496608067
TT4 = -0.008863228290024993
TT5 = 0.0035914470237015917
TT6 = -0.0014239969035219852

# ----------------------------------------------------------------------------- bit casts


@intrinsic
def _f2i(typingctx, x):
    """The bits of a float64 as an int64 (an LLVM bitcast: vectorises)."""
    sig = types.int64(types.float64)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))

    return sig, codegen


@intrinsic
def _i2f(typingctx, i):
    """The float64 whose bits are the int64 ``i``."""
    sig = types.float64(types.int64)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return sig, codegen


def _f2i_np(x):
    return np.asarray(x, dtype=np.float64).view(np.int64)


def _i2f_np(i):
    return np.asarray(i, dtype=np.int64).view(np.float64)


# ----------------------------------------------------------------------------- exact helpers
# Every helper and kernel below is written once; ``_numpy_twin`` re-binds its code to numpy.


@njit(**_INL)
def _sel(c, a, b):
    """``a if c else b`` with both operands already computed (an LLVM select)."""
    return a if c else b


@njit(**_INL)
def _two_sum(a, b):
    """s + e == a + b exactly (Knuth)."""
    s = a + b
    bb = s - a
    e = (a - (s - bb)) + (b - bb)
    return s, e


@njit(**_INL)
def _fast_two_sum(a, b):
    """s + e == a + b exactly when |a| >= |b| or a == 0 (Dekker)."""
    s = a + b
    e = b - (s - a)
    return s, e


@njit(**_INL)
def _split(a):
    """a == hi + lo with 26-bit halves (Veltkamp); |a| < 2^996."""
    c = SPLITTER * a
    hi = c - (c - a)
    return hi, a - hi


@njit(**_INL)
def _two_prod(a, b):
    """p + e == a * b exactly (Dekker, no FMA)."""
    p = a * b
    ah, al = _split(a)
    bh, bl = _split(b)
    e = ((ah * bh - p) + ah * bl + al * bh) + al * bl
    return p, e


@njit(**_INL)
def _trunc(v, mask):
    """v with its low mantissa bits cleared (fewer significant bits: exact products)."""
    return _i2f(_f2i(v) & mask)


@njit(**_INL)
def _rint52(v):
    """Round to the nearest integer, ties to even; exact for |v| < 2^52."""
    s = _sel(v < 0.0, -TWO52, TWO52)
    return (v + s) - s


@njit(**_INL)
def _ldexp2(v, k):
    """v * 2^k for |k| <= 2100 as two exact-or-IEEE-rounded multiplications."""
    k1 = k >> 1
    k2 = k - k1
    return (v * _i2f((k1 + 1023) << 52)) * _i2f((k2 + 1023) << 52)


@njit(**_INL)
def _sign_of(x, r):
    """r with the sign bit of x (x's sign bit set: -r)."""
    return _sel(_f2i(x) < 0, -r, r)


# ----------------------------------------------------------------------------- cores


@njit(**_INL)
def _log_dd(xh, xl):
    """log(xh + xl) as a double-double (hi, lo), relative error about 2^-68.

    xh > 0 finite (subnormals included); xl is a tail |xl| <= ulp(xh), used only when
    2^-1000 < xh < 2^1000."""
    sub = xh < TINY_NORMAL
    sc = _sel(sub, TWO54, 1.0)
    xh = xh * sc
    xl = xl * sc
    ix = _f2i(xh)
    e = (ix - SQRT_HALF_BITS) >> 52
    m = _i2f(ix - (e << 52))  # m in [sqrt(1/2), sqrt 2)
    ec = _sel(e > 1000, 1000, _sel(e < -1000, -1000, e))
    ml = xl * _i2f((1023 - ec) << 52)  # the tail scaled like m
    ef = (_i2f(e + SHIFT_BITS) - SHIFT) - _sel(sub, 54.0, 0.0)  # float(e), no conversion
    jf = (m * 8.0 + TWO52) - TWO52  # rint(8m) in 6..11
    c = jf * 0.125
    f = m - c  # exact: |f| <= 1/16, a multiple of ulp(m)
    dh, dl = _two_sum(m, c)
    dl = dl + ml
    inv = 1.0 / dh
    # s = (f + ml)/(m + c + ml) = sh + sl; sh has 26 bits, so sh*dht and sh*dhr are exact
    # and f - sh*dht is exact (Sterbenz).
    sh = _trunc(f * inv, MASK26)
    dht = _trunc(dh, MASK27)
    dhr = dh - dht
    rem = ((f - sh * dht) - sh * dhr) + (ml - sh * dl)
    sl = rem * inv
    # 2 atanh(s) = (2/3) s G(s^2), G(w) = 3 + w + w^2 H(w); s^2 = q + dq with q = sh^2
    # exact (52 bits), so G(s^2) = 3 + q + r, r = dq + w^2 H(w), w = q + dq.
    q = sh * sh
    dq = (2.0 * sh + sl) * sl
    w = q + dq
    r = dq + w * w * (LH0 + w * (LH1 + w * (LH2 + w * (LH3 + w * LH4))))
    gh = _trunc((3.0 + q) + r, MASK27)
    gl = ((3.0 - gh) + q) + r  # (3 - gh) + q is exact
    u = sh * gh  # exact: 26 + 27 bits
    v = sh * gl + sl * (gh + gl)
    # (u + v)/3 with an exact remainder: 3*yh = p + pe exactly, u - p exact (Sterbenz).
    yh = u * THIRD
    p, pe = _fast_two_sum(2.0 * yh, yh)
    yl = (((u - p) - pe) + v) * THIRD
    ch = _sel(
        jf == 6.0,
        LC6H,
        _sel(
            jf == 7.0,
            LC7H,
            _sel(jf == 9.0, LC9H, _sel(jf == 10.0, LC10H, _sel(jf == 11.0, LC11H, 0.0))),
        ),
    )
    cl = _sel(
        jf == 6.0,
        LC6L,
        _sel(
            jf == 7.0,
            LC7L,
            _sel(jf == 9.0, LC9L, _sel(jf == 10.0, LC10L, _sel(jf == 11.0, LC11L, 0.0))),
        ),
    )
    s1, e1 = _two_sum(ef * LN2_H, ch)  # ef * LN2_H is exact
    s2, e2 = _two_sum(s1, 2.0 * yh)
    lo = (e1 + e2) + ((ef * LN2_L + cl) + 2.0 * yl)
    return _fast_two_sum(s2, lo)


@njit(**_INL)
def _exp_dd(zh, zl):
    """exp(zh + zl) = (ph + pl) * 2^k with ph + pl in [0.7, 1.42] to about 2^-59.

    |zl| <= ulp(zh). zh is clamped to [-746, 711] (the result then overflows or underflows
    the same way); NaN gives NaN ph."""
    zc = _sel(zh > 711.0, 711.0, zh)
    zc = _sel(zc < -746.0, -746.0, zc)
    zl = _sel(zc == zh, zl, 0.0)
    t = zc * INV_LN2 + SHIFT
    kf = t - SHIFT
    k = _f2i(t) - SHIFT_BITS
    r0 = zc - kf * LN2_H  # exact: kf has <= 11 bits, LN2_H 42, and r0 is a multiple of ulp
    rh, rl = _two_sum(r0, zl - kf * LN2_L)
    r2h, r2l = _two_prod(rh, rh)
    qr = EQ0 + rh * (
        EQ1
        + rh
        * (
            EQ2
            + rh * (EQ3 + rh * (EQ4 + rh * (EQ5 + rh * (EQ6 + rh * (EQ7 + rh * (EQ8 + rh * EQ9))))))
        )
    )
    a1, a2 = _fast_two_sum(1.0, rh)
    b1, b2 = _fast_two_sum(a1, 0.5 * r2h)
    lo = (a2 + b2) + ((0.5 * r2l + (rh * r2h) * qr) + (rl + rl * rh))
    ph, pl = _fast_two_sum(b1, lo)
    return ph, pl, k


# ----------------------------------------------------------------------------- functions


@njit(**_INL)
def _exp(x):
    ph, pl, k = _exp_dd(x, 0.0)
    return _sel(x != x, NAN, _ldexp2(ph, k))


@njit(**_INL)
def _log(x):
    ok = (x > 0.0) & (x < INF)
    lh, ll = _log_dd(_sel(ok, x, 1.0), 0.0)
    r = _sel(x == 0.0, -INF, _sel(x == INF, INF, lh))
    return _sel((x < 0.0) | (x != x), NAN, r)


@njit(**_INL)
def _log10(x):
    ok = (x > 0.0) & (x < INF)
    lh, ll = _log_dd(_sel(ok, x, 1.0), 0.0)
    p, pe = _two_prod(lh, INV_LN10_H)
    r = p + (pe + (lh * INV_LN10_L + ll * INV_LN10_H))
    r = _sel(x == 0.0, -INF, _sel(x == INF, INF, r))
    return _sel((x < 0.0) | (x != x), NAN, r)


@njit(**_INL)
def _pow(x, y):
    ax = abs(x)
    ay = abs(y)
    lh, ll = _log_dd(_sel((ax > 0.0) & (ax < INF), ax, 1.0), 0.0)
    lh = _sel(ax == 0.0, -INF, _sel(ax == INF, INF, lh))
    # z = y * log|x| = zh + zl with an exact product (y split only where that cannot overflow).
    ysp = _sel(ay < TWO996, y, 0.0)
    zh = y * lh
    p, pe = _two_prod(ysp, lh)
    zl = _sel(abs(zh) < 2048.0, pe + ysp * ll, 0.0)
    ph, pl, k = _exp_dd(zh, zl)
    r = _ldexp2(ph, k)
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


@njit(**_INL)
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
    r = _sign_of(x, _sel(ax < 0.5, small, big))
    return _sel(x != x, NAN, r)


@njit(**_INL)
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


@njit(**_INL)
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


@njit(**_INL)
def _sqrt_dd(uh, ul):
    """sqrt(uh + ul) as a double-double, uh > 0."""
    rh = math.sqrt(uh)
    p, pe = _two_prod(rh, rh)
    rl = (((uh - p) - pe) + ul) / (2.0 * rh)
    return rh, rl


@njit(**_INL)
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
    lh, ll = _log_dd(xh, xl)
    s, e = _two_sum(lh, _sel(big, LN2_FULL_H, 0.0))
    r = s + ((e + ll) + _sel(big, LN2_FULL_L, 0.0))
    r = _sel(ax < TWO_M28, ax, _sel(ax == INF, INF, r))
    return _sel(x != x, NAN, _sign_of(x, r))


@njit(**_INL)
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
    lh, ll = _log_dd(xh, xl)
    s, e = _two_sum(lh, _sel(big, LN2_FULL_H, 0.0))
    r = s + ((e + ll) + _sel(big, LN2_FULL_L, 0.0))
    r = _sel(x == INF, INF, r)
    return _sel((x < 1.0) | (x != x), NAN, r)


@njit(**_INL)
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
    lh, ll = _log_dd(xh, xl)
    r = 0.5 * lh
    r = _sel(ax < TWO_M28, ax, _sel(ax == 1.0, INF, r))
    r = _sign_of(x, r)
    return _sel((ax > 1.0) | (x != x), NAN, r)


@njit(**_INL)
def _cbrt(x):
    ax = abs(x)
    ok = (ax > 0.0) & (ax < INF)
    lh, ll = _log_dd(_sel(ok, ax, 1.0), 0.0)
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


_KERNELS = [
    "_sel",
    "_two_sum",
    "_fast_two_sum",
    "_split",
    "_two_prod",
    "_trunc",
    "_rint52",
    "_ldexp2",
    "_sign_of",
    "_log_dd",
    "_exp_dd",
    "_exp",
    "_log",
    "_log10",
    "_pow",
    "_sinh",
    "_cosh",
    "_tanh",
    "_sqrt_dd",
    "_asinh",
    "_acosh",
    "_atanh",
    "_cbrt",
]

_NP_GLOBALS.update({k: v for k, v in globals().items() if k.isupper()})
_NP_GLOBALS.update({name: _numpy_twin(globals()[name]) for name in _KERNELS})
_NP_GLOBALS.update(
    {
        "_sel": np.where,
        "_f2i": _f2i_np,
        "_i2f": _i2f_np,
        "math": _pytypes.SimpleNamespace(sqrt=np.sqrt),
    }
)

_CHUNK = 4096  # elements per numpy pass: temporaries stay in cache


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


# ----------------------------------------------------------------------------- public API
# Rows: W[d, k] = f(W[a, k]) for k < n. The d == a loop is separate so that LLVM sees the
# in-place form (distance 0) and vectorises without a runtime overlap check.


@njit(**_OPTS)
def exp_row(W, d, a, n):
    """W[d, :n] = exp(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _exp(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _exp(W[a, k])


@njit(**_OPTS)
def exp_scalar(x):
    """exp(x), same bits as exp_row and exp_array."""
    return _exp(x)


def exp_array(x) -> np.ndarray:
    """exp(x) elementwise in numpy, same bits as exp_row."""
    return _apply1(_NP_GLOBALS["_exp"], x)


@njit(**_OPTS)
def log_row(W, d, a, n):
    """W[d, :n] = log(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _log(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _log(W[a, k])


@njit(**_OPTS)
def log_scalar(x):
    """log(x), same bits as log_row and log_array."""
    return _log(x)


def log_array(x) -> np.ndarray:
    """log(x) elementwise in numpy, same bits as log_row."""
    return _apply1(_NP_GLOBALS["_log"], x)


@njit(**_OPTS)
def pow_row_vv(W, d, a, b, n):
    """W[d, :n] = W[a, :n] ** W[b, :n] (C pow)."""
    if d == a:
        for k in range(n):
            W[d, k] = _pow(W[d, k], W[b, k])
    elif d == b:
        for k in range(n):
            W[d, k] = _pow(W[a, k], W[d, k])
    else:
        for k in range(n):
            W[d, k] = _pow(W[a, k], W[b, k])


@njit(**_OPTS)
def pow_row_vs(W, d, a, s, n):
    """W[d, :n] = W[a, :n] ** s."""
    if d == a:
        for k in range(n):
            W[d, k] = _pow(W[d, k], s)
    else:
        for k in range(n):
            W[d, k] = _pow(W[a, k], s)


@njit(**_OPTS)
def pow_row_sv(W, d, s, b, n):
    """W[d, :n] = s ** W[b, :n]."""
    if d == b:
        for k in range(n):
            W[d, k] = _pow(s, W[d, k])
    else:
        for k in range(n):
            W[d, k] = _pow(s, W[b, k])


@njit(**_OPTS)
def pow_scalar(x, y):
    """x ** y (C pow), same bits as the rows and pow_array."""
    return _pow(x, y)


def pow_array(x, y) -> np.ndarray:
    """x ** y elementwise (broadcasting) in numpy, same bits as the rows."""
    return _apply2(_NP_GLOBALS["_pow"], x, y)


@njit(**_OPTS)
def log10_row(W, d, a, n):
    """W[d, :n] = log10(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _log10(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _log10(W[a, k])


@njit(**_OPTS)
def log10_scalar(x):
    """log10(x), same bits as log10_row and log10_array."""
    return _log10(x)


def log10_array(x) -> np.ndarray:
    """log10(x) elementwise in numpy, same bits as log10_row."""
    return _apply1(_NP_GLOBALS["_log10"], x)


@njit(**_OPTS)
def sinh_row(W, d, a, n):
    """W[d, :n] = sinh(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _sinh(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _sinh(W[a, k])


@njit(**_OPTS)
def sinh_scalar(x):
    """sinh(x), same bits as sinh_row and sinh_array."""
    return _sinh(x)


def sinh_array(x) -> np.ndarray:
    """sinh(x) elementwise in numpy, same bits as sinh_row."""
    return _apply1(_NP_GLOBALS["_sinh"], x)


@njit(**_OPTS)
def cosh_row(W, d, a, n):
    """W[d, :n] = cosh(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _cosh(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _cosh(W[a, k])


@njit(**_OPTS)
def cosh_scalar(x):
    """cosh(x), same bits as cosh_row and cosh_array."""
    return _cosh(x)


def cosh_array(x) -> np.ndarray:
    """cosh(x) elementwise in numpy, same bits as cosh_row."""
    return _apply1(_NP_GLOBALS["_cosh"], x)


@njit(**_OPTS)
def tanh_row(W, d, a, n):
    """W[d, :n] = tanh(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _tanh(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _tanh(W[a, k])


@njit(**_OPTS)
def tanh_scalar(x):
    """tanh(x), same bits as tanh_row and tanh_array."""
    return _tanh(x)


def tanh_array(x) -> np.ndarray:
    """tanh(x) elementwise in numpy, same bits as tanh_row."""
    return _apply1(_NP_GLOBALS["_tanh"], x)


@njit(**_OPTS)
def asinh_row(W, d, a, n):
    """W[d, :n] = asinh(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _asinh(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _asinh(W[a, k])


@njit(**_OPTS)
def asinh_scalar(x):
    """asinh(x), same bits as asinh_row and asinh_array."""
    return _asinh(x)


def asinh_array(x) -> np.ndarray:
    """asinh(x) elementwise in numpy, same bits as asinh_row."""
    return _apply1(_NP_GLOBALS["_asinh"], x)


@njit(**_OPTS)
def acosh_row(W, d, a, n):
    """W[d, :n] = acosh(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _acosh(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _acosh(W[a, k])


@njit(**_OPTS)
def acosh_scalar(x):
    """acosh(x), same bits as acosh_row and acosh_array."""
    return _acosh(x)


def acosh_array(x) -> np.ndarray:
    """acosh(x) elementwise in numpy, same bits as acosh_row."""
    return _apply1(_NP_GLOBALS["_acosh"], x)


@njit(**_OPTS)
def atanh_row(W, d, a, n):
    """W[d, :n] = atanh(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _atanh(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _atanh(W[a, k])


@njit(**_OPTS)
def atanh_scalar(x):
    """atanh(x), same bits as atanh_row and atanh_array."""
    return _atanh(x)


def atanh_array(x) -> np.ndarray:
    """atanh(x) elementwise in numpy, same bits as atanh_row."""
    return _apply1(_NP_GLOBALS["_atanh"], x)


@njit(**_OPTS)
def cbrt_row(W, d, a, n):
    """W[d, :n] = cbrt(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _cbrt(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _cbrt(W[a, k])


@njit(**_OPTS)
def cbrt_scalar(x):
    """cbrt(x), same bits as cbrt_row and cbrt_array."""
    return _cbrt(x)


def cbrt_array(x) -> np.ndarray:
    """cbrt(x) elementwise in numpy, same bits as cbrt_row."""
    return _apply1(_NP_GLOBALS["_cbrt"], x)
