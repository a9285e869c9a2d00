"""The one numba interpreter that runs every compiled formula (tape format: compiler.py).

Kernels are dumb: arrays and scalars in, arrays out; :mod:`surfgen.generator.fast` validates
before calling. ``error_model='numpy'`` so that 0/0 and 1/0 give NaN and inf instead of raising;
no fastmath (NaN and inf are normal values here), hence no FMA contraction either. Every
transcendental function is surfgen's own (:mod:`surfgen.generator.elementary`): a row function
that runs a whole W row, whose numpy twin the reference evaluator calls, so results are
bit-identical to the reference on every CPU. No C library maths is called here.

Layout of a run (:func:`run_grid`): the caller allocates the output and the stores
(:func:`grid_stores`); the x, y, z and yz stores are computed once (:func:`_prologue`,
:func:`_yz_rows`), then each slab of x indices (:func:`_slab`, one per thread chunk) computes
its xy and xz rows per i and the xyz block per (i, j) row of z values, in tiles of W rows,
writing straight into the output. Scratch is O(tile * n_vector) per thread plus the yz store.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from surfgen.generator.compiler import M_S, M_SV, M_V, M_VS, M_VV, OP
from surfgen.generator.elementary import REGISTRY as _E
from surfgen.generator.elementary import roundtrip as _rt

_OPTS = {"cache": True, "error_model": "numpy", "nogil": True}

# Opcode numbers as globals (numba freezes them at compile time; the table is append-only).
OP_COPY = OP["copy"]
OP_NEG = OP["neg"]
OP_ABS = OP["abs"]
OP_SIN = OP["sin"]
OP_COS = OP["cos"]
OP_TAN = OP["tan"]
OP_ASIN = OP["asin"]
OP_ACOS = OP["acos"]
OP_ATAN = OP["atan"]
OP_SINH = OP["sinh"]
OP_COSH = OP["cosh"]
OP_TANH = OP["tanh"]
OP_ASINH = OP["asinh"]
OP_ACOSH = OP["acosh"]
OP_ATANH = OP["atanh"]
OP_EXP = OP["exp"]
OP_LOG = OP["log"]
OP_LOG10 = OP["log10"]
OP_SQRT = OP["sqrt"]
OP_CBRT = OP["cbrt"]
OP_SIGN = OP["sign"]
OP_FLOOR = OP["floor"]
OP_CEIL = OP["ceil"]
OP_SQUARE = OP["square"]
OP_RECIP = OP["recip"]
OP_USIGN = OP["usign"]
OP_POWI = OP["powi"]
OP_SERIES = OP["series"]
OP_SEGSUM = OP["segsum"]
OP_ADD = OP["add"]
OP_SUB = OP["sub"]
OP_MUL = OP["mul"]
OP_DIV = OP["div"]
OP_POW = OP["pow"]
OP_MIN = OP["min"]
OP_MAX = OP["max"]
OP_ATAN2 = OP["atan2"]
OP_RATIO1 = OP["ratio1"]
OP_ATANTAN = OP["atantan"]
OP_ASINSIN = OP["asinsin"]
OP_ACOSCOS = OP["acoscos"]
OP_ACOTCOT = OP["acotcot"]
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

# The row functions (numba dispatchers as globals: compiled into the interpreter).
_sin_row = _E["sin"].row
_cos_row = _E["cos"].row
_tan_row = _E["tan"].row
_asin_row = _E["asin"].row
_acos_row = _E["acos"].row
_atan_row = _E["atan"].row
_sinh_row = _E["sinh"].row
_cosh_row = _E["cosh"].row
_tanh_row = _E["tanh"].row
_asinh_row = _E["asinh"].row
_acosh_row = _E["acosh"].row
_atanh_row = _E["atanh"].row
_exp_row = _E["exp"].row
_log_row = _E["log"].row
_log10_row = _E["log10"].row
_cbrt_row = _E["cbrt"].row
_atan2_vv = _E["atan2"].row_vv
_atan2_vs = _E["atan2"].row_vs
_atan2_sv = _E["atan2"].row_sv
_pow_vv = _E["pow"].row_vv
_pow_vs = _E["pow"].row_vs
_pow_sv = _E["pow"].row_sv
_atantan_row = _rt.atantan_row
_asinsin_row = _rt.asinsin_row
_acoscos_row = _rt.acoscos_row
_acotcot_row = _rt.acotcot_row


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


@njit(inline="always", **_OPTS)
def unsigned(i):
    """Index ``i`` (never negative) as unsigned: numba checks a signed index for a negative
    value to wrap around, a compare and a select at every load of a gather."""
    return np.uint64(i)


@njit(inline="always", **_OPTS)
def _usign(u):
    """constituents.unit_sign: +1 for u >= 0 (also -0), -1 below, NaN for NaN."""
    if u >= 0.0:
        return 1.0
    if u < 0.0:
        return -1.0
    return u


@njit(inline="always", **_OPTS)
def _sign(u):
    """np.sign: sign(+-0) = +0, NaN stays NaN."""
    if u > 0.0:
        return 1.0
    if u < 0.0:
        return -1.0
    if u == 0.0:
        return 0.0
    return u


@njit(inline="always", **_OPTS)
def _minimum(a, b):
    """np.minimum: NaN propagates; for equal operands (+0, -0) numpy returns the second."""
    if a < b or a != a:
        return a
    return b


@njit(inline="always", **_OPTS)
def _maximum(a, b):
    if a > b or a != a:
        return a
    return b


@njit(inline="always", **_OPTS)
def _ratio1(a, b):
    q = a / b
    if a == 0.0 and b == 0.0:
        return 1.0
    return q


@njit(inline="always", **_OPTS)
def _truth(v):
    """logic.truth: |v| >= 0.5, NaN false."""
    return abs(v) >= 0.5


@njit(inline="always", **_OPTS)
def _is_logic2(op):
    return (OP_LT <= op <= OP_OR) or op == OP_PICK or op == OP_PICKN or op == OP_FMOD  # noqa: SIM109 (numba)


@njit(inline="always", **_OPTS)
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


@njit(inline="always", **_OPTS)
def _trunc(u):
    return np.floor(u) if u >= 0.0 else np.ceil(u)


@njit(inline="always", **_OPTS)
def _pow_rule(u, e, p):
    """The ``x^c`` convention (elementary.POW_SHORTCUTS) applied to ``p = pow(u, e)``:
    branch-free selects, so the loop that applies it vectorises."""
    r = p
    r = u * u if e == 2.0 else r
    r = math.sqrt(u) if e == 0.5 else r
    r = 1.0 / u if e == -1.0 else r
    r = u if e == 1.0 else r
    return 1.0 if e == 0.0 else r


@njit(**_OPTS)
def _power_vs(W, d, a, s, n):
    """W[d] = W[a]^s: the shortcut loop for s in POW_SHORTCUTS, else surfgen's pow."""
    if s == 2.0 or s == 0.5 or s == -1.0 or s == 1.0 or s == 0.0:
        for k in range(n):
            u = W[a, k]
            W[d, k] = _pow_rule(u, s, u)
    else:
        _pow_vs(W, d, a, s, n)


