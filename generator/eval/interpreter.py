"""The tape interpreter: one block of code rows over the W rows of a tile (tape format:
compiler.py). :mod:`surfgen.generator.eval.grid_driver` drives it over a grid, :mod:`surfgen.generator.eval.point_driver`
over lists of points, lattices and grid edges.

Kernels are dumb: arrays and scalars in, arrays out; :mod:`surfgen.generator.eval.tape` validates
before calling. ``error_model='numpy'`` so that 0/0 and 1/0 give NaN and inf instead of raising;
no fastmath (NaN and inf are normal values here), hence no FMA contraction either (the one
explicit FMA sequence, a row divided by a scalar, is proven to give the division's bits). Every
transcendental function is surfgen's own (:mod:`surfgen.generator.elementary`): a row function
that runs a whole W row, whose numpy twin the reference evaluator calls, so results are
bit-identical to the reference on every CPU. No C library maths is called here.

The interpreter is compiled once, as a C function (:func:`load_interpreter`), and the kernels
call it through a pointer (:func:`run_code_far`, at the end of this file): numba would otherwise
compile its code into every kernel that calls it. In the same way the interpreter runs its cheap
operations inline and calls its heavy ones (every elementary function, the round trips, ``pow``,
the series) through the row table (:mod:`surfgen.generator.eval.row_calls`), each compiled once as a C
function of its own (:mod:`surfgen.generator.eval.row_functions`) instead of again in every layer above.
"""

from __future__ import annotations

import ctypes
import logging
import math
import threading

import numpy as np
from llvmlite import binding as llvm
from llvmlite import ir
from numba import carray, cfunc, njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from surfgen.generator.elementary import REGISTRY as _E
from surfgen.generator.elementary.division import ROW_DIVISION, div_row_by_scalar
from surfgen.generator.eval.compiler import M_S, M_SV, M_V, M_VS, M_VV, OP
from surfgen.generator.eval.row_calls import (
    SLOT,
    c_arguments,
    far_row,
    require_c_arrays,
    require_integers,
)
from surfgen.generator.jit.cache import c_function_cached
from surfgen.generator.jit.interleave import evaluator_compile
from surfgen.generator.jit.options import C_FUNCTION, INLINE, KERNEL

log = logging.getLogger(__name__)


# Opcode numbers as globals (numba freezes them at compile time; the table is append-only).
OP_COPY = OP["copy"]
OP_NEG = OP["neg"]
OP_ABS = OP["abs"]
OP_SQRT = OP["sqrt"]
OP_SIGN = OP["sign"]
OP_FLOOR = OP["floor"]
OP_CEIL = OP["ceil"]
OP_SQUARE = OP["square"]
OP_RECIP = OP["recip"]
OP_USIGN = OP["usign"]
OP_POWI = OP["powi"]
OP_ADD = OP["add"]
OP_SUB = OP["sub"]
OP_MUL = OP["mul"]
OP_DIV = OP["div"]
OP_POW = OP["pow"]
OP_MIN = OP["min"]
OP_MAX = OP["max"]
OP_ATAN2 = OP["atan2"]
OP_RATIO1 = OP["ratio1"]
OP_LT = OP["lt"]
OP_LE = OP["le"]
OP_EQ = OP["eq"]
OP_NE = OP["ne"]
OP_AND = OP["and"]
OP_OR = OP["or"]
OP_NOT = OP["not"]
OP_PICK = OP["pick"]
OP_PICKN = OP["pickn"]
OP_FMOD = OP["fmod"]
OP_TRUNC = OP["trunc"]
EPS = 1e-12  # logic.EPS: fparser's comparison tolerance

# pow's rows (:func:`_power_vs` and its kin apply the x^c convention to them).
_pow_vv = _E["pow"].row_vv
_pow_vs = _E["pow"].row_vs
_pow_sv = _E["pow"].row_sv

# The unary operations that run behind the row table (far.py): the slots named after an opcode
# (the binary ones are named by operand mode), by opcode; -1 for the others.
_UNARY_SLOT = np.full(max(OP.values()) + 1, -1, dtype=np.int64)
for _name, _slot in SLOT.items():
    if _name in OP:
        _UNARY_SLOT[OP[_name]] = _slot
