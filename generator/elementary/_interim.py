"""TEMPORARY backing of the elementary-function registry until ``trig.py``/``explog.py`` land.

The C library through numba (``math.sin`` -> libm ``sin``) for the rows and scalars; the
"numpy twins" run the rows on a copy, so everything agrees bit for bit on any CPU. API: /work/wt/LIBM.md. Delete this module
once the registry points at surfgen's own functions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_OPTS = {"cache": True, "error_model": "numpy", "nogil": True}


def _twin1(row):
    """numpy-level twin through the row function itself: the same libm calls, same bits."""

    def array(x):
        x = np.asarray(x, np.float64)
        W = np.empty((2, x.size))
        W[0] = x.ravel()
        row(W, 1, 0, x.size)
        return W[1].reshape(x.shape)

    return array


def _twin2(row_vv):
    def array(p, q):
        p, q = np.broadcast_arrays(np.asarray(p, np.float64), np.asarray(q, np.float64))
        W = np.empty((3, p.size))
        W[0] = p.ravel()
        W[1] = q.ravel()
        row_vv(W, 2, 0, 1, p.size)
        return W[2].reshape(p.shape)

    return array


@njit(**_OPTS)
def sin_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.sin(W[a, k])


@njit(**_OPTS)
def sin_scalar(x):
    return math.sin(x)


sin_array = _twin1(sin_row)


@njit(**_OPTS)
def cos_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.cos(W[a, k])


@njit(**_OPTS)
def cos_scalar(x):
    return math.cos(x)


cos_array = _twin1(cos_row)


@njit(**_OPTS)
def tan_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.tan(W[a, k])


@njit(**_OPTS)
def tan_scalar(x):
    return math.tan(x)


tan_array = _twin1(tan_row)


@njit(**_OPTS)
def asin_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.asin(W[a, k])


@njit(**_OPTS)
def asin_scalar(x):
    return math.asin(x)


asin_array = _twin1(asin_row)


@njit(**_OPTS)
def acos_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.acos(W[a, k])


@njit(**_OPTS)
def acos_scalar(x):
    return math.acos(x)


acos_array = _twin1(acos_row)


@njit(**_OPTS)
def atan_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.atan(W[a, k])


@njit(**_OPTS)
def atan_scalar(x):
    return math.atan(x)


atan_array = _twin1(atan_row)


@njit(**_OPTS)
def sinh_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.sinh(W[a, k])


@njit(**_OPTS)
def sinh_scalar(x):
    return math.sinh(x)


sinh_array = _twin1(sinh_row)


@njit(**_OPTS)
def cosh_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.cosh(W[a, k])


@njit(**_OPTS)
def cosh_scalar(x):
    return math.cosh(x)


cosh_array = _twin1(cosh_row)


@njit(**_OPTS)
def tanh_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.tanh(W[a, k])


@njit(**_OPTS)
def tanh_scalar(x):
    return math.tanh(x)


tanh_array = _twin1(tanh_row)


@njit(**_OPTS)
def asinh_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.asinh(W[a, k])


@njit(**_OPTS)
def asinh_scalar(x):
    return math.asinh(x)


asinh_array = _twin1(asinh_row)


@njit(**_OPTS)
def acosh_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.acosh(W[a, k])


@njit(**_OPTS)
def acosh_scalar(x):
    return math.acosh(x)


acosh_array = _twin1(acosh_row)


@njit(**_OPTS)
def atanh_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.atanh(W[a, k])


@njit(**_OPTS)
def atanh_scalar(x):
    return math.atanh(x)


atanh_array = _twin1(atanh_row)


@njit(**_OPTS)
def exp_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.exp(W[a, k])


@njit(**_OPTS)
def exp_scalar(x):
    return math.exp(x)


exp_array = _twin1(exp_row)


@njit(**_OPTS)
def log_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.log(W[a, k])


@njit(**_OPTS)
def log_scalar(x):
    return math.log(x)


log_array = _twin1(log_row)


@njit(**_OPTS)
def log10_row(W, d, a, n):
    for k in range(n):
        W[d, k] = math.log10(W[a, k])


@njit(**_OPTS)
def log10_scalar(x):
    return math.log10(x)


log10_array = _twin1(log10_row)


@njit(**_OPTS)
def cbrt_row(W, d, a, n):
    for k in range(n):
        W[d, k] = np.cbrt(W[a, k])


@njit(**_OPTS)
def cbrt_scalar(x):
    return np.cbrt(x)


cbrt_array = _twin1(cbrt_row)


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


atan2_array = _twin2(atan2_row_vv)


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


pow_array = _twin2(pow_row_vv)
