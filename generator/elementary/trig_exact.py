"""The exact operations of surfgen's trigonometric functions, written once for numpy and numba:
selects, floor, sqrt, copysign, frexp, ldexp, table lookups (numpy calls in Python, numba
``@overload``s when jitted), :func:`_dual` (a plain-Python helper that numba compiles from the
same source), and the error-free sums and products (Knuth, Dekker; no FMA).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba.extending import overload

from surfgen.generator.elementary.trig_tables import _SPLIT, NAN
from surfgen.generator.jit.options import OVERLOAD

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


def _dual(func):
    """Make a plain-Python helper callable from jitted code: numba compiles the same source.

    Called from Python the function runs on numpy arrays or floats; called from a jitted
    function, numba's ``@overload`` hands it the very same function to compile for scalars.
    """

    @functools.wraps(func)
    def typer(*args):
        return func

    # Inlined by LLVM into every caller (``forceinline``: a call left in a loop would stop its
    # vectorisation), not by numba: numba's IR inlining ("always") typed the helper again at
    # every call site, 11 of the interpreter's 32 s of compiling (benchmarks/
    # interpreter_baseline.py: 32.3 -> 21.3 s, the same fields, the same speed).
    overload(func, jit_options={**OVERLOAD, "forceinline": True}, inline="never")(typer)
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