@njit(**_OPTS)
def _power_vv(W, d, a, b, n):
    """W[d] = W[a]^W[b] (d differs from a and b: the compiler never writes in place)."""
    _pow_vv(W, d, a, b, n)
    for k in range(n):
        W[d, k] = _pow_rule(W[a, k], W[b, k], W[d, k])


@njit(**_OPTS)
def _power_sv(W, d, s, b, n):
    _pow_sv(W, d, s, b, n)
    for k in range(n):
        W[d, k] = _pow_rule(s, W[b, k], W[d, k])


@njit(**_OPTS)
def _series_exact(x, r, p):
    """sum_{i=-p}^{p} (1 - us(x-a) us(x-b)) (x - a), a = r(i-1), b = r i: as the reference."""
    total = 0.0
    for i in range(-p, p + 1):
        a = r * (i - 1)
        b = r * i
        total = total + (1.0 - _usign(x - a) * _usign(x - b)) * (x - a)
    return total


@njit(**_OPTS)
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


@njit(**_OPTS)
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


@njit(**_OPTS)
def _series_row(W, d, a, n, consts, base):
    r = consts[base]
    p = int(consts[base + 1])
    if consts[base + 2] != 0.0:
        for k in range(n):
            W[d, k] = _series_exact(W[a, k], r, p)
    else:
        for k in range(n):
            W[d, k] = _series(W[a, k], r, p)


@njit(**_OPTS)
def _unary(op, W, d, a, n, consts, imm, T):
    """The operations of one vector operand but the cheap ones (:func:`_exec` runs those)."""
    if op == OP_SIN:
        _sin_row(W, d, a, n)
    elif op == OP_COS:
        _cos_row(W, d, a, n)
    elif op == OP_TAN:
        _tan_row(W, d, a, n)
    elif op == OP_ATAN:
        _atan_row(W, d, a, n)
    elif op == OP_ASIN:
        _asin_row(W, d, a, n)
    elif op == OP_ACOS:
        _acos_row(W, d, a, n)
    elif op == OP_ATANTAN:
        _atantan_row(W, d, a, n)
    elif op == OP_ACOTCOT:
        _acotcot_row(W, d, a, n)
    elif op == OP_ASINSIN:
        _asinsin_row(W, d, a, n)
    elif op == OP_ACOSCOS:
        _acoscos_row(W, d, a, n)
    elif op == OP_USIGN:
        for k in range(n):
            W[d, k] = _usign(W[a, k])
    elif op == OP_EXP:
        _exp_row(W, d, a, n)
    elif op == OP_LOG:
        _log_row(W, d, a, n)
    elif op == OP_LOG10:
        _log10_row(W, d, a, n)
    elif op == OP_SINH:
        _sinh_row(W, d, a, n)
    elif op == OP_COSH:
        _cosh_row(W, d, a, n)
    elif op == OP_TANH:
        _tanh_row(W, d, a, n)
    elif op == OP_ASINH:
        _asinh_row(W, d, a, n)
    elif op == OP_ACOSH:
        _acosh_row(W, d, a, n)
    elif op == OP_ATANH:
        _atanh_row(W, d, a, n)
    elif op == OP_CBRT:
        _cbrt_row(W, d, a, n)
    elif op == OP_POWI:  # programs of earlier versions: u^imm, now surfgen's pow
        _power_vs(W, d, a, float(imm), n)
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
    elif op == OP_SERIES:
        _series_row(W, d, a, n, consts, imm)
    elif op == OP_SEGSUM:
        _segsum(W, d, a, n, consts, imm)


@njit(**_OPTS)
def _binary_vv(op, W, d, a, b, n):
    """The operations of two operands but + - * / (:func:`_exec` runs those)."""
    if op == OP_POW:
        _power_vv(W, d, a, b, n)
    elif op == OP_MIN:
        for k in range(n):
            W[d, k] = _minimum(W[a, k], W[b, k])
    elif op == OP_MAX:
        for k in range(n):
            W[d, k] = _maximum(W[a, k], W[b, k])
    elif op == OP_ATAN2:
        _atan2_vv(W, d, a, b, n)
    elif op == OP_RATIO1:
        for k in range(n):
            W[d, k] = _ratio1(W[a, k], W[b, k])
    elif _is_logic2(op):
        for k in range(n):
            W[d, k] = _logic2(op, W[a, k], W[b, k])


