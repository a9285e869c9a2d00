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
- ``pow(x, y) = exp(y log|x|)`` with y*log|x| as an exact Dekker product plus tails; for
  y = 1.5 and y = 3 (the eq. (13) exponents left per point) exact products instead:
  x^3 = x*x*x and x^1.5 = x*sqrt(x) as double-doubles, one final rounding (``_pow_exact``).
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
from numba.core.dispatcher import Dispatcher
from numba.extending import intrinsic

from surfgen.generator.jit.options import FORCE_INLINE, INLINE, KERNEL

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

# Kernels are inlined into the loops at numba IR level: LLVM vectorises only call-free bodies.

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

# log(j/8), j = 6..11, as LCjH + LCjL with LCjH a multiple of 2^-42 (so that e*LN2_H + LCjH
# is exact) and LCjL the rest rounded to double.
LC6H, LC6L = -0.28768207245184385, 6.292357389008195e-14
LC7H, LC7L = -0.13353139262449076, -3.1859736349078334e-14
LC9H, LC9L = 0.11778303565643, -4.654729747598445e-14
LC10H, LC10L = 0.22314355131425145, -4.169796584527195e-14
LC11H, LC11L = 0.31845373111855224, -1.7625431312172662e-14

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
# (2/3) H for the plain log: 2 atanh(s) = 2s + s w (2/3 + w (2/3) H(w)).
TWO_THIRDS = 2.0 / 3.0
LK0 = TWO_THIRDS * LH0
LK1 = TWO_THIRDS * LH1
LK2 = TWO_THIRDS * LH2
LK3 = TWO_THIRDS * LH3
LK4 = TWO_THIRDS * LH4

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


@njit(**FORCE_INLINE)
def _sel(c, a, b):
    """``a if c else b`` with both operands already computed (an LLVM select)."""
    return a if c else b


@njit(**FORCE_INLINE)
def _two_sum(a, b):
    """s + e == a + b exactly (Knuth)."""
    s = a + b
    bb = s - a
    e = (a - (s - bb)) + (b - bb)
    return s, e


@njit(**FORCE_INLINE)
def _fast_two_sum(a, b):
    """s + e == a + b exactly when |a| >= |b| or a == 0 (Dekker)."""
    s = a + b
    e = b - (s - a)
    return s, e


@njit(**FORCE_INLINE)
def _split(a):
    """a == hi + lo with 26-bit halves (Veltkamp); |a| < 2^996."""
    c = SPLITTER * a
    hi = c - (c - a)
    return hi, a - hi


@njit(**FORCE_INLINE)
def _two_prod(a, b):
    """p + e == a * b exactly (Dekker, no FMA)."""
    p = a * b
    ah, al = _split(a)
    bh, bl = _split(b)
    e = ((ah * bh - p) + ah * bl + al * bh) + al * bl
    return p, e


@njit(**FORCE_INLINE)
def _trunc(v, mask):
    """v with its low mantissa bits cleared (fewer significant bits: exact products)."""
    return _i2f(_f2i(v) & mask)


@njit(**FORCE_INLINE)
def _rint52(v):
    """Round to the nearest integer, ties to even; exact for |v| < 2^52."""
    s = _sel(v < 0.0, -TWO52, TWO52)
    return (v + s) - s


@njit(**FORCE_INLINE)
def _ldexp2(v, k):
    """v * 2^k for |k| <= 2100 as two exact-or-IEEE-rounded multiplications."""
    k1 = k >> 1
    k2 = k - k1
    return (v * _i2f((k1 + 1023) << 52)) * _i2f((k2 + 1023) << 52)


