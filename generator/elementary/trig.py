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

Coefficients: ``tools/trig_coefficients.py`` (mpmath Remez, relative error; degrees and fit
errors in the comments of the tables below). Accuracy (``tools/accuracy_trig.py``,
10**6 arguments each against mpmath, hard ranges included): max 0.77 ulp (sin, cos),
<= 0.71 ulp for the others; NaN results are the canonical
quiet NaN ``0x7ff8000000000000`` (so NaN bits agree too).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.elementary.trig_kernels import (
    _acos_fast,
    _asin_fast,
    _atan2_fast,
    _atan2_slow,
    _atan2_slow_lane,
    _atan_fast,
    _cos_fast,
    _cos_slow,
    _sin_fast,
    _sin_slow,
    _tan_fast,
    _tan_slow,
    _trig_slow_lane,
)
from surfgen.generator.jit.options import INLINE, KERNEL

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


# A scalar operand's row for _gather2. The gathers take int64 values, never literals: a literal
# argument (-1, or a count numba types as 0) compiles them again for each (6 signatures, 1.5 s).
_NO_ROW = np.int64(-1)


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
        idx, val = _gather1(W, a, n, np.int64(cnt))
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
        idx, vy, vx = _gather2(W, a, b, n, np.int64(cnt), 0.0, 0.0)
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
        idx, vy, vx = _gather2(W, a, _NO_ROW, n, np.int64(cnt), 0.0, s)
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
        idx, vy, vx = _gather2(W, _NO_ROW, b, n, np.int64(cnt), s, 0.0)
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
