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

Algorithms (derived from the literature; coefficients from ``tools/explog_coefficients.py``):

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

import numpy as np
from numba import njit

from surfgen.generator.elementary.explog_kernels import (
    _NP_GLOBALS,
    _acosh,
    _apply1,
    _apply2,
    _asinh,
    _atanh,
    _cbrt,
    _cosh,
    _exp,
    _log,
    _log10,
    _pow,
    _pow3,
    _pow15,
    _pow_exact_lane,
    _sinh,
    _tanh,
)
from surfgen.generator.jit.options import INLINE, KERNEL

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