SLOT_POW_VV, SLOT_POW_VS, SLOT_POW_SV = SLOT["pow_vv"], SLOT["pow_vs"], SLOT["pow_sv"]
SLOT_ATAN2_VV, SLOT_ATAN2_VS, SLOT_ATAN2_SV = SLOT["atan2_vv"], SLOT["atan2_vs"], SLOT["atan2_sv"]


@intrinsic
def _cycles(typingctx):
    """The CPU's cycle counter (for profiles only)."""
    sig = types.int64()

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(i64, []), "llvm.readcyclecounter"
        )
        return builder.call(fn, [])

    return sig, codegen


# ----------------------------------------------------------------------------- scalar helpers


@njit(**INLINE)
def unsigned(i):
    """Index ``i`` (never negative) as unsigned: numba checks a signed index for a negative
    value to wrap around, a compare and a select at every load of a gather."""
    return np.uint64(i)


@njit(**INLINE)
def _usign(u):
    """constituents.unit_sign: +1 for u >= 0 (also -0), -1 below, NaN for NaN."""
    if u >= 0.0:
        return 1.0
    if u < 0.0:
        return -1.0
    return u


@njit(**INLINE)
def _sign(u):
    """np.sign: sign(+-0) = +0, NaN stays NaN."""
    if u > 0.0:
        return 1.0
    if u < 0.0:
        return -1.0
    if u == 0.0:
        return 0.0
    return u


@njit(**INLINE)
def _minimum(a, b):
    """np.minimum: NaN propagates; for equal operands (+0, -0) numpy returns the second."""
    if a < b or a != a:
        return a
    return b


@njit(**INLINE)
def _maximum(a, b):
    if a > b or a != a:
        return a
    return b


@njit(**INLINE)
def _ratio1(a, b):
    q = a / b
    if a == 0.0 and b == 0.0:
        return 1.0
    return q


@njit(**INLINE)
def _truth(v):
    """logic.truth: |v| >= 0.5, NaN false."""
    return abs(v) >= 0.5


@njit(**INLINE)
def _is_logic2(op):
    return (OP_LT <= op <= OP_OR) or op == OP_PICK or op == OP_PICKN or op == OP_FMOD  # noqa: SIM109 (numba)


@njit(**INLINE)
def _logic2(op, a, b):
    """The two-operand operations of logic.py, value for value."""
    if op == OP_LT:
        return 1.0 if a < b - EPS else 0.0
    if op == OP_LE:
        return 1.0 if a <= b + EPS else 0.0
    if op == OP_EQ:
        return 1.0 if abs(a - b) <= EPS else 0.0
    if op == OP_NE:
        return 1.0 if abs(a - b) > EPS else 0.0
    if op == OP_AND:
        return 1.0 if _truth(a) and _truth(b) else 0.0
    if op == OP_OR:
        return 1.0 if _truth(a) or _truth(b) else 0.0
    if op == OP_PICK:
        return b if _truth(a) else 0.0
    if op == OP_PICKN:
        return 0.0 if _truth(a) else b
    return np.fmod(a, b)  # OP_FMOD (C fmod: exact)


@njit(**INLINE)
def _trunc(u):
    return np.floor(u) if u >= 0.0 else np.ceil(u)


@njit(**INLINE)
def _pow_rule(u, e, p):
    """The ``x^c`` convention (elementary.POW_SHORTCUTS) applied to ``p = pow(u, e)``:
    branch-free selects, so the loop that applies it vectorises."""
    r = p
    r = u * u if e == 2.0 else r
    r = math.sqrt(u) if e == 0.5 else r
    r = 1.0 / u if e == -1.0 else r
    r = u if e == 1.0 else r
    return 1.0 if e == 0.0 else r