@njit(**FORCE_INLINE)
def _scale_dd(ph, pl, k):
    """(ph + pl) * 2^k rounded once, also where the result is subnormal.

    A subnormal result is formed as (1 + t) - 1 with t = (ph + pl) * 2^(k + 1022): 1 + t
    (exact as a double-double, then one addition) rounds at the subnormal grid (2^-1074
    scaled by 2^1022), so ph + pl is rounded once there instead of twice (ph, then ph*2^k)."""
    t = _ldexp2(ph, k + 1022)
    sh, sl = _fast_two_sum(1.0, t)
    s = sh + (sl + _ldexp2(pl, k + 1022))
    return _sel(t < 1.0, (s - 1.0) * TINY_NORMAL, _ldexp2(ph, k))


@njit(**FORCE_INLINE)
def _sign_of(x, r):
    """r with the sign bit of x (x's sign bit set: -r)."""
    return _sel(_f2i(x) < 0, -r, r)


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


# Every private numba kernel and helper gets a numpy twin under the same name.
_KERNELS = [
    name
    for name, obj in globals().items()
    if name.startswith("_") and isinstance(obj, Dispatcher) and name not in ("_f2i", "_i2f")
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


# ----------------------------------------------------------------------------- public API
# Rows: W[d, k] = f(W[a, k]) for k < n. The d == a loop is separate so that LLVM sees the
# in-place form (distance 0) and vectorises without a runtime overlap check.


@njit(**INLINE)
def exp_row(W, d, a, n):
    """W[d, :n] = exp(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _exp(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _exp(W[a, k])


@njit(**KERNEL)
def exp_scalar(x):
    """exp(x), same bits as exp_row and exp_array."""
    return _exp(x)


def exp_array(x) -> np.ndarray:
    """exp(x) elementwise in numpy, same bits as exp_row."""
    return _apply1(_NP_GLOBALS["_exp"], x)


@njit(**INLINE)
def log_row(W, d, a, n):
    """W[d, :n] = log(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _log(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _log(W[a, k])


@njit(**KERNEL)
def log_scalar(x):
    """log(x), same bits as log_row and log_array."""
    return _log(x)


def log_array(x) -> np.ndarray:
    """log(x) elementwise in numpy, same bits as log_row."""
    return _apply1(_NP_GLOBALS["_log"], x)


@njit(**INLINE)
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


@njit(**INLINE)
def pow_row_vs(W, d, a, s, n):
    """W[d, :n] = W[a, :n] ** s (s = 1.5 or 3: the exact-product loop when every lane allows)."""
    if s == 1.5 or s == 3.0:
        bad = 0
        for k in range(n):
            bad += 0 if _pow_exact_lane(W[a, k], s) else 1
        if bad == 0:
            if s == 3.0 and d == a:
                for k in range(n):
                    W[d, k] = _pow3(W[d, k])
            elif s == 3.0:
                for k in range(n):
                    W[d, k] = _pow3(W[a, k])
            elif d == a:
                for k in range(n):
                    W[d, k] = _pow15(W[d, k])
            else:
                for k in range(n):
                    W[d, k] = _pow15(W[a, k])
            return
    if d == a:
        for k in range(n):
            W[d, k] = _pow(W[d, k], s)
    else:
        for k in range(n):
            W[d, k] = _pow(W[a, k], s)


@njit(**INLINE)
def pow_row_sv(W, d, s, b, n):
    """W[d, :n] = s ** W[b, :n]."""
    if d == b:
        for k in range(n):
            W[d, k] = _pow(s, W[d, k])
    else:
        for k in range(n):
            W[d, k] = _pow(s, W[b, k])


@njit(**KERNEL)
def pow_scalar(x, y):
    """x ** y (C pow), same bits as the rows and pow_array."""
    return _pow(x, y)


def pow_array(x, y) -> np.ndarray:
    """x ** y elementwise (broadcasting) in numpy, same bits as the rows."""
    return _apply2(_NP_GLOBALS["_pow"], x, y)


@njit(**INLINE)
def log10_row(W, d, a, n):
    """W[d, :n] = log10(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _log10(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _log10(W[a, k])


@njit(**KERNEL)
def log10_scalar(x):
    """log10(x), same bits as log10_row and log10_array."""
    return _log10(x)


def log10_array(x) -> np.ndarray:
    """log10(x) elementwise in numpy, same bits as log10_row."""
    return _apply1(_NP_GLOBALS["_log10"], x)


@njit(**INLINE)
def sinh_row(W, d, a, n):
    """W[d, :n] = sinh(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _sinh(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _sinh(W[a, k])


@njit(**KERNEL)
def sinh_scalar(x):
    """sinh(x), same bits as sinh_row and sinh_array."""
    return _sinh(x)


def sinh_array(x) -> np.ndarray:
    """sinh(x) elementwise in numpy, same bits as sinh_row."""
    return _apply1(_NP_GLOBALS["_sinh"], x)


@njit(**INLINE)
def cosh_row(W, d, a, n):
    """W[d, :n] = cosh(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _cosh(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _cosh(W[a, k])


@njit(**KERNEL)
def cosh_scalar(x):
    """cosh(x), same bits as cosh_row and cosh_array."""
    return _cosh(x)


def cosh_array(x) -> np.ndarray:
    """cosh(x) elementwise in numpy, same bits as cosh_row."""
    return _apply1(_NP_GLOBALS["_cosh"], x)


@njit(**INLINE)
def tanh_row(W, d, a, n):
    """W[d, :n] = tanh(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _tanh(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _tanh(W[a, k])


@njit(**KERNEL)
def tanh_scalar(x):
    """tanh(x), same bits as tanh_row and tanh_array."""
    return _tanh(x)


def tanh_array(x) -> np.ndarray:
    """tanh(x) elementwise in numpy, same bits as tanh_row."""
    return _apply1(_NP_GLOBALS["_tanh"], x)


@njit(**INLINE)
def asinh_row(W, d, a, n):
    """W[d, :n] = asinh(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _asinh(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _asinh(W[a, k])


@njit(**KERNEL)
def asinh_scalar(x):
    """asinh(x), same bits as asinh_row and asinh_array."""
    return _asinh(x)


def asinh_array(x) -> np.ndarray:
    """asinh(x) elementwise in numpy, same bits as asinh_row."""
    return _apply1(_NP_GLOBALS["_asinh"], x)


@njit(**INLINE)
def acosh_row(W, d, a, n):
    """W[d, :n] = acosh(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _acosh(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _acosh(W[a, k])


@njit(**KERNEL)
def acosh_scalar(x):
    """acosh(x), same bits as acosh_row and acosh_array."""
    return _acosh(x)


def acosh_array(x) -> np.ndarray:
    """acosh(x) elementwise in numpy, same bits as acosh_row."""
    return _apply1(_NP_GLOBALS["_acosh"], x)


@njit(**INLINE)
def atanh_row(W, d, a, n):
    """W[d, :n] = atanh(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _atanh(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _atanh(W[a, k])


@njit(**KERNEL)
def atanh_scalar(x):
    """atanh(x), same bits as atanh_row and atanh_array."""
    return _atanh(x)


def atanh_array(x) -> np.ndarray:
    """atanh(x) elementwise in numpy, same bits as atanh_row."""
    return _apply1(_NP_GLOBALS["_atanh"], x)


@njit(**INLINE)
def cbrt_row(W, d, a, n):
    """W[d, :n] = cbrt(W[a, :n])."""
    if d == a:
        for k in range(n):
            W[d, k] = _cbrt(W[d, k])
    else:
        for k in range(n):
            W[d, k] = _cbrt(W[a, k])


@njit(**KERNEL)
def cbrt_scalar(x):
    """cbrt(x), same bits as cbrt_row and cbrt_array."""
    return _cbrt(x)


def cbrt_array(x) -> np.ndarray:
    """cbrt(x) elementwise in numpy, same bits as cbrt_row."""
    return _apply1(_NP_GLOBALS["_cbrt"], x)