@njit(**_OPTS)
def _binary_vs(op, W, d, a, s, n):
    """The operations of two operands but + - * / (:func:`_exec` runs those)."""
    if op == OP_POW:
        _power_vs(W, d, a, s, n)
    elif op == OP_MIN:
        for k in range(n):
            W[d, k] = _minimum(W[a, k], s)
    elif op == OP_MAX:
        for k in range(n):
            W[d, k] = _maximum(W[a, k], s)
    elif op == OP_ATAN2:
        _atan2_vs(W, d, a, s, n)
    elif op == OP_RATIO1:
        for k in range(n):
            W[d, k] = _ratio1(W[a, k], s)
    elif _is_logic2(op):
        for k in range(n):
            W[d, k] = _logic2(op, W[a, k], s)


@njit(**_OPTS)
def _binary_sv(op, W, d, s, b, n):
    """The operations of two operands but + - * / (:func:`_exec` runs those)."""
    if op == OP_POW:
        _power_sv(W, d, s, b, n)
    elif op == OP_MIN:
        for k in range(n):
            W[d, k] = _minimum(s, W[b, k])
    elif op == OP_MAX:
        for k in range(n):
            W[d, k] = _maximum(s, W[b, k])
    elif op == OP_ATAN2:
        _atan2_sv(W, d, s, b, n)
    elif op == OP_RATIO1:
        for k in range(n):
            W[d, k] = _ratio1(s, W[b, k])
    elif _is_logic2(op):
        for k in range(n):
            W[d, k] = _logic2(op, s, W[b, k])