@njit(**INLINE)
def _power_vs(W, d, a, s, n):
    """W[d] = W[a]^s: the shortcut loop for s in POW_SHORTCUTS, else surfgen's pow."""
    if s == 2.0 or s == 0.5 or s == -1.0 or s == 1.0 or s == 0.0:
        for k in range(n):
            u = W[a, k]
            W[d, k] = _pow_rule(u, s, u)
    else:
        _pow_vs(W, d, a, s, n)


@njit(**INLINE)
def _power_vv(W, d, a, b, n):
    """W[d] = W[a]^W[b] (d differs from a and b: the compiler never writes in place)."""
    _pow_vv(W, d, a, b, n)
    for k in range(n):
        W[d, k] = _pow_rule(W[a, k], W[b, k], W[d, k])


@njit(**INLINE)
def _power_sv(W, d, s, b, n):
    _pow_sv(W, d, s, b, n)
    for k in range(n):
        W[d, k] = _pow_rule(s, W[b, k], W[d, k])


@njit(**KERNEL)
def _series_exact(x, r, p):
    """sum_{i=-p}^{p} (1 - us(x-a) us(x-b)) (x - a), a = r(i-1), b = r i: as the reference."""
    total = 0.0
    for i in range(-p, p + 1):
        a = r * (i - 1)
        b = r * i
        total = total + (1.0 - _usign(x - a) * _usign(x - b)) * (x - a)
    return total


@njit(**KERNEL)
def _series(x, r, p):
    """The same sum in O(1): the selectors are 2 on [a, b), so one term survives and every
    other term adds a zero, which leaves the sum bit-identical (see constituents.py)."""
    if x != x or abs(x) > 1e307:  # NaN, inf (0*inf) and overflow of x - a: the slow way
        return _series_exact(x, r, p)
    q = x / r
    if q < -(p + 2.0) or q > p + 2.0:
        return 0.0
    i0 = int(np.floor(q)) + 1
    for i in range(i0 - 1, i0 + 2):
        if -p <= i <= p:
            a = r * (i - 1)
            if a <= x and x < r * i:
                return 0.0 + 2.0 * (x - a)  # +0 + ...: the sum's sign of zero (x = -0)
    return 0.0


# ----------------------------------------------------------------------------- row operations
#
# Every operation reads and writes rows of the register file W (n_vector, tile) by index:
# creating array views per instruction costs reference counting that, per row of a few
# hundred points, is as expensive as the arithmetic.


@njit(**INLINE)
def _segsum(W, d, a, n, consts, base):
    """W[d] = 0.5 * sum over segments of selector * line, in the reference's order."""
    kind = consts[base]
    nseg = int(consts[base + 1])
    for k in range(n):
        x = W[a, k]
        total = 0.0
        for s in range(nseg):
            q = base + 2 + 6 * s
            sel = 1.0 - _usign(x - consts[q]) * _usign(x - consts[q + 1])
            if kind == 0.0:  # fcc: ((y1-y0) x + y0 x1 - y1 x0) / (x1 - x0)
                line = (consts[q + 2] * x + consts[q + 3] - consts[q + 4]) / consts[q + 5]
            else:  # fcc8: slope x + intercept
                line = consts[q + 2] * x + consts[q + 3]
            total = total + sel * line
        W[d, k] = 0.5 * total


@njit(**INLINE)
def _series_special(x):
    """The lanes :func:`_series` takes the slow way: NaN, inf and |x| > 1e307."""
    return not (abs(x) <= 1e307)


@njit(**INLINE)
def _series_lanes(x, r, inv_r, fp):
    """:func:`_series` without a branch, for the other lanes (the loop that calls it vectorises):
    three candidate segments around x/r, their index as a float (exact: out of [-p, p] a
    candidate is dropped whatever its value), the same operations as ``_series`` on the one
    that holds x. At most one does: the segments [r(i-1), r i) tile the line, each bound the
    same product for both its segments. So which candidates are tried changes nothing as long
    as the one holding x is among them: x times 1/r (a multiplication instead of a division)
    is within a few ulps of x/r, and the window of three covers an index off by one. Far from
    [-p, p] (``_series``'s early exit) no candidate is in range, so the sum is 0 there too."""
    i = np.floor(x * inv_r)
    out = _series_candidate(x, r, fp, i, 0.0)
    out = _series_candidate(x, r, fp, i + 1.0, out)
    return _series_candidate(x, r, fp, i + 2.0, out)


