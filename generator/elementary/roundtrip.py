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

Accuracy: ``r`` is computed in double-double (Cody-Waite with pi as three doubles and exact
Dekker products, no FMA) and rounded once, so the result is within 0.5 ulp plus about 2^-100
absolute of the exact value for ``|u| <= LIMIT = 2^50``; ``acos(cos u)`` and ``pi + r`` add one
more rounding of a double-double sum. The direct forms lose up to half the digits where ``asin``
and ``acos`` are ill-conditioned (``asin(sin u)`` near ``u = pi/2``: ``asin(1 - d)`` turns an
ulp of ``sin`` into ``1e-8``) and a few ulp elsewhere. Beyond ``LIMIT`` (and for inf/NaN) the
closed forms *are* the direct forms, computed with surfgen's elementary functions.

Every function exists as a numba row ``NAME_row(W, d, a, n)`` (``d != a``), a numba scalar and a
numpy twin ``NAME_array``, bit-identical (one shared arithmetic core, :func:`_reduce_py`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.elementary import REGISTRY

_OPTS = {"cache": True, "error_model": "numpy", "nogil": True}

ROUND_TRIPS = ("atantan", "asinsin", "acoscos", "acotcot")

LIMIT = 2.0**50  # |u| above this: the direct forms (k would not fit the exact products)

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


def _reduce_py(u):
    """``u = k*pi + hi + lo`` with ``hi + lo`` in [-pi/2, pi/2): returns ``(k, hi, lo)``.

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
    b = s - _C1
    e = (_C1 - (s - b)) + (-hi - b)
    return s + (e + (_C2 - lo))


def _pi_plus_py(hi, lo):
    """pi + (hi + lo) rounded once, for -pi/2 <= hi < 0."""
    s = _C1 + hi
    b = s - _C1
    e = (_C1 - (s - b)) + (hi - b)
    return s + (e + (_C2 + lo))


_reduce = njit(inline="always", **_OPTS)(_reduce_py)
_parity = njit(inline="always", **_OPTS)(_parity_py)
_pi_minus = njit(inline="always", **_OPTS)(_pi_minus_py)
_pi_plus = njit(inline="always", **_OPTS)(_pi_plus_py)

_sin = REGISTRY["sin"].scalar
_cos = REGISTRY["cos"].scalar
_tan = REGISTRY["tan"].scalar
_asin = REGISTRY["asin"].scalar
_acos = REGISTRY["acos"].scalar
_atan = REGISTRY["atan"].scalar

# ----------------------------------------------------------------------------- numba


@njit(inline="always", **_OPTS)
def _atantan_fast(u):
    k, hi, lo = _reduce(u)
    return u if k == 0.0 else hi


@njit(inline="always", **_OPTS)
def _asinsin_fast(u):
    k, hi, lo = _reduce(u)
    r = -hi if _parity(k) != 0.0 else hi
    return u if k == 0.0 else r


@njit(inline="always", **_OPTS)
def _acoscos_fast(u):
    k, hi, lo = _reduce(u)
    ahi = abs(hi)
    alo = lo if hi >= 0.0 else -lo
    far = _pi_minus(ahi, alo)
    return far if _parity(k) != 0.0 else ahi


@njit(inline="always", **_OPTS)
def _acotcot_fast(u):
    k, hi, lo = _reduce(u)
    neg = _pi_plus(hi, lo)
    return neg if hi < 0.0 else hi + 0.0


@njit(**_OPTS)
def atantan_scalar(u):
    if abs(u) <= LIMIT:
        return _atantan_fast(u)
    return _atan(_tan(u))


@njit(**_OPTS)
def asinsin_scalar(u):
    if abs(u) <= LIMIT:
        return _asinsin_fast(u)
    return _asin(_sin(u))


@njit(**_OPTS)
def acoscos_scalar(u):
    if abs(u) <= LIMIT:
        return _acoscos_fast(u)
    return _acos(_cos(u))


@njit(**_OPTS)
def acotcot_scalar(u):
    if abs(u) <= LIMIT:
        return _acotcot_fast(u)
    return _PI_2 - _atan(1.0 / _tan(u))


# Rows: loop 1 is branch-free (vectorised) and counts the arguments outside the fast range;
# loop 2 recomputes those, only when there are any. d != a (loop 2 reads the argument again).


@njit(**_OPTS)
def atantan_row(W, d, a, n):
    bad = 0
    for k in range(n):
        u = W[a, k]
        W[d, k] = _atantan_fast(u)
        bad += 0 if abs(u) <= LIMIT else 1
    if bad:
        for k in range(n):
            if not abs(W[a, k]) <= LIMIT:
                W[d, k] = atantan_scalar(W[a, k])


@njit(**_OPTS)
def asinsin_row(W, d, a, n):
    bad = 0
    for k in range(n):
        u = W[a, k]
        W[d, k] = _asinsin_fast(u)
        bad += 0 if abs(u) <= LIMIT else 1
    if bad:
        for k in range(n):
            if not abs(W[a, k]) <= LIMIT:
                W[d, k] = asinsin_scalar(W[a, k])


@njit(**_OPTS)
def acoscos_row(W, d, a, n):
    bad = 0
    for k in range(n):
        u = W[a, k]
        W[d, k] = _acoscos_fast(u)
        bad += 0 if abs(u) <= LIMIT else 1
    if bad:
        for k in range(n):
            if not abs(W[a, k]) <= LIMIT:
                W[d, k] = acoscos_scalar(W[a, k])


@njit(**_OPTS)
def acotcot_row(W, d, a, n):
    bad = 0
    for k in range(n):
        u = W[a, k]
        W[d, k] = _acotcot_fast(u)
        bad += 0 if abs(u) <= LIMIT else 1
    if bad:
        for k in range(n):
            if not abs(W[a, k]) <= LIMIT:
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


_OWN = {name: REGISTRY[name].array for name in ("sin", "cos", "tan", "asin", "acos", "atan")}


def _twin(name: str, fast):
    def array(u) -> np.ndarray:
        u = np.asarray(u, np.float64)
        with np.errstate(all="ignore"):
            k, hi, lo = _reduce_py(u)
            out = fast(u, k, hi, lo)
            bad = ~(np.abs(u) <= LIMIT)
            if bad.any():
                out = np.where(bad, direct_array(name, u, _OWN), out)
        return np.asarray(out, np.float64)

    array.__name__ = f"{name}_array"
    array.__doc__ = f"numpy twin of ``{name}_row`` (same bits)."
    return array


atantan_array = _twin("atantan", lambda u, k, hi, lo: np.where(k == 0.0, u, hi))
asinsin_array = _twin(
    "asinsin",
    lambda u, k, hi, lo: np.where(k == 0.0, u, np.where(_parity_py(k) != 0.0, -hi, hi)),
)
acoscos_array = _twin(
    "acoscos",
    lambda u, k, hi, lo: np.where(
        _parity_py(k) != 0.0, _pi_minus_py(np.abs(hi), np.where(hi >= 0.0, lo, -lo)), np.abs(hi)
    ),
)
acotcot_array = _twin(
    "acotcot", lambda u, k, hi, lo: np.where(hi < 0.0, _pi_plus_py(hi, lo), hi + 0.0)
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
