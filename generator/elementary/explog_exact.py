"""The exact operations of surfgen's exp and log family: bit casts (LLVM bitcasts in numba,
``.view`` in numpy), a select, and the error-free sums, splits and products (Knuth, Veltkamp,
Dekker; no FMA) that the double-double cores of :mod:`.explog_kernels` are built from.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from surfgen.generator.elementary.explog_tables import SPLITTER, TINY_NORMAL, TWO52
from surfgen.generator.jit.options import FORCE_INLINE

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