@njit(**INLINE)
def _series_candidate(x, r, fp, i, out):
    """``2(x - a) + 0`` when segment i, [a, b) = [r(i-1), r i), holds x and -p <= i <= p (as
    :func:`_series` computes it), else ``out``: a select."""
    lo = r * (i - 1.0)
    hit = (i >= -fp) & (i <= fp) & (lo <= x) & (x < r * i)
    return (0.0 + 2.0 * (x - lo)) if hit else out


@njit(**INLINE)
def _series_row(W, d, a, n, consts, base):
    r = consts[base]
    p = int(consts[base + 1])
    if consts[base + 2] != 0.0:
        for k in range(n):
            W[d, k] = _series_exact(W[a, k], r, p)
        return
    # NaN, inf and huge lanes are rare: count them, save them (d may equal a), run the
    # branch-free loop over the row, then patch them the slow way.
    cnt = 0
    for k in range(n):
        cnt += 1 if _series_special(W[a, k]) else 0
    if cnt > 0:
        idx = np.empty(cnt, np.int64)
        val = np.empty(cnt, np.float64)
        j = 0
        for k in range(n):
            if _series_special(W[a, k]):
                idx[j] = k
                val[j] = W[a, k]
                j += 1
    fp = float(p)
    inv_r = 1.0 / r
    for k in range(n):
        W[d, k] = _series_lanes(W[a, k], r, inv_r, fp)
    if cnt > 0:
        for j in range(cnt):
            W[d, idx[j]] = _series(val[j], r, p)


@njit(**KERNEL)
def _unary(op, W, d, a, n, consts, imm, T):
    """The operations of one vector operand but the cheap ones (:func:`run_code` runs those)."""
    slot = _UNARY_SLOT[op]
    if slot >= 0:  # an elementary function, a round trip, a series: behind the row table
        far_row(slot, W, d, a, 0, 0.0, n, consts, imm)
    elif op == OP_USIGN:
        for k in range(n):
            W[d, k] = _usign(W[a, k])
    elif op == OP_POWI:  # programs of earlier versions: u^imm, now surfgen's pow
        far_row(SLOT_POW_VS, W, d, a, 0, float(imm), n, consts, 0)
    elif op == OP_SIGN:
        for k in range(n):
            W[d, k] = _sign(W[a, k])
    elif op == OP_FLOOR:
        for k in range(n):
            W[d, k] = np.floor(W[a, k])
    elif op == OP_CEIL:
        for k in range(n):
            W[d, k] = np.ceil(W[a, k])
    elif op == OP_NOT:
        for k in range(n):
            W[d, k] = 0.0 if _truth(W[a, k]) else 1.0
    elif op == OP_TRUNC:
        for k in range(n):
            W[d, k] = _trunc(W[a, k])


@njit(**KERNEL)
def _binary_vv(op, W, d, a, b, n, consts):
    """The operations of two operands but + - * / (:func:`run_code` runs those)."""
    if op == OP_POW:
        far_row(SLOT_POW_VV, W, d, a, b, 0.0, n, consts, 0)
    elif op == OP_MIN:
        for k in range(n):
            W[d, k] = _minimum(W[a, k], W[b, k])
    elif op == OP_MAX:
        for k in range(n):
            W[d, k] = _maximum(W[a, k], W[b, k])
    elif op == OP_ATAN2:
        far_row(SLOT_ATAN2_VV, W, d, a, b, 0.0, n, consts, 0)
    elif op == OP_RATIO1:
        for k in range(n):
            W[d, k] = _ratio1(W[a, k], W[b, k])
    elif _is_logic2(op):
        for k in range(n):
            W[d, k] = _logic2(op, W[a, k], W[b, k])


