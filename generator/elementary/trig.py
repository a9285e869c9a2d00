"""surfgen's own sin, cos, tan, asin, acos, atan and atan2: one result on every CPU.

Each function is written **once**, as plain Python arithmetic on float64 values, and run twice:
jitted by numba (``NAME_row`` over a row of the interpreter's register file, ``NAME_scalar``)
and as numpy array code (``NAME_array``). Both execute the same IEEE-754 operation sequence
(no FMA, no reassociation, no ``math``/``np`` transcendental call anywhere), so they agree
bit for bit on every CPU, vectorised or not. The few operations that must be spelled
differently for scalars and arrays (select, floor, sqrt, copysign, frexp, ldexp, table
lookup) are helpers such as ``_where``, ``_floor``, ``_sqrt``: numpy calls in Python, and numba ``@overload``\\ s (plain
scalar selects / intrinsics) when jitted. All of them are exact operations.

Structure of a unary function NAME (NAME_row):

1. count the lanes outside the fast range (for sin/cos/tan finite ``|x| > 2**23``; for atan2
   finite non-zero operands outside ``[2**-500, 2**500]``; asin, acos, atan have none);
2. when there are some, save those inputs and their indices (``d`` may equal ``a``);
3. a branch-free loop computes the fast result for every lane (LLVM vectorises it: selects,
   multiply/add, ``floor``, ``sqrt``, division, no calls);
4. the saved lanes are recomputed by the slow path (scalar in numba; numpy runs it on all
   slow lanes of an array at once: it is written branch-free too).

Algorithms (derived from the literature: Cody & Waite 1980, Payne & Hanek 1983, fdlibm's
published kernel structure, Muller's "Elementary Functions"; the code is our own):

* reduction ``x = n*(pi/2) + y`` (``pi/4`` for tan), ``|y| <= pi/4``, as a double-double
  ``yh + yl``: Cody–Waite with pi/2 cut into three 29-bit parts (``n*C1``, ``n*C2``, ``n*C3``
  exact for ``|n| < 2**24``) and a rounded fourth (error < 2**-115 absolute, while no
  double is closer than ~2**-61 to a non-zero multiple of pi/2: Muller's worst case). Beyond: Payne–Hanek,
  computed exactly in 24-bit digits held in doubles (products < 2**50), 1344 bits of 2/pi.
* sin, cos on ``|y| <= pi/4``: odd/even minimax polynomials (degree 6 in ``z = y*y``), the
  leading term kept exact (``1 - z/2`` as a double-double); both are computed and the
  quadrant selects.
* tan: ``y`` in ``|y| <= pi/8``, ``T = tan(y)`` (degree 10 in z, Estrin's scheme) as a
  double-double and ``tan(x) = (a + b*T) / (c + d*T)`` with (a, b, c, d) chosen by ``n mod 4``
  — i.e. ``T``, ``(1+T)/(1-T)``, ``-1/T``, ``(T-1)/(T+1)`` — divided as double-doubles with
  one division (a quotient cut to 26 bits makes the remainder exact without an exact product).
* asin, acos: ``|x| <= 1/2`` polynomial in ``x*x`` (degree 13); above,
  ``asin(x) = pi/2 - 2*asin(sqrt((1-x)/2))`` with the square root as a double-double; the
  same polynomial serves both (select the argument, evaluate once).
* atan, atan2: the ratio ``|y|/|x|`` is reduced around c in {0, 1/2, 1, 2, inf}
  (``atan(u) = atan(c) + atan((u - c)/(1 + c*u))``), written as ``(|y| - c|x|)/(|x| + c|y|)``
  so the numerator is exact; ``atan(t)`` for ``|t| <= 7/16`` by a degree-11 polynomial; the
  quadrant by ``pi - ...`` as a double-double. atan2 divides as a double-double (Horner's
  scheme); atan (``x = 1``: ``t`` is exact below 7/16, elsewhere half an ulp of the rounded
  quotient is at most a quarter of an ulp of the result) takes the rounded quotient and
  Estrin's scheme, 25 % fewer cycles.

Coefficients: ``benchmarks/fit_trig.py`` (mpmath Remez, relative error; degrees and fit
errors in the comments of the tables below). Accuracy (``benchmarks/accuracy_trig.py``,
10**6 arguments each against mpmath, hard ranges included): max 0.77 ulp (sin, cos),
<= 0.71 ulp for the others; NaN results are the canonical
quiet NaN ``0x7ff8000000000000`` (so NaN bits agree too).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit
from numba.extending import overload

from surfgen.generator.jit.options import INLINE, KERNEL, OVERLOAD

# ----------------------------------------------------------------------------- constants

NAN = float("nan")
INF = float("inf")
_RND = 6755399441055744.0  # 1.5 * 2**52: (v + _RND) - _RND rounds v (|v| < 2**51) to an integer
_SPLIT = 134217729.0  # 2**27 + 1, Veltkamp/Dekker splitting
_TINY_TRIG = 2.0**-27  # below this sin(x) and tan(x) round to x (and keep the sign of zero)

# Fast range of the trigonometric reduction: |x| <= 2**23 keeps |n| < 2**24 for pi/4 steps.
TRIG_FAST_LIMIT = 8388608.0

_TWO_OVER_PI = 0.6366197723675814
_FOUR_OVER_PI = 1.2732395447351628
# pi/2 = _C1 + _C2 + _C3 + _C4 (+ 2e-43): three 29-bit parts (n * part is exact) and the rest.
_C1 = 1.570796325802803
_C2 = 9.920935774287987e-10
_C3 = 2.2517417706346578e-18
_C4 = 3.5215598651832e-27

# Double-double constants (hi, lo).
_PIO2_HI = 1.5707963267948966
_PIO2_LO = 6.123233995736766e-17
_PI_HI = 3.141592653589793
_PI_LO = 1.2246467991473532e-16
_PIO4_HI = 0.7853981633974483
_PIO4_LO = 3.061616997868383e-17
_ATAN_HALF_HI = 0.4636476090008061
_ATAN_HALF_LO = 2.2698777452961687e-17
_ATAN_TWO_HI = 1.1071487177940904
_ATAN_TWO_LO = 9.40447137356638e-17

# 2/pi in hexadecimal, 56 digits of 24 bits (1344 bits: enough for |x| up to 2**1024 with
# 9 digits = 216 bits below the binary point). A test checks it against mpmath.
_TWO_OVER_PI_HEX = (
    "A2F9836E4E441529FC2757D1F534DDC0DB6295993C439041FE5163ABDEBBC561B7246E3A424DD2E0"
    "06492EEA09D1921CFE1DEB1CB129A73EE88235F52EBB4484E99C7026B45F7E413991D639835339F4"
    "9C845F8BBDF9283B1FF897FFDE05980FEF2F118B5A0A6D1F6D367ECF27CB09B74F463F669E5FEA2D"
    "7527BAC7EBE5F17B3D0739F78A5292EA6BFB5FB11F8D5D0856033046FC7B6BABF0CFBC209AF4361D"
    "A9E391615EE61B08"
)
_F = np.array(
    [float(int(_TWO_OVER_PI_HEX[6 * i : 6 * i + 6], 16)) for i in range(56)], dtype=np.float64
)
_NF = 56

# Minimax coefficients (benchmarks/fit_trig.py; relative error of the double coefficients).
# SIN: (sin y - y)/y^3 ~ P(z), degree 6 in z on [0, (pi/4)^2], max relative error 2^-53.96
_S0 = -0.16666666666666666
_S1 = 0.008333333333333331
_S2 = -0.00019841269841265025
_S3 = 2.7557319219311545e-06
_S4 = -2.5052106223756418e-08
_S5 = 1.6058530358304306e-10
_S6 = -7.586628537108794e-13
# COS: (cos y - 1 + z/2)/z^2 ~ P(z), degree 6 in z on [0, (pi/4)^2], max relative error 2^-53.99
_K0 = 0.041666666666666664
_K1 = -0.0013888888888888887
_K2 = 2.4801587301584632e-05
_K3 = -2.7557319221392475e-07
_K4 = 2.0876755787810643e-09
_K5 = -1.1470460411538402e-11
_K6 = 4.7458459095111584e-14
# TAN: (tan y - y)/y^3 ~ P(z), degree 10 in z on [0, (pi/8)^2], max relative error 2^-53.98
_T0 = 0.3333333333333333
_T1 = 0.1333333333333333
_T2 = 0.05396825396825912
_T3 = 0.02186948853563535
_T4 = 0.008863235556764073
_T5 = 0.003592127228321649
_T6 = 0.0014558495097747608
_T7 = 0.000589846429091682
_T8 = 0.00024051180051042978
_T9 = 9.044154256713682e-05
_T10 = 5.585806408573994e-05
# ASIN: (asin x - x)/x^3 ~ P(z), degree 13 in z on [0, 1/4], max relative error 2^-53.97
_A0 = 0.16666666666666666
_A1 = 0.07500000000000125
_A2 = 0.04464285714253505
_A3 = 0.030381944477026034
_A4 = 0.02237215737477593
_A5 = 0.017352818420701247
_A6 = 0.013963747020434432
_A7 = 0.01156684716425047
_A8 = 0.009618729468019399
_A9 = 0.009336720020990662
_A10 = 0.002981078356138755
_A11 = 0.019707461794546254
_A12 = -0.019455095000504977
_A13 = 0.029743704563521073
# ATAN: (atan t - t)/t^3 ~ P(z), degree 11 in z on [0, (7/16)^2], max relative error 2^-53.76
_U0 = -0.3333333333333333
_U1 = 0.19999999999999424
_U2 = -0.14285714285569598
_U3 = 0.11111111096871155
_U4 = -0.09090908365001396
_U5 = 0.0769228578295156
_U6 = -0.06666245375190637
_U7 = 0.05876980023758304
_U8 = -0.05216889502494796
_U9 = 0.04493073489321706
_U10 = -0.033145998293442634
_U11 = 0.01479011397139272

# atan2: finite non-zero operands outside [2**-500, 2**500] take the slow path (scaling).
_A2_LO = 2.0**-500
_A2_HI = 2.0**500
_ATAN_CLAMP = 2.0**60  # atan(x) rounds to pi/2 for |x| >= 2**60

# ----------------------------------------------------------------------------- exact helpers
# Python versions work on numpy arrays (and on floats); the numba overloads on scalars.


def _where(c, a, b):
    """``a`` where ``c`` else ``b`` (a select; both sides are always computed)."""
    return np.where(c, a, b)


@overload(_where, jit_options=OVERLOAD)
def _ov_where(c, a, b):
    def impl(c, a, b):
        return a if c else b

    return impl


def _floor(x):
    """Largest integer <= x, as a float."""
    return np.floor(x)


@overload(_floor, jit_options=OVERLOAD)
def _ov_floor(x):
    def impl(x):
        return np.floor(x)

    return impl


def _sqrt(x):
    """Correctly rounded square root (NaN below 0)."""
    return np.sqrt(x)


@overload(_sqrt, jit_options=OVERLOAD)
def _ov_sqrt(x):
    def impl(x):
        return np.sqrt(x)

    return impl


def _copysign(x, s):
    """|x| with the sign bit of s."""
    return np.copysign(x, s)


@overload(_copysign, jit_options=OVERLOAD)
def _ov_copysign(x, s):
    def impl(x, s):
        return math.copysign(x, s)

    return impl


def _frexp(x):
    """(m, e) with x = m * 2**e, 0.5 <= |m| < 1 (exact)."""
    return np.frexp(x)


@overload(_frexp, jit_options=OVERLOAD)
def _ov_frexp(x):
    def impl(x):
        return math.frexp(x)

    return impl


def _ldexp(x, e):
    """x * 2**e (exact unless it overflows or underflows)."""
    return np.ldexp(x, e)


@overload(_ldexp, jit_options=OVERLOAD)
def _ov_ldexp(x, e):
    def impl(x, e):
        return math.ldexp(x, e)

    return impl


def _table(t, i):
    """t[i] with out-of-range indices clamped (their products are then discarded)."""
    return t[np.clip(i, 0, t.size - 1)]


@overload(_table, jit_options=OVERLOAD)
def _ov_table(t, i):
    def impl(t, i):
        return t[min(max(i, 0), t.size - 1)]

    return impl


def _dual(func=None, *, inline: bool = False):
    """Make a plain-Python helper callable from jitted code: numba compiles the same source.

    Called from Python the function runs on numpy arrays or floats; called from a jitted
    function, numba's ``@overload`` hands it the very same function to compile for scalars.
    """

    if func is None:
        return functools.partial(_dual, inline=inline)

    @functools.wraps(func)
    def typer(*args):
        return func

    # Big helpers are inlined in numba's IR (LLVM's inliner would keep them as calls, and a
    # call in a loop stops vectorisation); small ones are left to LLVM (faster to compile).
    overload(func, jit_options=OVERLOAD, inline="always" if inline else "never")(typer)
    return func


@_dual
def _two_sum(a, b):
    """(s, e) with s = fl(a + b) and s + e = a + b exactly (Knuth)."""
    s = a + b
    bb = s - a
    e = (a - (s - bb)) + (b - bb)
    return s, e


@_dual
def _fast_two_sum(a, b):
    """(s, e) with s + e = a + b exactly, for |a| >= |b| or a = 0 (Dekker)."""
    s = a + b
    e = b - (s - a)
    return s, e


@_dual
def _two_prod(a, b):
    """(p, e) with p = fl(a * b) and p + e = a * b exactly (Veltkamp/Dekker, no FMA).

    Valid while |a|, |b| < 2**995 and the product does not underflow.
    """
    p = a * b
    c = _SPLIT * a
    ah = c - (c - a)
    al = a - ah
    c = _SPLIT * b
    bh = c - (c - b)
    bl = b - bh
    e = ((ah * bh - p) + ah * bl + al * bh) + al * bl
    return p, e


@_dual
def _nan_fix(r):
    """Every NaN becomes the canonical quiet NaN (payloads would depend on operand order)."""
    return _where(r != r, NAN, r)


# ----------------------------------------------------------------------------- kernels


@_dual
def _reduce_cw2(x):
    n = (x * _TWO_OVER_PI + _RND) - _RND
    t1 = x - n * _C1
    s, e = _two_sum(t1, -(n * _C2))
    s2, e2 = _two_sum(s, -(n * _C3))
    lo = (e + e2) - n * _C4
    yh, yl = _fast_two_sum(s2, lo)
    return n, yh, yl


@_dual
def _reduce_cw4(x):
    n = (x * _FOUR_OVER_PI + _RND) - _RND
    t1 = x - n * (0.5 * _C1)
    s, e = _two_sum(t1, -(n * (0.5 * _C2)))
    s2, e2 = _two_sum(s, -(n * (0.5 * _C3)))
    lo = (e + e2) - n * (0.5 * _C4)
    yh, yl = _fast_two_sum(s2, lo)
    return n, yh, yl


@_dual
def _mod4(n):
    """n mod 4 in {0, 1, 2, 3} for an integer-valued float n."""
    return n - 4.0 * _floor(n * 0.25)


@_dual
def _sin_k(yh, yl):
    """sin(yh + yl) for |yh| <= ~pi/4, |yl| <= ulp(yh)."""
    z = yh * yh
    p = _S0 + z * (_S1 + z * (_S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))))
    v = z * yh
    return yh + (v * p + (yl - 0.5 * z * yl))


@_dual
def _cos_k(yh, yl):
    """cos(yh + yl) for |yh| <= ~pi/4: (1 - z/2) kept exact as a double-double."""
    z = yh * yh
    p = _K0 + z * (_K1 + z * (_K2 + z * (_K3 + z * (_K4 + z * (_K5 + z * _K6)))))
    hz = 0.5 * z
    w = 1.0 - hz
    return w + (((1.0 - w) - hz) + (z * z * p - yh * yl))


@_dual(inline=True)
def _sin_finish(q, yh, yl):
    """sin(q*pi/2 + y) for q = n mod 4."""
    s = _sin_k(yh, yl)
    c = _cos_k(yh, yl)
    odd = (q == 1.0) | (q == 3.0)
    r = _where(odd, c, s)
    return _where(q >= 2.0, -r, r)


@_dual(inline=True)
def _cos_finish(q, yh, yl):
    """cos(q*pi/2 + y) for q = n mod 4."""
    s = _sin_k(yh, yl)
    c = _cos_k(yh, yl)
    odd = (q == 1.0) | (q == 3.0)
    r = _where(odd, s, c)
    neg = (q == 1.0) | (q == 2.0)
    return _where(neg, -r, r)


@_dual(inline=True)
def _tan_finish(q, yh, yl):
    """tan(q*pi/4 + y) for q = n mod 4, |y| <= ~pi/8, via (a + b*T)/(c + d*T).

    Cost matters here (tan led the interpreter's profile): the polynomial is evaluated by
    Estrin's scheme (short dependency chains, so the vectorised loop is not latency-bound), the
    numerator and denominator are exact sums by Dekker's fast two-sum (``|b*T| <= tan(pi/8) <
    1 = |a|`` or ``a = 0``), and the double-double quotient takes one division: ``t`` = the
    quotient cut to 26 bits, ``zd`` = the denominator cut to 26 bits, so ``t*zd`` is exact and
    ``nh - t*zd`` exact by Sterbenz; the remainder divided by ``dh`` corrects ``t``.
    """
    z = yh * yh
    z2 = z * z
    z4 = z2 * z2
    z8 = z4 * z4
    f0 = (_T0 + z * _T1) + z2 * (_T2 + z * _T3)
    f1 = (_T4 + z * _T5) + z2 * (_T6 + z * _T7)
    f2 = (_T8 + z * _T9) + z2 * _T10
    p = (f0 + z4 * f1) + z8 * f2
    corr = (yh * z) * p + (yl + yl * z)  # tan' = 1 + tan^2 ~ 1 + z
    th, tl = _fast_two_sum(yh, corr)
    # q: 0 -> T/1, 1 -> (1+T)/(1-T), 2 -> -1/T, 3 -> (T-1)/(1+T); c = b
    a = _where(q == 0.0, 0.0, _where(q == 1.0, 1.0, -1.0))
    b = _where(q == 2.0, 0.0, 1.0)
    d = _where(q == 0.0, 0.0, _where(q == 1.0, -1.0, 1.0))
    nh, nl = _fast_two_sum(a, b * th)
    nl = nl + b * tl
    dh, dl = _fast_two_sum(b, d * th)
    dl = dl + d * tl
    inv = 1.0 / dh
    qh = nh * inv
    cq = _SPLIT * qh
    t = cq - (cq - qh)  # qh to 26 bits
    cd = _SPLIT * dh
    zd = cd - (cd - dh)  # dh to 26 bits: t * zd is exact
    r = ((nh - t * zd) - t * (dh - zd)) + (nl - t * dl)
    return t + r * inv


@_dual(inline=True)
def _sin_fast(x):
    n, yh, yl = _reduce_cw2(x)
    r = _sin_finish(_mod4(n), yh, yl)
    r = _where(abs(x) < _TINY_TRIG, x, r)
    return _nan_fix(r)


@_dual(inline=True)
def _cos_fast(x):
    n, yh, yl = _reduce_cw2(x)
    return _nan_fix(_cos_finish(_mod4(n), yh, yl))


@_dual(inline=True)
def _tan_fast(x):
    n, yh, yl = _reduce_cw4(x)
    r = _tan_finish(_mod4(n), yh, yl)
    r = _where(abs(x) < _TINY_TRIG, x, r)
    return _nan_fix(r)


@_dual
def _trig_slow_lane(x):
    """True where sin/cos/tan need the Payne–Hanek path (finite, |x| > 2**23)."""
    ax = abs(x)
    return (ax > TRIG_FAST_LIMIT) & (ax < INF)


@_dual
def _asin_poly(z):
    return _A0 + z * (
        _A1
        + z
        * (
            _A2
            + z
            * (
                _A3
                + z
                * (
                    _A4
                    + z
                    * (
                        _A5
                        + z
                        * (
                            _A6
                            + z
                            * (
                                _A7
                                + z
                                * (
                                    _A8
                                    + z * (_A9 + z * (_A10 + z * (_A11 + z * (_A12 + z * _A13))))
                                )
                            )
                        )
                    )
                )
            )
        )
    )


@_dual(inline=True)
def _asin_parts(ax):
    """For a = |x|: (big, b, btail) with asin(a) = H - 2*b - 2*btail when big, a + btail else.

    big: a > 1/2, b = sqrt((1-a)/2) rounded, btail its double-double tail plus the series.
    """
    big = ax > 0.5
    w = (1.0 - ax) * 0.5  # exact for 1/2 <= a <= 1
    s = _sqrt(w)
    ph, pl = _two_prod(s, s)
    slo = _where(w > 0.0, ((w - ph) - pl) / (s + s), 0.0)
    z = _where(big, w, ax * ax)
    p = _asin_poly(z)
    b = _where(big, s, ax)
    btail = _where(big, slo + s * z * p, ax * z * p)
    return big, b, btail


@_dual(inline=True)
def _asin_fast(x):
    ax = abs(x)
    big, b, btail = _asin_parts(ax)
    hh = _where(big, _PIO2_HI, 0.0)
    hl = _where(big, _PIO2_LO, 0.0)
    m = _where(big, -2.0 * b, b)
    tail = _where(big, -2.0 * btail, btail)
    sh, se = _two_sum(hh, m)
    r = sh + ((se + hl) + tail)
    return _nan_fix(_copysign(r, x))


@_dual(inline=True)
def _acos_fast(x):
    ax = abs(x)
    big, b, btail = _asin_parts(ax)
    pos = x > 0.0
    # small: pi/2 - x - x z P; big, x > 0: 2 (s + tail); big, x < 0: pi - 2 (s + tail)
    hh = _where(big, _where(pos, 0.0, _PI_HI), _PIO2_HI)
    hl = _where(big, _where(pos, 0.0, _PI_LO), _PIO2_LO)
    g = _where(big & pos, 2.0, -2.0)
    g = _where(big, g, _where(pos, -1.0, 1.0))  # small: -x = -(sign) * |x|
    sh, se = _two_sum(hh, g * b)
    r = sh + ((se + hl) + g * btail)
    return _nan_fix(r)


@_dual
def _atan_poly_horner(z):
    return _U0 + z * (
        _U1
        + z
        * (
            _U2
            + z
            * (
                _U3
                + z
                * (
                    _U4
                    + z
                    * (_U5 + z * (_U6 + z * (_U7 + z * (_U8 + z * (_U9 + z * (_U10 + z * _U11))))))
                )
            )
        )
    )


@_dual
def _atan_poly_estrin(z):
    """The same polynomial by Estrin's scheme: short dependency chains, so the vectorised loop
    is not latency-bound (other roundings than Horner's: atan's own bits)."""
    z2 = z * z
    z4 = z2 * z2
    z8 = z4 * z4
    b0 = (_U0 + z * _U1) + z2 * (_U2 + z * _U3)
    b1 = (_U4 + z * _U5) + z2 * (_U6 + z * _U7)
    b2 = (_U8 + z * _U9) + z2 * (_U10 + z * _U11)
    return (b0 + z4 * b1) + z8 * b2


@_dual(inline=True)
def _atan_core(ay, ax, u, exact):
    """atan(ay/ax) for 0 <= ay, 0 < ax (or ay > 0 = ax), u ~ ay/ax, as (h, tail).

    ``exact`` (a constant at each call, so numba drops the other branch): the reduced argument
    ``t = num / (dh + dl)`` as a double-double, the division's rounding error included, and
    the polynomial by Horner's scheme (atan2, where ``t`` may be the result itself: below 7/16
    the quotient's half ulp would be half an ulp of the result).  Else ``t`` is the rounded
    quotient with the first-order term of ``dl``, and the polynomial by Estrin's scheme (atan,
    ``ax = 1``: ``t`` is exact below 7/16, and elsewhere half an ulp of ``t`` is at most a
    quarter of an ulp of the result; 0.71 ulp at most on 10**6 arguments)."""
    i0 = u < 0.4375
    i1 = u < 0.6875
    i2 = u < 1.1875
    i3 = u < 2.4375
    c = _where(i0, 0.0, _where(i1, 0.5, _where(i2, 1.0, 2.0)))
    ah = _where(
        i0, 0.0, _where(i1, _ATAN_HALF_HI, _where(i2, _PIO4_HI, _where(i3, _ATAN_TWO_HI, _PIO2_HI)))
    )
    al = _where(
        i0, 0.0, _where(i1, _ATAN_HALF_LO, _where(i2, _PIO4_LO, _where(i3, _ATAN_TWO_LO, _PIO2_LO)))
    )
    num = _where(i3, ay - c * ax, -ax)  # exact (Sterbenz) on each interval
    dh, dl = _two_sum(_where(i3, ax, ay), _where(i3, c * ay, 0.0))
    th = num / dh
    z = th * th
    if exact:
        ph, pl = _two_prod(th, dh)
        tl = (((num - ph) - pl) - th * dl) / dh
        p = _atan_poly_horner(z)
    else:
        tl = -(th * dl) / dh
        p = _atan_poly_estrin(z)
    corr = (th * z) * p + (tl - tl * z)
    h, e = _two_sum(ah, th)
    return h, (e + al) + corr


@_dual(inline=True)
def _atan_fast(x):
    ay = abs(x)
    ay = _where(ay > _ATAN_CLAMP, _ATAN_CLAMP, ay)  # also inf; NaN stays NaN
    h, tail = _atan_core(ay, 1.0, ay, False)
    r = h + tail
    return _nan_fix(_copysign(r, x))


@_dual(inline=True)
def _atan2_fast(y, x):
    """atan2 for operands that are 0, inf, NaN or of magnitude in [2**-500, 2**500]."""
    ay = abs(y)
    ax = abs(x)
    yinf = ay == INF
    xinf = ax == INF
    both0 = (ay == 0.0) & (ax == 0.0)
    # Special operands become a finite pair with the same angle (C99 Annex F).
    ay2 = _where(yinf, _where(xinf, 1.0, 1.0), _where(xinf | both0, 0.0, ay))
    ax2 = _where(yinf, _where(xinf, 1.0, 0.0), _where(xinf | both0, 1.0, ax))
    u = ay2 / ax2
    h, tail = _atan_core(ay2, ax2, u, True)
    xneg = _copysign(1.0, x) < 0.0
    hh = _where(xneg, _PI_HI, 0.0)
    hl = _where(xneg, _PI_LO, 0.0)
    g = _where(xneg, -1.0, 1.0)
    sh, se = _two_sum(hh, g * h)
    r = sh + ((se + hl) + g * tail)
    r = _copysign(r, y)
    return _nan_fix(_where((x != x) | (y != y), NAN, r))


@_dual
def _atan2_slow_lane(y, x):
    """True where atan2 needs scaling: a finite non-zero operand outside [2**-500, 2**500]."""
    ay = abs(y)
    ax = abs(x)
    oy = ((ay > _A2_HI) & (ay < INF)) | ((ay > 0.0) & (ay < _A2_LO))
    ox = ((ax > _A2_HI) & (ax < INF)) | ((ax > 0.0) & (ax < _A2_LO))
    return oy | ox


# ----------------------------------------------------------------------------- slow paths
# Written like the fast paths (selects, no data-dependent branches), so numba runs them on
# the few slow scalars of a row and numpy on all slow lanes of an array at once.


@_dual
def _rem_pio2_slow(x, shift):
    """Payne–Hanek: (q, yh, yl) with x = (4k + q)*(pi/2)/2**shift + yh + yl, |y| <= ~pi/4/2**shift.

    x finite with |x| > 2**23 (any finite |x| >= 1 works); shift 0 (sin, cos) or 1 (tan).
    Exact integer arithmetic in 24-bit digits held in doubles: x*2**shift = m*2**e,
    m < 2**53 is cut into four 24-bit digits aligned to multiples of 24 bits, 2/pi is the
    table _F; the digit products (< 2**48, sums < 2**50) are exact, and carries are
    propagated from the last of 9 fraction digits (216 bits) to the integer digit mod 4.
    """
    ax = abs(x)
    mant, ex = _frexp(ax)
    e = ex - 53 + shift
    pp = (e - (e % 24)) // 24  # floor(e / 24)
    big = _ldexp(mant, 53 + e - 24 * pp)  # m * 2**rem < 2**77, exact
    t2 = _floor(big * 5.960464477539063e-08)  # floor(big / 2**24)
    t1 = _floor(big * 3.552713678800501e-15)  # floor(big / 2**48)
    t0 = _floor(big * 2.117582368135751e-22)  # floor(big / 2**72)
    xd = (t0, t1 - t0 * 16777216.0, t2 - t1 * 16777216.0, big - t2 * 16777216.0)
    carry = 0.0 * big
    g1 = 0.0 * big
    g2 = 0.0 * big
    g3 = 0.0 * big
    nint = 0.0 * big
    for j in range(9, -1, -1):
        s = pp + (2 + j)
        q = 0.0 * big
        for a in range(4):
            b = s - a
            q = q + _where((b >= 0) & (b < _NF), xd[a] * _table(_F, b), 0.0)
        v = q + carry
        if j == 0:
            nint = v - 4.0 * _floor(v * 0.25)
        else:
            c = _floor(v * 5.960464477539063e-08)
            dig = v - c * 16777216.0
            carry = c
            w = _ldexp(dig, -24 * j)
            if j <= 2:
                g1 = g1 + w
            elif j <= 4:
                g2 = g2 + w
            elif j <= 7:
                g3 = g3 + w
    up = g1 >= 0.5
    nint = _where(up, nint + 1.0, nint)
    g1 = _where(up, g1 - 1.0, g1)
    h, l0 = _fast_two_sum(g1, g2)
    h, l1 = _fast_two_sum(h, l0 + g3)
    # y = (h + l1) * pi/2 / 2**shift
    ph, pl = _two_prod(h, _PIO2_HI)
    pl = pl + (h * _PIO2_LO + l1 * _PIO2_HI)
    yh, yl = _fast_two_sum(ph, pl)
    scale = 0.5 if shift == 1 else 1.0
    yh = yh * scale
    yl = yl * scale
    nint = nint - 4.0 * _floor(nint * 0.25)
    neg = x < 0.0
    nint = _where(neg, _where(nint == 0.0, 0.0, 4.0 - nint), nint)
    return nint, _where(neg, -yh, yh), _where(neg, -yl, yl)


@_dual
def _sin_slow(x):
    q, yh, yl = _rem_pio2_slow(x, 0)
    return _nan_fix(_sin_finish(q, yh, yl))


@_dual
def _cos_slow(x):
    q, yh, yl = _rem_pio2_slow(x, 0)
    return _nan_fix(_cos_finish(q, yh, yl))


@_dual
def _tan_slow(x):
    q, yh, yl = _rem_pio2_slow(x, 1)
    return _nan_fix(_tan_finish(q, yh, yl))


@_dual
def _atan2_slow(y, x):
    """atan2 when an operand is finite, non-zero and outside [2**-500, 2**500].

    Its partner may be 0, inf or NaN: then only the finite operand's sign matters and it is
    replaced by +-1. Otherwise both are scaled by the same power of two (exact) unless their
    ratio is beyond 2**+-60, where the result is pi/2, or t resp. pi - t with t = |y/x|.
    """
    ay = abs(y)
    ax = abs(x)
    fy = (ay > 0.0) & (ay < INF)
    fx = (ax > 0.0) & (ax < INF)
    special = (fy & fx) == False  # noqa: E712 (arrays and numba scalars alike)
    y1 = _where(special & fy, _copysign(1.0, y), y)
    x1 = _where(special & fx, _copysign(1.0, x), x)
    ey = _frexp(ay)[1]
    ex = _frexp(ax)[1]
    sc = _where(special, 0, -ex)
    r = _atan2_fast(_ldexp(y1, sc), _ldexp(x1, sc))
    d = ey - ex
    t = ay / ax
    xneg = _copysign(1.0, x) < 0.0
    tiny = _where(xneg, _PI_HI - (t - _PI_LO), t)
    r = _where(special, r, _where(d > 60, _PIO2_HI, _where(d < -60, tiny, r)))
    return _nan_fix(_where(special, r, _copysign(r, y)))


# ----------------------------------------------------------------------------- public API
# Unary rows: count the slow lanes (cheap, vectorised), save them (d may equal a), run the
# branch-free fast loop over the whole row (vectorised), then patch the saved lanes.


@njit(**KERNEL)
def _gather1(W, a, n, cnt):
    """Indices and values of the slow lanes of row a (saved before d == a is overwritten)."""
    idx = np.empty(cnt, np.int64)
    val = np.empty(cnt, np.float64)
    j = 0
    for k in range(n):
        if _trig_slow_lane(W[a, k]):
            idx[j] = k
            val[j] = W[a, k]
            j += 1
    return idx, val


@njit(**KERNEL)
def _gather2(W, a, b, n, cnt, sa, sb):
    """Indices and operands (y, x) of the slow lanes of atan2: row a or scalar sa (a < 0)."""
    idx = np.empty(cnt, np.int64)
    vy = np.empty(cnt, np.float64)
    vx = np.empty(cnt, np.float64)
    j = 0
    for k in range(n):
        y = W[a, k] if a >= 0 else sa
        x = W[b, k] if b >= 0 else sb
        if _atan2_slow_lane(y, x):
            idx[j] = k
            vy[j] = y
            vx[j] = x
            j += 1
    return idx, vy, vx


SIN, COS, TAN = 0, 1, 2  # trig_row's kinds


@njit(**INLINE)
def _trig_value(kind, x):
    """sin, cos or tan (``kind``) of x, fast path; ``kind`` is a constant at each call, so
    only its branch is compiled into the row."""
    if kind == SIN:
        return _sin_fast(x)
    if kind == COS:
        return _cos_fast(x)
    return _tan_fast(x)


@njit(**INLINE)
def _trig_slow_value(kind, x):
    """The same, for the arguments beyond the fast range (Payne-Hanek)."""
    if kind == SIN:
        return _sin_slow(x)
    if kind == COS:
        return _cos_slow(x)
    return _tan_slow(x)


@njit(**INLINE)
def trig_row(W, d, a, n, kind, recip):
    """W[d, k] = f(W[a, k]) for k < n, f = sin, cos or tan (``kind``: SIN, COS, TAN), or 1/f
    with ``recip`` (csc, sec, cot: the function, then the division, in one loop, so the divider
    works while the function's arithmetic does; the bits of the two operations). d may equal
    a: the slow lanes' arguments are gathered first. Both flags are constants at each call."""
    cnt = 0
    for k in range(n):
        cnt += 1 if _trig_slow_lane(W[a, k]) else 0
    if cnt > 0:
        idx, val = _gather1(W, a, n, cnt)
    for k in range(n):
        v = _trig_value(kind, W[a, k])
        W[d, k] = 1.0 / v if recip else v
    if cnt > 0:
        for j in range(cnt):
            v = _trig_slow_value(kind, val[j])
            W[d, idx[j]] = 1.0 / v if recip else v


@njit(**INLINE)
def sin_row(W, d, a, n):
    """W[d, k] = sin(W[a, k]) for k < n (W: 2-D C-contiguous float64; d may equal a)."""
    trig_row(W, d, a, n, SIN, False)


@njit(**INLINE)
def cos_row(W, d, a, n):
    """W[d, k] = cos(W[a, k]) for k < n (d may equal a)."""
    trig_row(W, d, a, n, COS, False)


@njit(**INLINE)
def tan_row(W, d, a, n):
    """W[d, k] = tan(W[a, k]) for k < n (d may equal a)."""
    trig_row(W, d, a, n, TAN, False)


@njit(**INLINE)
def asin_row(W, d, a, n):
    """W[d, k] = asin(W[a, k]) for k < n (no slow path: one branch-free loop)."""
    for k in range(n):
        W[d, k] = _asin_fast(W[a, k])


@njit(**INLINE)
def acos_row(W, d, a, n):
    """W[d, k] = acos(W[a, k]) for k < n (no slow path: one branch-free loop)."""
    for k in range(n):
        W[d, k] = _acos_fast(W[a, k])


@njit(**INLINE)
def atan_row(W, d, a, n):
    """W[d, k] = atan(W[a, k]) for k < n (no slow path: one branch-free loop)."""
    for k in range(n):
        W[d, k] = _atan_fast(W[a, k])


@njit(**INLINE)
def atan2_row_vv(W, d, a, b, n):
    """W[d, k] = atan2(W[a, k], W[b, k]) for k < n (d may equal a or b)."""
    cnt = 0
    for k in range(n):
        cnt += 1 if _atan2_slow_lane(W[a, k], W[b, k]) else 0
    if cnt > 0:
        idx, vy, vx = _gather2(W, a, b, n, cnt, 0.0, 0.0)
    for k in range(n):
        W[d, k] = _atan2_fast(W[a, k], W[b, k])
    if cnt > 0:
        for j in range(cnt):
            W[d, idx[j]] = _atan2_slow(vy[j], vx[j])


@njit(**INLINE)
def atan2_row_vs(W, d, a, s, n):
    """W[d, k] = atan2(W[a, k], s) for k < n (d may equal a)."""
    cnt = 0
    for k in range(n):
        cnt += 1 if _atan2_slow_lane(W[a, k], s) else 0
    if cnt > 0:
        idx, vy, vx = _gather2(W, a, -1, n, cnt, 0.0, s)
    for k in range(n):
        W[d, k] = _atan2_fast(W[a, k], s)
    if cnt > 0:
        for j in range(cnt):
            W[d, idx[j]] = _atan2_slow(vy[j], vx[j])


@njit(**INLINE)
def atan2_row_sv(W, d, s, b, n):
    """W[d, k] = atan2(s, W[b, k]) for k < n (d may equal b)."""
    cnt = 0
    for k in range(n):
        cnt += 1 if _atan2_slow_lane(s, W[b, k]) else 0
    if cnt > 0:
        idx, vy, vx = _gather2(W, -1, b, n, cnt, s, 0.0)
    for k in range(n):
        W[d, k] = _atan2_fast(s, W[b, k])
    if cnt > 0:
        for j in range(cnt):
            W[d, idx[j]] = _atan2_slow(vy[j], vx[j])


@njit(**KERNEL)
def sin_scalar(x):
    """sin(x), the same bits as sin_row and sin_array."""
    if _trig_slow_lane(x):
        return _sin_slow(x)
    return _sin_fast(x)


@njit(**KERNEL)
def cos_scalar(x):
    """cos(x), the same bits as cos_row and cos_array."""
    if _trig_slow_lane(x):
        return _cos_slow(x)
    return _cos_fast(x)


@njit(**KERNEL)
def tan_scalar(x):
    """tan(x), the same bits as tan_row and tan_array."""
    if _trig_slow_lane(x):
        return _tan_slow(x)
    return _tan_fast(x)


@njit(**KERNEL)
def asin_scalar(x):
    """asin(x), the same bits as asin_row and asin_array."""
    return _asin_fast(x)


@njit(**KERNEL)
def acos_scalar(x):
    """acos(x), the same bits as acos_row and acos_array."""
    return _acos_fast(x)


@njit(**KERNEL)
def atan_scalar(x):
    """atan(x), the same bits as atan_row and atan_array."""
    return _atan_fast(x)


@njit(**KERNEL)
def atan2_scalar(p, q):
    """atan2(p, q) (angle of the point (q, p)), the same bits as the rows and atan2_array."""
    if _atan2_slow_lane(p, q):
        return _atan2_slow(p, q)
    return _atan2_fast(p, q)


# The numpy twins work in blocks: each function makes ~50 temporaries, which should stay in
# cache (and not cost 50 full-size arrays of memory on a 128^3 field).
_BLOCK = 16384


def _unary_array(x, fast, slow_lane, slow) -> np.ndarray:
    """Apply the numpy twin of a unary function: fast path everywhere, slow lanes patched."""
    xa = np.asarray(x, dtype=np.float64)
    flat = np.ascontiguousarray(xa).reshape(-1)
    out = np.empty(flat.size, dtype=np.float64)
    with np.errstate(all="ignore"):
        for i in range(0, flat.size, _BLOCK):
            v = flat[i : i + _BLOCK]
            r = np.asarray(fast(v), dtype=np.float64)
            if slow_lane is not None:
                mask = slow_lane(v)
                if mask.any():
                    r = r.copy()
                    r[mask] = slow(v[mask])
            out[i : i + _BLOCK] = r
    return out.reshape(xa.shape)


def sin_array(x) -> np.ndarray:
    """sin of a float64 array (or scalar) with numpy: the same bits as sin_row/sin_scalar."""
    return _unary_array(x, _sin_fast, _trig_slow_lane, _sin_slow)


def cos_array(x) -> np.ndarray:
    """cos with numpy: the same bits as cos_row/cos_scalar."""
    return _unary_array(x, _cos_fast, _trig_slow_lane, _cos_slow)


def tan_array(x) -> np.ndarray:
    """tan with numpy: the same bits as tan_row/tan_scalar."""
    return _unary_array(x, _tan_fast, _trig_slow_lane, _tan_slow)


def asin_array(x) -> np.ndarray:
    """asin with numpy: the same bits as asin_row/asin_scalar (NaN outside [-1, 1])."""
    return _unary_array(x, _asin_fast, None, None)


def acos_array(x) -> np.ndarray:
    """acos with numpy: the same bits as acos_row/acos_scalar (NaN outside [-1, 1])."""
    return _unary_array(x, _acos_fast, None, None)


def atan_array(x) -> np.ndarray:
    """atan with numpy: the same bits as atan_row/atan_scalar."""
    return _unary_array(x, _atan_fast, None, None)


def atan2_array(p, q) -> np.ndarray:
    """atan2(p, q) with numpy, broadcasting: the same bits as the numba rows and scalar."""
    pa, qa = np.broadcast_arrays(np.asarray(p, dtype=np.float64), np.asarray(q, dtype=np.float64))
    fy = np.ascontiguousarray(pa).reshape(-1)
    fx = np.ascontiguousarray(qa).reshape(-1)
    out = np.empty(fy.size, dtype=np.float64)
    with np.errstate(all="ignore"):
        for i in range(0, fy.size, _BLOCK):
            vy = fy[i : i + _BLOCK]
            vx = fx[i : i + _BLOCK]
            r = np.asarray(_atan2_fast(vy, vx), dtype=np.float64)
            mask = _atan2_slow_lane(vy, vx)
            if mask.any():
                r = r.copy()
                r[mask] = _atan2_slow(vy[mask], vx[mask])
            out[i : i + _BLOCK] = r
    return out.reshape(pa.shape)