@njit(**_OPTS)
def _exec(code, c0, c1, consts, W, S, T, n, prof):
    """Run code rows [c0, c1) on the first n columns of W; with a non-empty ``prof``,
    add the cycles each row takes to ``prof[row]``.

    The cheap operations (+, -, *, / in every operand mode; copy, neg, abs, square, recip,
    sqrt) run here, inline; only the others call :func:`_unary` and ``_binary_*``. A call of
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
                _binary_vv(op, W, d, a, b, n)
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
                for k in range(n):
                    W[d, k] = W[a, k] / s
            else:
                _binary_vs(op, W, d, a, s, n)
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
                _binary_sv(op, W, d, s, b, n)
        elif mode == M_S:
            s = S[a]
            for k in range(n):
                W[d, k] = s
        if profiling:
            prof[pc] += _cycles() - t0


# ----------------------------------------------------------------------------- blocks and drivers


@njit(**_OPTS)
def _block(
    lv,
    i,
    j0,
    j1,
    nrun,
    code,
    blocks,
    loads,
    stores,
    consts,
    sx,
    sy,
    sz,
    sxy,
    sxz,
    syz,
    out,
    W,
    S,
    T,
    prof,
):
    """Run the block of level ``lv`` for rows j0 <= j < j1 (at x index i), ``nrun`` points
    along its axis each, tile by tile: scalar loads per row, vector loads, code, stores."""
    c0 = blocks[lv, 0]
    c1 = blocks[lv, 1]
    l0 = blocks[lv, 2]
    l1 = blocks[lv, 3]
    s0 = blocks[lv, 4]
    s1 = blocks[lv, 5]
    if c0 == c1:
        return
    # A root of a lower level (a formula of one or two variables): the output is a broadcast,
    # written straight from its source instead of through the register file.
    if lv == 7 and c1 - c0 == 1 and code[c0, 0] == OP_COPY:
        _broadcast(
            code[c0, 1],
            code[c0, 3],
            loads,
            l0,
            l1,
            consts,
            sx,
            sy,
            sxy,
            sz,
            sxz,
            syz,
            out,
            i,
            j0,
            j1,
        )
        return
    tile = W.shape[1]
    # Rows of several j per tile when a run is short (nrun <= tile/2) and no scalar load varies
    # with j (y or xy values): the code then runs on m*nrun points per dispatch, and the per-op
    # cost of the interpreter is paid once per m rows. Every operation is elementwise, so the
    # values (and bits) are those of a row at a time.
    m = tile // nrun if (lv == 6 or lv == 7) and nrun > 0 else 1
    if m > 1:
        for q in range(l0, l1):
            if loads[q, 3] == 0 and (loads[q, 0] == 2 or loads[q, 0] == 3):
                m = 1
    if m > 1:
        _block_rows(
            m,
            i,
            j0,
            j1,
            nrun,
            code,
            c0,
            c1,
            l0,
            l1,
            s0,
            s1,
            loads,
            stores,
            consts,
            sx,
            sy,
            sz,
            sxy,
            sxz,
            syz,
            out,
            W,
            S,
            T,
            prof,
        )
        return
    for j in range(j0, j1):
        for q in range(l0, l1):
            if loads[q, 3] == 0:
                kind = loads[q, 0]
                row = loads[q, 1]
                if kind == 0:
                    S[loads[q, 2]] = consts[row]
                elif kind == 1:
                    S[loads[q, 2]] = sx[row, i]
                elif kind == 2:
                    S[loads[q, 2]] = sy[row, j]
                else:
                    S[loads[q, 2]] = sxy[row, j]
        r0 = 0
        while r0 < nrun:
            n = min(tile, nrun - r0)
            for q in range(l0, l1):
                vec = loads[q, 3]
                if vec == 1 or (vec == 2 and (j == j0 or nrun > tile)):
                    kind = loads[q, 0]
                    row = loads[q, 1]
                    slot = loads[q, 2]
                    if kind == 4:
                        for k in range(n):
                            W[slot, k] = sz[row, r0 + k]
                    elif kind == 6:
                        for k in range(n):
                            W[slot, k] = syz[row, j, r0 + k]
                    elif kind == 5:
                        for k in range(n):
                            W[slot, k] = sxz[row, r0 + k]
                    elif kind == 2:
                        for k in range(n):
                            W[slot, k] = sy[row, r0 + k]
                    else:
                        for k in range(n):
                            W[slot, k] = sx[row, r0 + k]
            _exec(code, c0, c1, consts, W, S, T, n, prof)
            for q in range(s0, s1):
                slot = stores[q, 0]
                kind = stores[q, 1]
                row = stores[q, 2]
                if kind == 7:
                    for k in range(n):
                        out[i, j, r0 + k] = W[slot, k]
                elif kind == 6:
                    for k in range(n):
                        syz[row, j, r0 + k] = W[slot, k]
                elif kind == 5:
                    for k in range(n):
                        sxz[row, r0 + k] = W[slot, k]
                elif kind == 3:
                    for k in range(n):
                        sxy[row, r0 + k] = W[slot, k]
                elif kind == 4:
                    for k in range(n):
                        sz[row, r0 + k] = W[slot, k]
                elif kind == 2:
                    for k in range(n):
                        sy[row, r0 + k] = W[slot, k]
                else:
                    for k in range(n):
                        sx[row, r0 + k] = W[slot, k]
            r0 += n


@njit(**_OPTS)
def _block_rows(
    m,
    i,
    j0,
    j1,
    nrun,
    code,
    c0,
    c1,
    l0,
    l1,
    s0,
    s1,
    loads,
    stores,
    consts,
    sx,
    sy,
    sz,
    sxy,
    sxz,
    syz,
    out,
    W,
    S,
    T,
    prof,
):
    """A block along z (yz or xyz) in tiles of up to m whole rows j (see :func:`_block`): its
    scalar loads are constants or x values, the same for every j; y and xy values enter as
    vector loads (kinds 2 and 3, one value per row j: fast.rows_program rewrites a program so).

    A run is the whole z axis (``nrun == Nz``), so the tile's rows of the output and of the yz
    plane are one contiguous stretch: they are copied as such, through flat views."""
    ny = syz.shape[1]
    out_flat = out.reshape(out.size)
    syz_flat = syz.reshape(syz.size)
    for q in range(l0, l1):
        if loads[q, 3] == 0:
            if loads[q, 0] == 0:
                S[loads[q, 2]] = consts[loads[q, 1]]
            else:
                S[loads[q, 2]] = sx[loads[q, 1], i]
    j = j0
    while j < j1:
        rows = min(m, j1 - j)
        n = rows * nrun
        for q in range(l0, l1):
            vec = loads[q, 3]
            if vec == 1 or (vec == 2 and j == j0):
                kind = loads[q, 0]
                row = loads[q, 1]
                slot = loads[q, 2]
                if kind == 6:  # rows j..j+rows-1 of the plane: contiguous
                    base = unsigned((row * ny + j) * nrun)
                    for k in range(n):
                        W[slot, k] = syz_flat[base + unsigned(k)]
                elif kind == 2:
                    for r in range(rows):
                        v = sy[row, j + r]
                        for k in range(nrun):
                            W[slot, r * nrun + k] = v
                elif kind == 3:
                    for r in range(rows):
                        v = sxy[row, j + r]
                        for k in range(nrun):
                            W[slot, r * nrun + k] = v
                elif kind == 5:
                    for r in range(rows):
                        for k in range(nrun):
                            W[slot, r * nrun + k] = sxz[row, k]
                else:  # z (the only other vector load of a block along z)
                    for r in range(rows):
                        for k in range(nrun):
                            W[slot, r * nrun + k] = sz[row, k]
        _exec(code, c0, c1, consts, W, S, T, n, prof)
        for q in range(s0, s1):
            slot = stores[q, 0]
            kind = stores[q, 1]
            row = stores[q, 2]
            if kind == 7:  # out[i, j:j+rows, :] is contiguous (nrun is the whole z axis)
                base = unsigned((i * ny + j) * nrun)
                for k in range(n):
                    out_flat[base + unsigned(k)] = W[slot, k]
            else:  # the yz store
                base = unsigned((row * ny + j) * nrun)
                for k in range(n):
                    syz_flat[base + unsigned(k)] = W[slot, k]
        j += rows


@njit(**_OPTS)
def _broadcast(mode, a, loads, l0, l1, consts, sx, sy, sxy, sz, sxz, syz, out, i, j0, j1):
    """out[i, j, :] for j0 <= j < j1 = the root of a formula of one or two variables: a scalar
    per row (mode S: a constant, x, y or xy value) or a z, xz or yz row (mode V), copied
    straight from its store, in one call for all rows j (a call per row cost more than the
    copy of its Nz values). Indexed flat, without a view per row (numba counts references to
    every view it makes)."""
    ny = out.shape[1]
    nz = out.shape[2]
    out_flat = out.reshape(out.size)
    for q in range(l0, l1):
        if loads[q, 2] != a or (loads[q, 3] == 0) != (mode == M_S):
            continue
        kind = loads[q, 0]
        row = loads[q, 1]
        for j in range(j0, j1):
            base = unsigned((i * ny + j) * nz)
            if mode == M_S:
                if kind == 0:
                    s = consts[row]
                elif kind == 1:
                    s = sx[row, i]
                elif kind == 2:
                    s = sy[row, j]
                else:
                    s = sxy[row, j]
                for k in range(nz):
                    out_flat[base + unsigned(k)] = s
            elif kind == 4:
                for k in range(nz):
                    out_flat[base + unsigned(k)] = sz[row, k]
            elif kind == 5:
                for k in range(nz):
                    out_flat[base + unsigned(k)] = sxz[row, k]
            else:
                for k in range(nz):
                    out_flat[base + unsigned(k)] = syz[row, j, k]


@njit(**_OPTS)
def _scratch(prog, tile):
    nv, ns = prog[6], prog[7]
    return np.empty((nv, tile)), np.empty(ns), np.empty((2, tile))


@njit(**_OPTS)
def grid_stores(rows, ax, ay, az):
    """The x, y, z and yz stores of a grid run (``rows``: the program's), the axes in row 0."""
    sx = np.empty((rows[1], ax.size))
    sy = np.empty((rows[2], ay.size))
    sz = np.empty((rows[4], az.size))
    sx[0] = ax
    sy[0] = ay
    sz[0] = az
    syz = np.empty((rows[6], ay.size, az.size))
    return sx, sy, sz, syz


@njit(**_OPTS)
def _prologue(prog, tile, sx, sy, sz, syz, out, prof):
    """The x, y and z blocks (1-D, once per grid)."""
    code, blocks, loads, stores, consts = prog[0], prog[1], prog[2], prog[3], prog[4]
    W, S, T = _scratch(prog, tile)
    e = np.empty((0, 1))
    args = (code, blocks, loads, stores, consts, sx, sy, sz, e, e, syz, out, W, S, T, prof)
    _block(1, 0, 0, 1, sx.shape[1], *args)
    _block(2, 0, 0, 1, sy.shape[1], *args)
    _block(4, 0, 0, 1, sz.shape[1], *args)


@njit(**_OPTS)
def _yz_rows(j0, j1, prog, tile, sx, sy, sz, syz, out, prof):
    """The yz block for rows j0 <= j < j1 (once per grid)."""
    code, blocks, loads, stores, consts = prog[0], prog[1], prog[2], prog[3], prog[4]
    W, S, T = _scratch(prog, tile)
    e = np.empty((0, 1))
    args = (code, blocks, loads, stores, consts, sx, sy, sz, e, e, syz, out, W, S, T, prof)
    _block(6, 0, j0, j1, sz.shape[1], *args)


@njit(**_OPTS)
def _slab(i0, i1, prog, tile, sx, sy, sz, syz, out, prof):
    """x indices i0 <= i < i1: per i the xy and xz rows, then the xyz block row by row."""
    code, blocks, loads, stores, consts, rows = prog[0], prog[1], prog[2], prog[3], prog[4], prog[5]
    W, S, T = _scratch(prog, tile)
    ny = sy.shape[1]
    nz = sz.shape[1]
    sxy = np.empty((rows[3], ny))
    sxz = np.empty((rows[5], nz))
    args = (code, blocks, loads, stores, consts, sx, sy, sz, sxy, sxz, syz, out, W, S, T, prof)
    for i in range(i0, i1):
        _block(3, i, 0, 1, ny, *args)
        _block(5, i, 0, 1, nz, *args)
        _block(7, i, 0, ny, nz, *args)


# What run_grid does: all of a grid on one thread, or one part of it (the threads' way).
GRID_ALL, GRID_XYZ_AXES, GRID_YZ_ROWS, GRID_SLAB = 0, 1, 2, 3


@njit(**_OPTS)
def run_grid(prog, tile, sx, sy, sz, syz, out, prof, part, lo, hi):
    """Evaluate a program into ``out`` (Nx, Ny, Nz), with the stores of :func:`grid_stores`.

    ``prog`` is ``(code, blocks, loads, stores, consts, rows, n_vector, n_scalar)`` of a
    :class:`~surfgen.generator.compiler.Program`; ``prof`` is empty, or float64 of one entry
    per code row to receive cycle counts. ``part`` is :data:`GRID_ALL` (the whole grid), or
    one step of it, for threads: :data:`GRID_XYZ_AXES` (the x, y and z blocks, first),
    :data:`GRID_YZ_ROWS` (the yz plane's rows lo <= j < hi, next), :data:`GRID_SLAB` (x
    indices lo <= i < hi, last). Every part computes the same values wherever it runs.

    One entry point for both: numba compiles (and caches) the whole interpreter again into
    every entry point that calls it, a minute and more of LLVM each.
    """
    whole = part == GRID_ALL
    j0, j1 = (0, sy.shape[1]) if whole else (lo, hi)
    i0, i1 = (0, sx.shape[1]) if whole else (lo, hi)
    # one call site each (LLVM may inline a callee into every site: twice the code to compile)
    if whole or part == GRID_XYZ_AXES:
        _prologue(prog, tile, sx, sy, sz, syz, out, prof)
    if whole or part == GRID_YZ_ROWS:
        _yz_rows(j0, j1, prog, tile, sx, sy, sz, syz, out, prof)
    if whole or part == GRID_SLAB:
        _slab(i0, i1, prog, tile, sx, sy, sz, syz, out, prof)


# ----------------------------------------------------------------------------- arbitrary points


@njit(**_OPTS)
def run_points(prog, tile, px, py, pz, out):
    """Evaluate a program at the points ``(px[p], py[p], pz[p])`` into ``out[p]``.

    ``prog`` is ``(code, blocks, loads, stores, consts, rows, n_rows)`` of a program rewritten
    by :func:`surfgen.generator.fast.points_program`: every block runs along the points, so
    each level's store holds one value per point of the current tile and the row scalars of
    the grid's blocks (S slots) are W rows ``n_vector + slot`` read by ``vv`` operations.
    Each element goes through the same scalar operations as on a grid, so the values are the
    grid interpreter's (and the reference's) bit for bit.
    """
    code, blocks, loads, stores, consts, rows = prog[0], prog[1], prog[2], prog[3], prog[4], prog[5]
    n_rows = prog[6]
    depth = 1
    for lv in range(8):
        depth = max(depth, rows[lv])
    st = np.empty((8, depth, tile))  # st[level, row, point]
    W = np.empty((n_rows, tile))
    S = np.empty(1)
    T = np.empty((2, tile))
    prof = np.empty(0)
    total = px.size
    for p0 in range(0, total, tile):
        n = min(tile, total - p0)
        for k in range(n):
            st[1, 0, k] = px[p0 + k]
            st[2, 0, k] = py[p0 + k]
            st[4, 0, k] = pz[p0 + k]
        for lv in (1, 2, 4, 6, 3, 5, 7):
            c0 = blocks[lv, 0]
            c1 = blocks[lv, 1]
            if c0 == c1:
                continue
            for q in range(blocks[lv, 2], blocks[lv, 3]):
                kind = loads[q, 0]
                row = loads[q, 1]
                slot = loads[q, 2]
                if kind == 0:
                    v = consts[row]
                    for k in range(n):
                        W[slot, k] = v
                else:
                    for k in range(n):
                        W[slot, k] = st[kind, row, k]
            _exec(code, c0, c1, consts, W, S, T, n, prof)
            for q in range(blocks[lv, 4], blocks[lv, 5]):
                slot = stores[q, 0]
                kind = stores[q, 1]
                row = stores[q, 2]
                if kind == 7:
                    for k in range(n):
                        out[p0 + k] = W[slot, k]
                else:
                    for k in range(n):
                        st[kind, row, k] = W[slot, k]


@njit(**_OPTS)
def dedupe(keys):
    """Distinct int64 keys in order of first appearance (open addressing, O(n)).

    Returns ``ids`` (``keys[p]`` is the ``ids[p]``-th distinct key) and ``first`` (the position
    of each distinct key's first appearance)."""
    ids = np.empty(keys.size, dtype=np.int64)
    return ids, _dedupe_into(keys, ids)


@njit(**_OPTS)
def _dedupe_into(keys, ids):
    """:func:`dedupe` writing ``ids`` into the given array (a row of the maps, no copy);
    returns ``first``."""
    n = keys.size
    cap = 16
    while cap < 2 * n:
        cap *= 2
    mask = np.uint64(cap - 1)
    table = np.full(cap, -1, dtype=np.int64)
    held = np.empty(cap, dtype=np.int64)  # the key in each used slot: no lookup through first
    first = np.empty(n, dtype=np.int64)
    m = 0
    for p in range(n):
        k = keys[p]
        u = np.uint64(k)
        h = ((u ^ (u >> np.uint64(31))) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(17)
        h = h & mask
        while True:
            t = table[h]
            if t == -1:
                table[h] = m
                held[h] = k
                first[m] = p
                ids[p] = m
                m += 1
                break
            if held[h] == k:
                ids[p] = t
                break
            h = (h + np.uint64(1)) & mask
    return first[:m]


@njit(**_OPTS)
def dedupe_in(keys, size):
    """:func:`dedupe` of keys known to lie in ``[0, size)`` (pairs of dense ids): the same
    ``ids`` and ``first``, through a table indexed by the key where it is small enough (no
    hashing, no probing), else :func:`dedupe`."""
    ids = np.empty(keys.size, dtype=np.int64)
    return ids, _dedupe_in_into(keys, size, ids)


@njit(**_OPTS)
def _dedupe_in_into(keys, size, ids):
    """:func:`dedupe_in` writing ``ids`` into the given array; returns ``first``."""
    n = keys.size
    if size > 8 * n + 4096:
        return _dedupe_into(keys, ids)
    table = np.full(size, -1, dtype=np.int32)
    first = np.empty(n, dtype=np.int64)
    m = 0
    for p in range(n):
        k = keys[p]
        t = table[unsigned(k)]
        if t == -1:
            table[unsigned(k)] = m
            first[m] = p
            ids[p] = m
            m += 1
        else:
            ids[p] = t
    return first[:m]


@njit(**_OPTS)
def run_lattice(prog, tile, sizes, offsets, maps, map_at, store, out, skip=None):
    """Evaluate a points program (see :func:`run_points`) level by level over the distinct
    values each level needs: level ``lv`` runs over ``sizes[lv]`` entries (distinct x values,
    distinct (x, y) pairs, ..., every point for xyz); a load of level ``K`` in level ``lv``'s
    block reads entry ``maps[map_at[lv, K] + c]`` of K's store for entry ``c`` (K == lv: the
    level's own variable, entry ``c``).  Stores live in ``store``: level K, row r, entry e at
    ``offsets[K] + r * sizes[K] + e``; rows 0 of levels x, y, z hold the coordinates (filled
    by the caller).  Every entry is computed from the same bits as at its points, so values
    equal :func:`run_points`' bit for bit.  ``skip[lv]``: level ``lv``'s store is already
    filled (the edges' levels that do not vary along them, :func:`eval_edges`)."""
    code, blocks, loads, stores, consts = prog[0], prog[1], prog[2], prog[3], prog[4]
    n_rows = prog[6]
    W = np.empty((n_rows, tile))
    S = np.empty(1)
    T = np.empty((2, tile))
    prof = np.empty(0)
    for lv in (1, 2, 4, 6, 3, 5, 7):
        c0 = blocks[lv, 0]
        c1 = blocks[lv, 1]
        if c0 == c1 or (skip is not None and skip[lv]):
            continue
        total = sizes[lv]
        for e0 in range(0, total, tile):
            n = min(tile, total - e0)
            for q in range(blocks[lv, 2], blocks[lv, 3]):
                kind = loads[q, 0]
                row = loads[q, 1]
                slot = loads[q, 2]
                if kind == 0:
                    v = consts[row]
                    for k in range(n):
                        W[slot, k] = v
                elif kind == lv:
                    base = offsets[kind] + row * sizes[kind] + e0
                    for k in range(n):
                        W[slot, k] = store[unsigned(base + k)]
                else:
                    base = offsets[kind] + row * sizes[kind]
                    at = map_at[lv, kind] + e0
                    for k in range(n):
                        W[slot, k] = store[unsigned(base + maps[at + k])]
            _exec(code, c0, c1, consts, W, S, T, n, prof)
            for q in range(blocks[lv, 4], blocks[lv, 5]):
                slot = stores[q, 0]
                kind = stores[q, 1]
                row = stores[q, 2]
                if kind == 7:
                    for k in range(n):
                        out[unsigned(e0 + k)] = W[slot, k]
                else:
                    base = offsets[kind] + row * sizes[kind] + e0
                    for k in range(n):
                        store[unsigned(base + k)] = W[slot, k]


@njit(**_OPTS)
def _gather(values, at):
    out = np.empty(at.size, dtype=values.dtype)
    for i in range(at.size):
        out[i] = values[unsigned(at[i])]
    return out


@njit(**_OPTS)
def _pair_level(ids, sizes, has, lv, a, b):
    """Pair level ``lv`` of variables' levels ``a`` and ``b`` (dense ids ``ids[a]``,
    ``ids[b]`` of the points): its entries are their distinct pairs (sets ``ids[lv]``,
    ``sizes[lv]``, ``has[lv]``).  Returns the entries of ``a`` and of ``b`` each one reads (the
    caller appends them to the parts :func:`_place_parts` copies: numba types the list there)."""
    first = _dedupe_in_into(ids[a] * sizes[b] + ids[b], sizes[a] * sizes[b], ids[lv])
    sizes[lv] = first.size
    has[lv] = True
    return _gather(ids[a], first), _gather(ids[b], first)


@njit(**_OPTS)
def _maps_with_ids(n, pair_levels):
    """The ``maps`` of :func:`run_lattice`, laid out so that the points' entries need no copy:
    first the xyz level's section, whose row ``k`` (``ids[k]``, a view, filled by the caller)
    is the entry of every point in level ``k``'s store, then room for the two parts of each of
    ``pair_levels`` pair levels (at most ``n`` entries each: :func:`_place_parts`)."""
    maps = np.empty(8 * n + 2 * n * pair_levels + 1, dtype=np.int64)
    return maps, maps[: 8 * n].reshape((8, n))


@njit(**_OPTS)
def _place_parts(maps, n, pair_parts, pair_keys, has, map_at):
    """Copy each pair level's two parts (the entries of its variables' stores, ``pair_keys[q]``
    = (pair level, variable level)) behind the xyz section of ``maps``
    (:func:`_maps_with_ids`), and record in ``map_at`` where every section starts."""
    for k in (1, 2, 4, 3, 5, 6):
        if has[k]:
            map_at[7, k] = k * n
    at = 8 * n
    for q in range(len(pair_parts)):
        lv, k = pair_keys[q]
        map_at[lv, k] = at
        part = pair_parts[q]
        maps[at : at + part.size] = part
        at += part.size


@njit(**_OPTS)
def eval_points(prog, tile, active, rows, px, py, pz, out):
    """Evaluate a points program at ``(px[p], py[p], pz[p])`` into ``out[p]``, each level once
    per distinct value it needs (:func:`run_lattice`): its plan made here, in one call.

    Level x runs over the distinct x values (told apart by their bits, so -0.0 and +0.0 are
    distinct and every entry is computed from exactly the bits of its points), xy over the
    distinct (x, y) pairs of the points (if ``active[3]``), likewise xz, yz; xyz over every
    point.  ``rows[lv]``: the store rows of level ``lv`` (``Program.rows``)."""
    n = px.size
    # the rows of the levels it has, all set below, in place in the maps
    maps, ids = _maps_with_ids(n, active[3] + active[5] + active[6])
    sizes = np.zeros(8, dtype=np.int64)
    has = np.zeros(8, dtype=np.bool_)
    first_x = _dedupe_into(px.view(np.int64), ids[1])
    first_y = _dedupe_into(py.view(np.int64), ids[2])
    first_z = _dedupe_into(pz.view(np.int64), ids[4])
    sizes[1], sizes[2], sizes[4] = first_x.size, first_y.size, first_z.size
    has[1] = has[2] = has[4] = True
    sizes[7] = n
    # parts: (level, variable level) -> the entries of the variable's store it reads, in maps
    map_at = np.zeros((8, 8), dtype=np.int64)
    pair_parts = []
    pair_keys = []
    for lv, a, b in ((3, 1, 2), (5, 1, 4), (6, 2, 4)):
        if not active[lv]:
            continue
        part_a, part_b = _pair_level(ids, sizes, has, lv, a, b)
        pair_parts.append(part_a)
        pair_keys.append((lv, a))
        pair_parts.append(part_b)
        pair_keys.append((lv, b))
    _place_parts(maps, n, pair_parts, pair_keys, has, map_at)
    offsets = np.zeros(8, dtype=np.int64)
    total = 0
    for k in (1, 2, 3, 4, 5, 6):
        offsets[k] = total
        total += rows[k] * sizes[k]
    store = np.empty(max(total, 1))
    store[offsets[1] : offsets[1] + sizes[1]] = _gather(px, first_x)
    store[offsets[2] : offsets[2] + sizes[2]] = _gather(py, first_y)
    store[offsets[4] : offsets[4] + sizes[4]] = _gather(pz, first_z)
    run_lattice(prog, tile, sizes, offsets, maps, map_at, store, out)


# ----------------------------------------------------------------------------- points on grid edges


@njit(**_OPTS)
def edge_lattice(prog, tile, active, rows, axis, ijk, axes):
    """The part of a points program that does not vary along grid edges parallel to ``axis``
    (0, 1, 2): for edges starting at grid indices ``ijk`` (n, 3), the two single-variable
    levels of the other axes over their whole grid axis and their pair level over the edges'
    distinct pairs, computed once (:func:`run_lattice`); :func:`eval_edges` then evaluates
    points on these edges running only the levels that involve ``axis``.

    ``axes``: the grid's three coordinate arrays.  Returns the context :func:`eval_edges` takes:
    ``(axis, ijk, sizes, offsets, pair_ids, store, fixed_end, pair_first)``."""
    va = 1 << axis
    b = (axis + 1) % 3
    c = (axis + 2) % 3
    if b > c:
        b, c = c, b
    vb, vc = 1 << b, 1 << c
    n = ijk.shape[0]
    nb, nc = axes[b].size, axes[c].size
    sizes = np.zeros(8, dtype=np.int64)
    sizes[vb], sizes[vc] = nb, nc
    pair_ids = np.zeros(n, dtype=np.int64)
    pair_first = np.zeros(0, dtype=np.int64)
    if active[vb | vc]:
        keys = np.empty(n, dtype=np.int64)
        for e in range(n):
            keys[e] = ijk[e, b] * nc + ijk[e, c]
        pair_ids, pair_first = dedupe_in(keys, nb * nc)
        sizes[vb | vc] = pair_first.size
    offsets = np.zeros(8, dtype=np.int64)
    total = 0
    for k in (vb, vc, vb | vc):
        offsets[k] = total
        total += rows[k] * sizes[k]
    fixed_end = total
    # room for the varying levels of a round of up to n points (one entry per point at most)
    for k in (va, va | vb, va | vc):
        total += rows[k] * n
    store = np.empty(max(total, 1))
    store[offsets[vb] : offsets[vb] + nb] = axes[b]
    store[offsets[vc] : offsets[vc] + nc] = axes[c]
    m = pair_first.size
    maps = np.empty(max(2 * m, 1), dtype=np.int64)
    for q in range(m):
        e = pair_first[q]
        maps[q] = ijk[e, b]
        maps[m + q] = ijk[e, c]
    map_at = np.zeros((8, 8), dtype=np.int64)
    map_at[vb | vc, vb] = 0
    map_at[vb | vc, vc] = m
    skip = np.ones(8, dtype=np.bool_)
    skip[vb] = skip[vc] = skip[vb | vc] = False
    run_lattice(prog, tile, sizes, offsets, maps, map_at, store, np.empty(0), skip)
    return axis, ijk, sizes, offsets, pair_ids, store, fixed_end, pair_first


@njit(**_OPTS)
def eval_edges(prog, tile, active, rows, ctx, sel, u, out):
    """Evaluate a points program at points on the edges of ``ctx`` (:func:`edge_lattice`):
    point ``p`` on edge ``sel[p]`` with coordinate ``u[p]`` along the edges' axis, the others the
    edge's grid values.  Levels that do not involve the axis come from ``ctx`` (computed once per
    edge); the axis' level runs over the distinct values of ``u`` (by their bits), its pair levels
    over the distinct (value, grid index) pairs, the xyz level over every point.  The values are
    :func:`eval_points`' (and the reference's) bit for bit: every entry is computed from the bits
    of the coordinates of its points."""
    axis, ijk, sizes_fixed, offsets_fixed, pair_ids, store, fixed_end, _first = ctx
    n = sel.size
    if n == 0:
        return
    va = 1 << axis
    b = (axis + 1) % 3
    c = (axis + 2) % 3
    if b > c:
        b, c = c, b
    vb, vc = 1 << b, 1 << c
    sizes = sizes_fixed.copy()
    offsets = offsets_fixed.copy()
    # the rows of the levels it has, all set below, in place in the maps
    maps, ids = _maps_with_ids(n, active[va | vb] + active[va | vc])
    ufirst = _dedupe_into(u.view(np.int64), ids[va])
    sizes[va] = ufirst.size
    sizes[7] = n
    has = np.zeros(8, dtype=np.bool_)
    has[va] = has[vb] = has[vc] = True
    has[vb | vc] = active[vb | vc]
    map_at = np.zeros((8, 8), dtype=np.int64)
    for p in range(n):
        e = sel[p]
        ids[vb, p] = ijk[unsigned(e), b]
        ids[vc, p] = ijk[unsigned(e), c]
        ids[vb | vc, p] = pair_ids[unsigned(e)]
    # the pair levels with the axis: (value id, grid index) pairs
    pair_parts = []
    pair_keys = []
    for other in (vb, vc):
        lv = va | other
        if not active[lv]:
            continue
        part_a, part_b = _pair_level(ids, sizes, has, lv, va, other)
        pair_parts.append(part_a)
        pair_keys.append((lv, va))
        pair_parts.append(part_b)
        pair_keys.append((lv, other))
    _place_parts(maps, n, pair_parts, pair_keys, has, map_at)
    total = fixed_end
    for k in (va, va | vb, va | vc):
        offsets[k] = total
        total += rows[k] * sizes[k]
    if total > store.size:  # more points than edges: a larger store with the fixed levels
        grown = np.empty(total)
        grown[:fixed_end] = store[:fixed_end]
        store = grown
    for q in range(ufirst.size):
        store[unsigned(offsets[va] + q)] = u[unsigned(ufirst[q])]
    skip = np.zeros(8, dtype=np.bool_)
    skip[vb] = skip[vc] = skip[vb | vc] = True
    run_lattice(prog, tile, sizes, offsets, maps, map_at, store, out, skip)