@njit(**KERNEL)
def _binary_vs(op, W, d, a, s, n, consts):
    """The operations of two operands but + - * / (:func:`run_code` runs those)."""
    if op == OP_POW:
        far_row(SLOT_POW_VS, W, d, a, 0, s, n, consts, 0)
    elif op == OP_MIN:
        for k in range(n):
            W[d, k] = _minimum(W[a, k], s)
    elif op == OP_MAX:
        for k in range(n):
            W[d, k] = _maximum(W[a, k], s)
    elif op == OP_ATAN2:
        far_row(SLOT_ATAN2_VS, W, d, a, 0, s, n, consts, 0)
    elif op == OP_RATIO1:
        for k in range(n):
            W[d, k] = _ratio1(W[a, k], s)
    elif _is_logic2(op):
        for k in range(n):
            W[d, k] = _logic2(op, W[a, k], s)


@njit(**KERNEL)
def _binary_sv(op, W, d, s, b, n, consts):
    """The operations of two operands but + - * / (:func:`run_code` runs those)."""
    if op == OP_POW:
        far_row(SLOT_POW_SV, W, d, 0, b, s, n, consts, 0)
    elif op == OP_MIN:
        for k in range(n):
            W[d, k] = _minimum(s, W[b, k])
    elif op == OP_MAX:
        for k in range(n):
            W[d, k] = _maximum(s, W[b, k])
    elif op == OP_ATAN2:
        far_row(SLOT_ATAN2_SV, W, d, 0, b, s, n, consts, 0)
    elif op == OP_RATIO1:
        for k in range(n):
            W[d, k] = _ratio1(s, W[b, k])
    elif _is_logic2(op):
        for k in range(n):
            W[d, k] = _logic2(op, s, W[b, k])


@njit(**INLINE)
def run_code(code, c0, c1, consts, W, S, T, n, prof):
    """Run code rows [c0, c1) on the first n columns of W; with a non-empty ``prof``,
    add the cycles each row takes to ``prof[row]``.

    The cheap operations (+, -, *, / in every operand mode; copy, neg, abs, square, recip,
    sqrt) run here, inline (a row divided by a scalar with FMAs: one division per row, the
    same bits); only the others call :func:`_unary` and ``_binary_*``. A call of
    those costs 15-35 ns whatever ``n`` (numba increments and decrements the reference counts
    of its array arguments, atomic operations), as much as the loop of a cheap operation over
    a few hundred points; inline, one dispatch costs a few ns. The arithmetic is the same, so
    are the bits.
    """
    profiling = prof.size > 0
    t0 = 0
    for pc in range(c0, c1):
        if profiling:
            t0 = _cycles()
        op = code[pc, 0]
        mode = code[pc, 1]
        d = code[pc, 2]
        a = code[pc, 3]
        b = code[pc, 4]
        if mode == M_VV:
            if op == OP_MUL:
                for k in range(n):
                    W[d, k] = W[a, k] * W[b, k]
            elif op == OP_ADD:
                for k in range(n):
                    W[d, k] = W[a, k] + W[b, k]
            elif op == OP_SUB:
                for k in range(n):
                    W[d, k] = W[a, k] - W[b, k]
            elif op == OP_DIV:
                for k in range(n):
                    W[d, k] = W[a, k] / W[b, k]
            else:
                _binary_vv(op, W, d, a, b, n, consts)
        elif mode == M_VS:
            s = S[b]
            if op == OP_MUL:
                for k in range(n):
                    W[d, k] = W[a, k] * s
            elif op == OP_ADD:
                for k in range(n):
                    W[d, k] = W[a, k] + s
            elif op == OP_SUB:
                for k in range(n):
                    W[d, k] = W[a, k] - s
            elif op == OP_DIV:
                if ROW_DIVISION:  # one division per row, the same bits (elementary/division.py)
                    div_row_by_scalar(W, d, a, s, n)
                else:
                    for k in range(n):
                        W[d, k] = W[a, k] / s
            else:
                _binary_vs(op, W, d, a, s, n, consts)
        elif mode == M_V:
            if op == OP_COPY:
                for k in range(n):
                    W[d, k] = W[a, k]
            elif op == OP_ABS:
                for k in range(n):
                    W[d, k] = abs(W[a, k])
            elif op == OP_SQUARE:
                for k in range(n):
                    W[d, k] = W[a, k] * W[a, k]
            elif op == OP_RECIP:
                for k in range(n):
                    W[d, k] = 1.0 / W[a, k]
            elif op == OP_NEG:
                for k in range(n):
                    W[d, k] = -W[a, k]
            elif op == OP_SQRT:
                for k in range(n):
                    W[d, k] = math.sqrt(W[a, k])
            else:
                _unary(op, W, d, a, n, consts, code[pc, 5], T)
        elif mode == M_SV:
            s = S[a]
            if op == OP_MUL:
                for k in range(n):
                    W[d, k] = s * W[b, k]
            elif op == OP_ADD:
                for k in range(n):
                    W[d, k] = s + W[b, k]
            elif op == OP_SUB:
                for k in range(n):
                    W[d, k] = s - W[b, k]
            elif op == OP_DIV:
                for k in range(n):
                    W[d, k] = s / W[b, k]
            else:
                _binary_sv(op, W, d, s, b, n, consts)
        elif mode == M_S:
            s = S[a]
            for k in range(n):
                W[d, k] = s
        if profiling:
            prof[pc] += _cycles() - t0


