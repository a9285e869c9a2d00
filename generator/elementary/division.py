"""Division of a row by one scalar, correctly rounded, without a division per value.

The interpreter's ``x / s`` with ``s`` the same for a whole row (operand mode ``vs``: a divisor
that depends on x, y or both, not on z) is 49 of the 114 divisions in the per-point blocks of the
50 stored eq. (13) formulas. A hardware division (``vdivpd``, barely pipelined) costs about 2 cycles a
value on the Intel Xeon, six times a product in the same loop, and there the divider bounds the
median formula. Here the row pays one division, for ``y = 1/s``, and each value a product and
four fused multiply-adds, with **the bits of** ``x / s`` (IEEE division, round to nearest),
which is what the numpy reference computes: nothing changes but the time (2.4-2.7x faster on
the Xeon: ``benchmarks/row_division.py``).

For each ``x`` (``u = 2**-53``; the FMA rounds once):

1. ``q0 = RN(x*y)``: ``y = RN(1/s)`` is within ``u`` of ``1/s`` (relative), so ``q0`` is
   within two ulps of ``x/s``.
2. ``r0 = RN(x - s*q0)``, ``q1 = RN(q0 + r0*y)``: before its rounding ``q0 + r0*y`` differs from
   ``x/s`` by at most ``|x/s - q0| * (2u + u**2)``, a few 2**-52 of an ulp, so ``q1`` is within
   one ulp of ``x/s`` (a faithful quotient).
3. ``r1 = x - s*q1`` is then exactly a double (the remainder of a faithful quotient: Boldo and
   Daumas 2003; Handbook of Floating-Point Arithmetic, 2nd ed., section 4.7), which the FMA
   returns exactly, and ``q2 = RN(q1 + r1*y)`` is ``RN(x/s)``: Markstein's theorem (1990; the
   same section), whose hypotheses are these — ``y`` within half an ulp of ``1/s``, ``q1``
   within one ulp of ``x/s``, no underflow or overflow on the way.

Where those hypotheses could fail the row takes ``x / s`` itself: a divisor outside
``[2**-100, 2**100]`` in magnitude (zero, inf and NaN included) for the whole row, and for the
whole row again when one value is neither 0 nor within ``[2**-900, 2**900]`` in magnitude (inf,
NaN, subnormal, huge). Inside those bounds ``x/s`` lies within ``[2**-1000, 2**1000]``, every
remainder is 0 or above 2**-1006, all normal. ``x = 0`` takes ``q0`` (``±0`` with the quotient's
sign; the two corrections would turn ``-0`` into ``+0``).

The fast loop writes the destination row while it checks, so it runs only when that row is not
the dividend's (the row is recomputed from an intact source; the compiler's register allocation
frees an operand's row only after the result has its own, and an in-place loop would not
vectorise anyway). It needs the FMA instruction (``llvm.fma``; without it LLVM calls the C library's
``fma``, exact but slow): :data:`ROW_DIVISION` says whether the CPU numba compiles for has it.

Tests: ``tests/generator/test_division.py`` (random quotients over the whole exponent range,
quotients built next to a rounding midpoint, exact quotients, every special value and the range
bounds, against numpy's ``/`` bit for bit); the evaluator's fast == reference tests cover its use.
"""

from __future__ import annotations

from llvmlite import binding, ir
from numba import njit, types
from numba.core import config
from numba.extending import intrinsic

from surfgen.generator.jit.options import INLINE, KERNEL

S_MIN = 2.0**-100  # |s| bounds of the fast path (a row's divisor)
S_MAX = 2.0**100
X_MIN = 2.0**-900  # |x| bounds of the fast path (0 aside)
X_MAX = 2.0**900


@intrinsic
def fma(typingctx, a, b, c):
    """``a*b + c`` rounded once (LLVM's ``llvm.fma.f64``: the FMA instruction, vectorised)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [d], ir.FunctionType(d, [d, d, d]))
        return builder.call(fn, args)

    return sig, codegen


def _codegen_has_fma() -> bool:
    """Whether the CPU numba compiles for has FMA: its configured features, else the host's
    (numba's default target); ``False`` for another named CPU, whose features are unknown here."""
    if config.CPU_FEATURES:
        features = config.CPU_FEATURES
    elif config.CPU_NAME in (None, "", "host"):
        features = binding.get_host_cpu_features().flatten()
    else:
        return False
    return "+fma" in features.split(",")


ROW_DIVISION = _codegen_has_fma()


@njit(**INLINE)
def div_row_by_scalar(W, d, a, s, n):
    """``W[d, k] = W[a, k] / s`` for ``k < n``, the bits of IEEE division (module docstring);
    returns whether the FMA path gave them (else the row was divided plainly)."""
    if d != a and abs(s) >= S_MIN and abs(s) <= S_MAX:
        y = 1.0 / s
        ms = -s
        bad = False
        for k in range(n):
            x = W[a, k]
            q0 = x * y
            r0 = fma(ms, q0, x)
            q1 = fma(r0, y, q0)
            r1 = fma(ms, q1, x)
            q2 = fma(r1, y, q1)
            W[d, k] = q2 if x != 0.0 else q0
            ax = abs(x)
            inside = (ax <= X_MAX) & ((ax >= X_MIN) | (ax == 0.0))  # False for NaN
            bad |= not inside
        if not bad:
            return True
    for k in range(n):
        W[d, k] = W[a, k] / s
    return False


@njit(**KERNEL)
def div_row_by_scalar_call(W, d, a, s, n):
    """:func:`div_row_by_scalar` as a function of its own (for the tests and benchmarks)."""
    return div_row_by_scalar(W, d, a, s, n)
