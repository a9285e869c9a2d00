"""TEMPORARY backing of the elementary-function registry until ``trig.py``/``explog.py`` land.

The C library through numba (``math.sin`` -> libm ``sin``) for the rows and scalars, and the very
same libm symbols through ctypes for the numpy twins, so the two agree bit for bit on any CPU
(slowly: the twins make one foreign call per element). API: /work/wt/LIBM.md. Delete this module
once the registry points at surfgen's own functions.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import math

import numpy as np
from numba import njit

_OPTS = {"cache": True, "error_model": "numpy", "nogil": True}
_LIBM = ctypes.CDLL(ctypes.util.find_library("m") or "libm.so.6")


def _c(name: str, arity: int):
    fn = getattr(_LIBM, name)
    fn.restype = ctypes.c_double
    fn.argtypes = [ctypes.c_double] * arity
    uf = np.frompyfunc(fn, arity, 1)

    def array(*args):
        args = [np.asarray(a, np.float64) for a in args]
        return np.asarray(uf(*args), np.float64).reshape(
            np.broadcast_shapes(*(a.shape for a in args))
        )

    return array


@njit(**_OPTS)
def sin_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.sin(W[a, k])


@njit(**_OPTS)
def sin_scalar(x):
    return math.sin(x)


sin_array = _c("sin", 1)


@njit(**_OPTS)
def cos_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.cos(W[a, k])


@njit(**_OPTS)
def cos_scalar(x):
    return math.cos(x)


cos_array = _c("cos", 1)


@njit(**_OPTS)
def tan_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.tan(W[a, k])


@njit(**_OPTS)
def tan_scalar(x):
    return math.tan(x)


tan_array = _c("tan", 1)


@njit(**_OPTS)
def asin_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.asin(W[a, k])


@njit(**_OPTS)
def asin_scalar(x):
    return math.asin(x)


asin_array = _c("asin", 1)


@njit(**_OPTS)
def acos_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.acos(W[a, k])


@njit(**_OPTS)
def acos_scalar(x):
    return math.acos(x)


acos_array = _c("acos", 1)


@njit(**_OPTS)
def atan_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.atan(W[a, k])


@njit(**_OPTS)
def atan_scalar(x):
    return math.atan(x)


atan_array = _c("atan", 1)


@njit(**_OPTS)
def sinh_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.sinh(W[a, k])


@njit(**_OPTS)
def sinh_scalar(x):
    return math.sinh(x)


sinh_array = _c("sinh", 1)


@njit(**_OPTS)
def cosh_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.cosh(W[a, k])


@njit(**_OPTS)
def cosh_scalar(x):
    return math.cosh(x)


cosh_array = _c("cosh", 1)


@njit(**_OPTS)
def tanh_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.tanh(W[a, k])


@njit(**_OPTS)
def tanh_scalar(x):
    return math.tanh(x)


tanh_array = _c("tanh", 1)


@njit(**_OPTS)
def asinh_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.asinh(W[a, k])


@njit(**_OPTS)
def asinh_scalar(x):
    return math.asinh(x)


asinh_array = _c("asinh", 1)


@njit(**_OPTS)
def acosh_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.acosh(W[a, k])


@njit(**_OPTS)
def acosh_scalar(x):
    return math.acosh(x)


acosh_array = _c("acosh", 1)


@njit(**_OPTS)
def atanh_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.atanh(W[a, k])


@njit(**_OPTS)
def atanh_scalar(x):
    return math.atanh(x)


atanh_array = _c("atanh", 1)


@njit(**_OPTS)
def exp_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.exp(W[a, k])


@njit(**_OPTS)
def exp_scalar(x):
    return math.exp(x)


exp_array = _c("exp", 1)


@njit(**_OPTS)
def log_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.log(W[a, k])


@njit(**_OPTS)
def log_scalar(x):
    return math.log(x)


log_array = _c("log", 1)


@njit(**_OPTS)
def log10_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.log10(W[a, k])


@njit(**_OPTS)
def log10_scalar(x):
    return math.log10(x)


log10_array = _c("log10", 1)


@njit(**_OPTS)
def cbrt_row(W, d, a, n):
    for k in range(n):
        W[d, k] = np.cbrt(W[a, k])


@njit(**_OPTS)
def cbrt_scalar(x):
    return np.cbrt(x)


cbrt_array = _c("cbrt", 1)


@njit(**_OPTS)
def atan2_row_vv(W, d, a, b, n):
    for k in range(n):
        W[d, k] = math.atan2(W[a, k], W[b, k])


@njit(**_OPTS)
def atan2_row_vs(W, d, a, s, n):
    for k in range(n):
        W[d, k] = math.atan2(W[a, k], s)


@njit(**_OPTS)
def atan2_row_sv(W, d, s, b, n):
    for k in range(n):
        W[d, k] = math.atan2(s, W[b, k])


@njit(**_OPTS)
def atan2_scalar(p, q):
    return math.atan2(p, q)


atan2_array = _c("atan2", 2)


@njit(**_OPTS)
def pow_row_vv(W, d, a, b, n):
    for k in range(n):
        W[d, k] = W[a, k] ** W[b, k]


@njit(**_OPTS)
def pow_row_vs(W, d, a, s, n):
    for k in range(n):
        W[d, k] = W[a, k] ** s


@njit(**_OPTS)
def pow_row_sv(W, d, s, b, n):
    for k in range(n):
        W[d, k] = s ** W[b, k]


@njit(**_OPTS)
def pow_scalar(p, q):
    return p**q


pow_array = _c("pow", 2)