# ----------------------------------------------------------------------------- behind a pointer
#
# numba links the code of every jitted function a kernel calls into that kernel, and LLVM
# optimises and emits it again there: the interpreter (then with every elementary function's
# vector loop, about a minute of LLVM) was compiled once more into the grid driver, the points
# kernels and the walls' kernel, each time it or they changed. Instead the interpreter is
# compiled once, as a C function (:data:`INTERPRETER`, cached by numba like the kernels), and
# the kernels call it through a pointer (:func:`run_code_far`): their own compile is their own
# code only.
#
# The pointer lives in one cell of this process, an external symbol of the kernels' machine
# code (so the code numba caches holds no address). Until the interpreter is loaded, the cell
# points to a small Python function that loads (or compiles) it, fills the cell and forwards the
# call: a kernel can never call an empty cell, whatever the order of first calls or a fork.

_CELL_SYMBOL = "surfgen_interpreter_cell_v1"
_I64 = types.int64
# code, its rows; c0, c1; consts, size; W, rows, columns; S, size; T, columns; n; prof, size
_C_SIGNATURE = types.void(
    types.voidptr, _I64, _I64, _I64, types.voidptr, _I64, types.voidptr, _I64, _I64,
    types.voidptr, _I64, types.voidptr, _I64, _I64, types.voidptr, _I64,
)  # fmt: skip
_C_PROTOTYPE = ctypes.CFUNCTYPE(
    None, *[ctypes.c_void_p if a == types.voidptr else ctypes.c_int64 for a in _C_SIGNATURE.args]
)


def _run_code_c(code_p, n_code, c0, c1, consts_p, n_consts, w_p, w_rows, tile, s_p, n_s, t_p,
                t_cols, n, prof_p, n_prof):  # fmt: skip
    """:func:`run_code` on raw C-contiguous buffers (the arrays' data and shapes)."""
    code = carray(code_p, (n_code, 6), np.int64)
    consts = carray(consts_p, n_consts, np.float64)
    W = carray(w_p, (w_rows, tile), np.float64)
    S = carray(s_p, n_s, np.float64)
    T = carray(t_p, (2, t_cols), np.float64)
    prof = carray(prof_p, n_prof, np.float64)
    run_code(code, c0, c1, consts, W, S, T, n, prof)


INTERPRETER = None  # the compiled C function (numba's CFunc) once loaded
_LOAD_LOCK = threading.Lock()


