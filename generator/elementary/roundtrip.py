"""The paper's round trips in closed form: ``atan(tan u)``, ``asin(sin u)``, ``acos(cos u)``,
``acot(cot u)``, exact functions of the double ``u`` instead of two rounded calls.

Write ``u = k*pi + r`` with an integer ``k`` and ``r`` in ``[-pi/2, pi/2)`` (pi the real number,
not the double nearest to it). Then

===========  ==========================================  =========================
round trip   closed form                                 range
===========  ==========================================  =========================
atantan      ``r``                                       ``[-pi/2, pi/2)``
asinsin      ``(-1)^k r``                                ``[-pi/2, pi/2]``
acoscos      ``|r|`` for even k, ``pi - |r|`` for odd k  ``[0, pi]``
acotcot      ``r`` for r >= 0, ``pi + r`` for r < 0      ``[0, pi)``
===========  ==========================================  =========================

The value at a jump is fixed by the half-open intervals: ``atan(tan u)`` jumps from just below
pi/2 to -pi/2, ``acot(cot u)`` is 0 (never pi) at u = 0, which is the only double where a jump
falls exactly on an argument (``acot(cot(-0)) = +0``; the direct form gives pi there). Since pi is
irrational, no other double lies on a jump: the closed forms decide every argument exactly,
whereas the direct forms may land on either side within an ulp or two of a jump. Signs of zero:
``atan(tan(-0)) = asin(sin(-0)) = -0``.

Accuracy: ``r`` is computed in double-double and rounded once, so the result is within 0.5 ulp
plus about 2^-120 absolute of the exact value for ``|u| <= FAST = 2^24`` (Cody-Waite with pi in
three 30-bit parts, exact products ``k*P_i`` for ``|k| < 2^23``, and a rounded fourth: the
vectorised path) and within 0.5 ulp plus about 2^-100 absolute for ``2^24 < |u| <= LIMIT = 2^50``
(pi as three doubles and exact Dekker products: a scalar path per lane, rare in formulas);
``acos(cos u)`` and ``pi + r`` add one more rounding of a double-double sum. The direct forms lose up to half the digits where ``asin``
and ``acos`` are ill-conditioned (``asin(sin u)`` near ``u = pi/2``: ``asin(1 - d)`` turns an
ulp of ``sin`` into ``1e-8``) and a few ulp elsewhere. Beyond ``LIMIT`` (and for inf/NaN) the
closed forms *are* the direct forms, computed with surfgen's elementary functions.

Cost (issue 9's speed work): the vectorised reduction takes about 25 operations (no Dekker
split of k) and the end adjustment compares ``(hi - pi/2) + (lo - pi_lo/2)`` with 0 (exact
sign: hi and pi/2 differ by at least an ulp when they differ, more than the tails); ``acot(cot
u)`` needs no adjustment at all (``r mod pi`` is the same whichever side k rounded to).

Every function exists as a numba row ``NAME_row(W, d, a, n)`` (``d != a``), a numba scalar and a
numpy twin ``NAME_array``, bit-identical (one shared arithmetic core, :func:`_reduce_py`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.elementary.registry import registry
from surfgen.generator.jit.options import INLINE, KERNEL

ROUND_TRIPS = ("atantan", "asinsin", "acoscos", "acotcot")

LIMIT = 2.0**50  # |u| above this: the direct forms (k would not fit the exact products)
FAST = 2.0**24  # |u| up to this: the vectorised Cody-Waite reduction (|k| < 2^23)

# pi = _P1 + _P2 + _P3 + _P4 + 1e-44: three parts of 30 significant bits (k * _Pi is exact for
# |k| < 2^23) and the rest rounded (mpmath, 120 digits).
_P1 = 3.1415926553308964
_P2 = -1.7411031384001463e-09
_P3 = -7.006868793909636e-19
_P4 = -2.2702237215044403e-28

# pi = _C1 + _C2 + _C3 to about 160 bits; _C1 and _C2 split in halves of 26 bits for Dekker's
# exact product (generated with mpmath at 60 digits).
_C1 = 3.141592653589793
_C2 = 1.2246467991473532e-16
_C3 = -2.9947698097183397e-33
_C1H = 3.1415926814079285
_C1L = -2.781813535079891e-08
_C2H = 1.2246467864107189e-16
_C2L = 1.2736634356969598e-24
_HALF_H = _C1 / 2  # pi/2 as a double-double (exact halves)
_HALF_L = _C2 / 2
_INV_PI = 0.3183098861837907
_MAGIC = 6755399441055744.0  # 1.5 * 2^52: (v + M) - M rounds v to an integer (|v| < 2^51)
_SPLIT = 134217729.0  # 2^27 + 1, Veltkamp's splitter
_PI_2 = 1.5707963267948966  # the double np.pi / 2 (acot = pi/2 - atan in the direct form)


def _reduce_cw_py(u):
    """``u = k*pi + hi + lo`` for ``|u| <= FAST``, k = u/pi rounded in floating point (so
    ``hi + lo`` may lie an ulp or so outside [-pi/2, pi/2]); ``(k, hi, lo)`` normalised.

    ``u - k*_P1`` is exact: ``k*_P1`` has at most 53 bits and, when k != 0, lies within a
    factor 2 of u (|u| >= 1), on the grid of ulp(u); the next two products are exact and summed
    by two-sums, the fourth is rounded: error about 2^-105 |r| + 2^-121."""
    k = (u * _INV_PI + _MAGIC) - _MAGIC
    t1 = u - k * _P1
    p2 = -(k * _P2)
    s = t1 + p2
    bs = s - t1
    e = (t1 - (s - bs)) + (p2 - bs)  # two-sum
    p3 = -(k * _P3)
    s2 = s + p3
    b2 = s2 - s
    e2 = (s - (s2 - b2)) + (p3 - b2)  # two-sum
    lo = (e + e2) - k * _P4
    hi = s2 + lo
    return k, hi, lo - (hi - s2)


def _adjust_py(k, hi, lo):
    """:func:`_reduce_cw_py`'s result moved into [-pi/2, pi/2).

    k is off by one at the ends of the interval when u/pi rounds across a half-integer: the
    sign of ``(hi + lo) - pi/2`` is that of ``(hi - H) + (lo - L)`` (pi/2 = H + L): when
    hi != H they differ by an ulp of H or more, more than |lo - L|; then hi - pi is exact
    (Sterbenz)."""
    above = ((hi - _HALF_H) + (lo - _HALF_L)) >= 0.0
    below = ((hi + _HALF_H) + (lo + _HALF_L)) < 0.0
    adj = above * 1.0 - below * 1.0
    h2 = hi - adj * _C1  # exact
    l2 = lo - adj * _C2
    hi2 = h2 + l2
    return k + adj, hi2, l2 - (hi2 - h2)


def _reduce_py(u):
    """``u = k*pi + hi + lo`` with ``hi + lo`` in [-pi/2, pi/2) for ``|u| <= FAST``."""
    k, hi, lo = _reduce_cw_py(u)
    return _adjust_py(k, hi, lo)


def _reduce_dekker_py(u):
    """``u = k*pi + hi + lo`` with ``hi + lo`` in [-pi/2, pi/2) for ``|u| <= LIMIT``: ``(k, hi, lo)``.

    Plain arithmetic and comparisons only, so the same source runs on floats (jitted by numba)
    and on numpy arrays, with the same IEEE operations in the same order."""
    k = (u * _INV_PI + _MAGIC) - _MAGIC
    # k*C1 = p1 + e1 and k*C2 = p2 + e2 exactly (Dekker's product with a split k).
    s = _SPLIT * k
    kh = s - (s - k)
    kl = k - kh
    p1 = k * _C1
    e1 = ((kh * _C1H - p1) + kh * _C1L + kl * _C1H) + kl * _C1L
    p2 = k * _C2
    e2 = ((kh * _C2H - p2) + kh * _C2L + kl * _C2H) + kl * _C2L
    t = u - p1  # exact (Sterbenz): u and k*pi are within a factor 2 when k != 0
    q = e1 + p2
    bq = q - e1
    eq = (e1 - (q - bq)) + (p2 - bq)  # two-sum: e1 + p2 = q + eq
    h = t - q
    bh = h - t
    eh = (t - (h - bh)) + (-q - bh)  # two-sum: t - q = h + eh
    lo0 = ((eh - eq) - e2) - k * _C3
    hi = h + lo0
    lo = lo0 - (hi - h)
    # k is u/pi rounded in floating point: off by one at the ends of the interval.
    below = (hi < -_HALF_H) | ((hi == -_HALF_H) & (lo < -_HALF_L))
    above = (hi > _HALF_H) | ((hi == _HALF_H) & (lo >= _HALF_L))
    adj = above * 1.0 - below * 1.0
    m = adj * _C1
    h2 = hi - m
    b2 = h2 - hi
    e3 = (hi - (h2 - b2)) + (-m - b2)
    l2 = (lo - adj * _C2) + e3
    hi2 = h2 + l2
    lo2 = l2 - (hi2 - h2)
    return k + adj, hi2, lo2


def _parity_py(k):
    """1.0 for odd k, 0.0 for even (k an integer-valued float)."""
    half = k * 0.5
    return (half != np.floor(half)) * 1.0


def _pi_minus_py(hi, lo):
    """pi - (hi + lo) rounded once, for 0 <= hi <= pi/2 (a double-double difference)."""
    s = _C1 - hi
    e = (_C1 - s) - hi  # fast two-sum: exact, |pi| >= hi
    return s + (e + (_C2 - lo))


def _pi_plus_py(hi, lo):
    """pi + (hi + lo) rounded once, for -pi/2 - 2^-40 <= hi < 0."""
    s = _C1 + hi
    e = hi - (s - _C1)  # fast two-sum: exact, |hi| <= pi
    return s + (e + (_C2 + lo))


_reduce_cw = njit(**INLINE)(_reduce_cw_py)
_adjust = njit(**INLINE)(_adjust_py)


@njit(**INLINE)
def _reduce(u):
    k, hi, lo = _reduce_cw(u)
    return _adjust(k, hi, lo)


_reduce_dekker = njit(**INLINE)(_reduce_dekker_py)
_parity = njit(**INLINE)(_parity_py)
_pi_minus = njit(**INLINE)(_pi_minus_py)
_pi_plus = njit(**INLINE)(_pi_plus_py)

_FUNCTIONS = registry()
_sin = _FUNCTIONS["sin"].scalar
_cos = _FUNCTIONS["cos"].scalar
_tan = _FUNCTIONS["tan"].scalar
_asin = _FUNCTIONS["asin"].scalar
_acos = _FUNCTIONS["acos"].scalar
_atan = _FUNCTIONS["atan"].scalar

# ----------------------------------------------------------------------------- numba
# Each round trip has a fast form (|u| <= FAST, vectorised) and a mid form (FAST < |u| <= LIMIT,
# the Dekker reduction, per lane); beyond LIMIT the direct form.


@njit(**INLINE)
def _atantan_of(u, k, hi, lo):
    return u if k == 0.0 else hi


@njit(**INLINE)
def _asinsin_of(u, k, hi, lo):
    r = -hi if _parity(k) != 0.0 else hi
    return u if k == 0.0 else r


@njit(**INLINE)
def _acoscos_of(u, k, hi, lo):
    ahi = abs(hi)
    alo = lo if hi >= 0.0 else -lo
    far = _pi_minus(ahi, alo)
    return far if _parity(k) != 0.0 else ahi


@njit(**INLINE)
def _acotcot_of(u, k, hi, lo):
    # r mod pi in [0, pi): hi + lo is within an ulp or so of [-pi/2, pi/2], so adding pi to
    # the negative ones is enough (no end adjustment needed).
    neg = _pi_plus(hi, lo)
    return neg if hi < 0.0 else hi + 0.0


@njit(**INLINE)
def _atantan_fast(u):
    k, hi, lo = _reduce(u)
    return _atantan_of(u, k, hi, lo)


@njit(**INLINE)
def _asinsin_fast(u):
    k, hi, lo = _reduce(u)
    return _asinsin_of(u, k, hi, lo)


@njit(**INLINE)
def _acoscos_fast(u):
    k, hi, lo = _reduce(u)
    return _acoscos_of(u, k, hi, lo)


@njit(**INLINE)
def _acotcot_fast(u):
    k, hi, lo = _reduce_cw(u)
    return _acotcot_of(u, k, hi, lo)


@njit(**KERNEL)
def atantan_scalar(u):
    if abs(u) <= FAST:
        return _atantan_fast(u)
    if abs(u) <= LIMIT:
        k, hi, lo = _reduce_dekker(u)
        return _atantan_of(u, k, hi, lo)
    return _atan(_tan(u))


@njit(**KERNEL)
def asinsin_scalar(u):
    if abs(u) <= FAST:
        return _asinsin_fast(u)
    if abs(u) <= LIMIT:
        k, hi, lo = _reduce_dekker(u)
        return _asinsin_of(u, k, hi, lo)
    return _asin(_sin(u))


@njit(**KERNEL)
def acoscos_scalar(u):
    if abs(u) <= FAST:
        return _acoscos_fast(u)
    if abs(u) <= LIMIT:
        k, hi, lo = _reduce_dekker(u)
        return _acoscos_of(u, k, hi, lo)
    return _acos(_cos(u))


@njit(**KERNEL)
def acotcot_scalar(u):
    if abs(u) <= FAST:
        return _acotcot_fast(u)
    if abs(u) <= LIMIT:
        k, hi, lo = _reduce_dekker(u)
        return _acotcot_of(u, k, hi, lo)
    return _PI_2 - _atan(1.0 / _tan(u))


# Rows: loop 1 is branch-free (vectorised) and counts the arguments outside the fast range;
# loop 2 recomputes those, only when there are any. d != a (loop 2 reads the argument again).


@njit(**INLINE)
def atantan_row(W, d, a, n):
    bad = 0
    for k in range(n):
        u = W[a, k]
        W[d, k] = _atantan_fast(u)
        bad += 0 if abs(u) <= FAST else 1
    if bad:
        for k in range(n):
            if not abs(W[a, k]) <= FAST:
                W[d, k] = atantan_scalar(W[a, k])


@njit(**INLINE)
def asinsin_row(W, d, a, n):
    bad = 0
    for k in range(n):
        u = W[a, k]
        W[d, k] = _asinsin_fast(u)
        bad += 0 if abs(u) <= FAST else 1
    if bad:
        for k in range(n):
            if not abs(W[a, k]) <= FAST:
                W[d, k] = asinsin_scalar(W[a, k])


@njit(**INLINE)
def acoscos_row(W, d, a, n):
    bad = 0
    for k in range(n):
        u = W[a, k]
        W[d, k] = _acoscos_fast(u)
        bad += 0 if abs(u) <= FAST else 1
    if bad:
        for k in range(n):
            if not abs(W[a, k]) <= FAST:
                W[d, k] = acoscos_scalar(W[a, k])


@njit(**INLINE)
def acotcot_row(W, d, a, n):
    bad = 0
    for k in range(n):
        u = W[a, k]
        W[d, k] = _acotcot_fast(u)
        bad += 0 if abs(u) <= FAST else 1
    if bad:
        for k in range(n):
            if not abs(W[a, k]) <= FAST:
                W[d, k] = acotcot_scalar(W[a, k])


# ----------------------------------------------------------------------------- numpy twins


def direct_array(name: str, u: np.ndarray, fns) -> np.ndarray:
    """The direct (two-call) form of a round trip with the array functions ``fns[name]``."""
    with np.errstate(all="ignore"):
        if name == "atantan":
            return fns["atan"](fns["tan"](u))
        if name == "asinsin":
            return fns["asin"](fns["sin"](u))
        if name == "acoscos":
            return fns["acos"](fns["cos"](u))
        if name == "acotcot":
            return _PI_2 - fns["atan"](1.0 / fns["tan"](u))
    raise KeyError(name)


_OWN = {name: _FUNCTIONS[name].array for name in ("sin", "cos", "tan", "asin", "acos", "atan")}


def _twin(name: str, finish, reduce_fast):
    def array(u) -> np.ndarray:
        u = np.asarray(u, np.float64)
        with np.errstate(all="ignore"):
            out = np.asarray(finish(u, *reduce_fast(u)), np.float64)
            slow = ~(np.abs(u) <= FAST)
            if slow.any():
                out = out.copy()
                us = u[slow]
                mid = finish(us, *_reduce_dekker_py(us))
                far = direct_array(name, us, _OWN)
                out[slow] = np.where(np.abs(us) <= LIMIT, mid, far)
        return out

    array.__name__ = f"{name}_array"
    array.__doc__ = f"numpy twin of ``{name}_row`` (same bits)."
    return array


def _acoscos_np(u, k, hi, lo):
    odd = _parity_py(k) != 0.0
    return np.where(odd, _pi_minus_py(np.abs(hi), np.where(hi >= 0.0, lo, -lo)), np.abs(hi))


atantan_array = _twin("atantan", lambda u, k, hi, lo: np.where(k == 0.0, u, hi), _reduce_py)
asinsin_array = _twin(
    "asinsin",
    lambda u, k, hi, lo: np.where(k == 0.0, u, np.where(_parity_py(k) != 0.0, -hi, hi)),
    _reduce_py,
)
acoscos_array = _twin("acoscos", _acoscos_np, _reduce_py)
acotcot_array = _twin(
    "acotcot", lambda u, k, hi, lo: np.where(hi < 0.0, _pi_plus_py(hi, lo), hi + 0.0), _reduce_cw_py
)

ARRAYS = {
    "atantan": atantan_array,
    "asinsin": asinsin_array,
    "acoscos": acoscos_array,
    "acotcot": acotcot_array,
}
ROWS = {
    "atantan": atantan_row,
    "asinsin": asinsin_row,
    "acoscos": acoscos_row,
    "acotcot": acotcot_row,
}
SCALARS = {
    "atantan": atantan_scalar,
    "asinsin": asinsin_scalar,
    "acoscos": acoscos_scalar,
    "acotcot": acotcot_scalar,
}
