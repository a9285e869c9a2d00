"""The scalar kernels of surfgen's trigonometric functions (:mod:`surfgen.generator.elementary.trig`
has the algorithms): the Cody-Waite and Payne-Hanek reductions, the polynomials on the reduced
argument, the fast branch-free paths and the slow paths of the rare lanes. Each is a
:func:`~surfgen.generator.elementary.trig_exact._dual` helper: numpy code in Python, compiled by
numba for scalars.
"""

from __future__ import annotations

from surfgen.generator.elementary.trig_exact import (
    _copysign,
    _dual,
    _fast_two_sum,
    _floor,
    _frexp,
    _ldexp,
    _nan_fix,
    _sqrt,
    _table,
    _two_prod,
    _two_sum,
    _where,
)
from surfgen.generator.elementary.trig_tables import (
    _A0,
    _A1,
    _A2,
    _A2_HI,
    _A2_LO,
    _A3,
    _A4,
    _A5,
    _A6,
    _A7,
    _A8,
    _A9,
    _A10,
    _A11,
    _A12,
    _A13,
    _ATAN_CLAMP,
    _ATAN_HALF_HI,
    _ATAN_HALF_LO,
    _ATAN_TWO_HI,
    _ATAN_TWO_LO,
    _C1,
    _C2,
    _C3,
    _C4,
    _F,
    _FOUR_OVER_PI,
    _K0,
    _K1,
    _K2,
    _K3,
    _K4,
    _K5,
    _K6,
    _NF,
    _PI_HI,
    _PI_LO,
    _PIO2_HI,
    _PIO2_LO,
    _PIO4_HI,
    _PIO4_LO,
    _RND,
    _S0,
    _S1,
    _S2,
    _S3,
    _S4,
    _S5,
    _S6,
    _SPLIT,
    _T0,
    _T1,
    _T2,
    _T3,
    _T4,
    _T5,
    _T6,
    _T7,
    _T8,
    _T9,
    _T10,
    _TINY_TRIG,
    _TWO_OVER_PI,
    _U0,
    _U1,
    _U2,
    _U3,
    _U4,
    _U5,
    _U6,
    _U7,
    _U8,
    _U9,
    _U10,
    _U11,
    INF,
    NAN,
    TRIG_FAST_LIMIT,
)

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


@_dual
def _sin_finish(q, yh, yl):
    """sin(q*pi/2 + y) for q = n mod 4."""
    s = _sin_k(yh, yl)
    c = _cos_k(yh, yl)
    odd = (q == 1.0) | (q == 3.0)
    r = _where(odd, c, s)
    return _where(q >= 2.0, -r, r)


@_dual
def _cos_finish(q, yh, yl):
    """cos(q*pi/2 + y) for q = n mod 4."""
    s = _sin_k(yh, yl)
    c = _cos_k(yh, yl)
    odd = (q == 1.0) | (q == 3.0)
    r = _where(odd, s, c)
    neg = (q == 1.0) | (q == 2.0)
    return _where(neg, -r, r)


@_dual
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


@_dual
def _sin_fast(x):
    n, yh, yl = _reduce_cw2(x)
    r = _sin_finish(_mod4(n), yh, yl)
    r = _where(abs(x) < _TINY_TRIG, x, r)
    return _nan_fix(r)


@_dual
def _cos_fast(x):
    n, yh, yl = _reduce_cw2(x)
    return _nan_fix(_cos_finish(_mod4(n), yh, yl))


@_dual
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


@_dual
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


@_dual
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


@_dual
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


@_dual
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


@_dual
def _atan_fast(x):
    ay = abs(x)
    ay = _where(ay > _ATAN_CLAMP, _ATAN_CLAMP, ay)  # also inf; NaN stays NaN
    h, tail = _atan_core(ay, 1.0, ay, False)
    r = h + tail
    return _nan_fix(_copysign(r, x))


@_dual
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