def load_interpreter():
    """Load the interpreter and its rows (:func:`surfgen.generator.eval.row_functions.load_rows`) from
    numba's cache (or compile them, about a minute on one CPU the first time on a machine) and
    point the kernels' cell at it; returns numba's ``CFunc``. Thread-safe."""
    global INTERPRETER
    from surfgen.generator.eval.row_functions import load_rows

    with _LOAD_LOCK:
        if INTERPRETER is None:
            load_rows()  # first: the interpreter calls them
            with evaluator_compile():  # numba's C functions send no compile event
                compiled = cfunc(_C_SIGNATURE, **C_FUNCTION)(_run_code_c)
            _CELL.value = compiled.address
            INTERPRETER = compiled
    return INTERPRETER


def interpreter_asm() -> str:
    """The interpreter's machine code (assembly), compiled first if need be; empty when it was
    loaded from numba's on-disk cache (numba keeps no assembly of cached code: inspect it in a
    process with an empty ``NUMBA_CACHE_DIR``)."""
    from surfgen.generator.eval.row_functions import rows_asm

    return load_interpreter()._library.get_asm_str() + "\n" + rows_asm()


def interpreter_loaded() -> bool:
    """Whether this process has loaded (or compiled) the interpreter."""
    return INTERPRETER is not None


def interpreter_cached() -> bool:
    """Whether numba's on-disk cache holds the interpreter for this machine and this code (then
    loading it takes a fraction of a second). True when that cannot be told (numba's internals
    moved): the caller then does what it always did."""
    from surfgen.generator.eval.row_functions import rows_cached

    return c_function_cached(_run_code_c, "the interpreter") and rows_cached()


def _first_call(*args, _load=load_interpreter) -> None:
    """The cell's first target: load the interpreter, then run the call. surfgen's entry points
    load it before they call a kernel, so this runs only for a kernel called directly. An error
    here cannot reach the kernel's caller (ctypes prints it): the call's values are then NaN,
    never stale memory."""
    try:
        compiled = _load()
    except BaseException:
        log.exception("cannot load surfgen's interpreter: this evaluation gives NaN")
        _, _, _, _, _, _, w_p, w_rows, tile, *_ = args
        rows = ctypes.cast(w_p, ctypes.POINTER(ctypes.c_double))
        np.ctypeslib.as_array(rows, shape=(w_rows, tile))[:] = np.nan
        return
    compiled.ctypes(*args)


_FIRST_CALL = _C_PROTOTYPE(_first_call)  # kept alive as long as the cell may point to it
_CELL = ctypes.c_void_p(ctypes.cast(_FIRST_CALL, ctypes.c_void_p).value)
llvm.add_symbol(_CELL_SYMBOL, ctypes.addressof(_CELL))


@intrinsic
def run_code_far(typingctx, code, c0, c1, consts, W, S, T, n, prof):
    """:func:`run_code`, called through the interpreter's pointer (its code is not compiled into
    the caller). Every array must be C-contiguous (the kernels' are)."""
    arrays = ((code, 2, types.int64), (consts, 1, types.float64), (W, 2, types.float64))
    arrays += ((S, 1, types.float64), (T, 2, types.float64), (prof, 1, types.float64))
    require_c_arrays("run_code_far", arrays)
    require_integers("run_code_far", (c0, c1, n))
    sig = types.void(code, c0, c1, consts, W, S, T, n, prof)

    def codegen(context, builder, signature, args):
        whole, buffer = c_arguments(context, builder, signature, args)
        code_p, (n_code, _) = buffer(0)
        consts_p, (n_consts,) = buffer(3)
        w_p, (w_rows, tile) = buffer(4)
        s_p, (n_s,) = buffer(5)
        t_p, (_, t_cols) = buffer(6)
        prof_p, (n_prof,) = buffer(8)
        values = [code_p, n_code, whole(1), whole(2), consts_p, n_consts, w_p, w_rows, tile]
        values += [s_p, n_s, t_p, t_cols, whole(7), prof_p, n_prof]
        fnty = ir.FunctionType(ir.VoidType(), [v.type for v in values])
        module = builder.module
        cell = module.globals.get(_CELL_SYMBOL)
        if cell is None:
            cell = ir.GlobalVariable(module, fnty.as_pointer(), _CELL_SYMBOL)
        builder.call(builder.load(cell), values)
        return context.get_dummy_value()

    return sig, codegen
