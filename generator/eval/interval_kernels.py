"""The interval interpreter's operations: one code row of the tape over the boxes of a tile.

Registers are three rows per value: ``L[r]``, ``H[r]`` (float64 bounds) and ``N[r]`` (uint8,
1 where a value may be NaN); column k is box k of the tile (the rules:
:mod:`surfgen.generator.eval.interval_rules`). Where a rule needs an elementary function at
the ends of an interval, it copies them into rows of the scratch ``T`` and calls the very
row the point interpreter calls (:func:`surfgen.generator.eval.row_calls.far_row`): the same
bits, and no second copy of the elementary functions compiled here.

Every operand is a W row (the program is rewritten by
:func:`surfgen.generator.eval.tape.points_program`: scalar slots are rows too).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.eval.interval_rules import (
    EMPTY_HI,
    EMPTY_LO,
    HALF_PI,
    INF,
    PI,
    TWO_PI,
    abs_rule,
    add_rule,
    atan2_corners_ok,
    bool_interval,
    can_false,
    can_true,
    compare_rule,
    contains0,
    div_rule,
    down,
    down_rt,
    fmod_rule,
    has_inf,
    hull,
    hull4,
    is_int,
    is_odd,
    may_hit,
    mul_rule,
    recip_rule,
    sign_rule,
    square_rule,
    sub_rule,
    trunc1,
    up,
    up_rt,
    usign_rule,
)
from surfgen.generator.eval.opcodes import OP
from surfgen.generator.eval.row_calls import SLOT, far_row
from surfgen.generator.jit.options import KERNEL

# Opcode numbers as globals (numba freezes them).
_O = OP
O_COPY, O_NEG, O_ABS, O_SIN, O_COS, O_TAN = (
    _O[k] for k in ("copy", "neg", "abs", "sin", "cos", "tan")
)
O_ASIN, O_ACOS, O_ATAN, O_SINH, O_COSH = (_O[k] for k in ("asin", "acos", "atan", "sinh", "cosh"))
O_TANH, O_ASINH, O_ACOSH, O_ATANH = (_O[k] for k in ("tanh", "asinh", "acosh", "atanh"))
O_EXP, O_LOG, O_LOG10, O_SQRT, O_CBRT = (_O[k] for k in ("exp", "log", "log10", "sqrt", "cbrt"))
O_SIGN, O_FLOOR, O_CEIL, O_SQUARE = (_O[k] for k in ("sign", "floor", "ceil", "square"))
O_RECIP, O_USIGN, O_POWI, O_SERIES = (_O[k] for k in ("recip", "usign", "powi", "series"))
O_SEGSUM, O_ADD, O_SUB, O_MUL, O_DIV = (_O[k] for k in ("segsum", "add", "sub", "mul", "div"))
O_POW, O_MIN, O_MAX, O_ATAN2, O_RATIO1 = (_O[k] for k in ("pow", "min", "max", "atan2", "ratio1"))
O_LT, O_LE, O_EQ, O_NE, O_AND, O_OR = (_O[k] for k in ("lt", "le", "eq", "ne", "and", "or"))
O_NOT, O_PICK, O_PICKN, O_FMOD = (_O[k] for k in ("not", "pick", "pickn", "fmod"))
O_TRUNC, O_ATANTAN, O_ASINSIN = (_O[k] for k in ("trunc", "atantan", "asinsin"))
O_ACOSCOS, O_ACOTCOT, O_SEC, O_CSC, O_COT = (
    _O[k] for k in ("acoscos", "acotcot", "sec", "csc", "cot")
)  # noqa: E501

S_SIN, S_COS, S_TAN, S_ASIN, S_ACOS = (SLOT[k] for k in ("sin", "cos", "tan", "asin", "acos"))
S_ATAN, S_SINH, S_COSH, S_TANH = (SLOT[k] for k in ("atan", "sinh", "cosh", "tanh"))
S_ASINH, S_ACOSH, S_ATANH, S_EXP = (SLOT[k] for k in ("asinh", "acosh", "atanh", "exp"))
S_LOG, S_LOG10, S_CBRT, S_COT = (SLOT[k] for k in ("log", "log10", "cbrt", "cot"))
S_ATANTAN, S_ASINSIN, S_ACOSCOS = (SLOT[k] for k in ("atantan", "asinsin", "acoscos"))
S_ACOTCOT, S_ATAN2, S_POW = SLOT["acotcot"], SLOT["atan2_vv"], SLOT["pow_vv"]

# Operations whose value is NaN whenever an operand is (the others: logic, pick, pow).
_NON_STRICT = {"not", "lt", "le", "eq", "ne", "and", "or", "pick", "pickn", "pow", "powi"}
STRICT = np.array([name not in _NON_STRICT for name in sorted(OP, key=OP.get)], dtype=np.bool_)
UNARY = np.zeros(len(OP), dtype=np.bool_)
for _name in ("copy", "neg", "abs", "sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh",
              "tanh", "asinh", "acosh", "atanh", "exp", "log", "log10", "sqrt", "cbrt", "sign",
              "floor", "ceil", "square", "recip", "usign", "powi", "series", "segsum", "not",
              "trunc", "atantan", "asinsin", "acoscos", "acotcot", "sec", "csc", "cot"):  # fmt: skip
    UNARY[OP[_name]] = True


@njit(**KERNEL)
def _set(L, H, N, d, k, lo, hi, nan):
    L[d, k] = lo
    H[d, k] = hi
    N[d, k] = 1 if nan else 0


@njit(**KERNEL)
def _ends(slot, L, H, a, T, n, consts, clo, chi):
    """T[2] = f(lo clamped to [clo, chi]), T[3] = f(hi clamped), f the row of ``slot``."""
    for k in range(n):
        T[0, k] = min(max(L[a, k], clo), chi)
        T[1, k] = min(max(H[a, k], clo), chi)
    far_row(slot, T, 2, 0, 0, 0.0, n, consts, 0)
    far_row(slot, T, 3, 1, 0, 0.0, n, consts, 0)


@njit(**KERNEL)
def _monotone(slot, L, H, N, d, a, n, consts, T, dlo, dhi, increasing):
    """A function monotone on its domain ``[dlo, dhi]`` (NaN outside it)."""
    _ends(slot, L, H, a, T, n, consts, dlo, dhi)
    for k in range(n):
        lo = L[a, k]
        hi = H[a, k]
        if lo > dhi or hi < dlo or lo > hi:
            _set(L, H, N, d, k, EMPTY_LO, EMPTY_HI, True)
            continue
        nan = N[a, k] != 0 or lo < dlo or hi > dhi
        if increasing:
            _set(L, H, N, d, k, down(T[2, k]), up(T[3, k]), nan)
        else:
            _set(L, H, N, d, k, down(T[3, k]), up(T[2, k]), nan)


@njit(**KERNEL)
def _wave(slot, L, H, N, d, a, n, consts, T, off_max, off_min, vmin, vmax, rt):
    """A continuous periodic function (sin, cos, asin(sin), acos(cos)): its maxima at
    ``off_max + 2 pi j``, its minima at ``off_min + 2 pi j``, monotone between; NaN at ±inf."""
    _ends(slot, L, H, a, T, n, consts, -INF, INF)
    for k in range(n):
        lo = L[a, k]
        hi = H[a, k]
        nan = N[a, k] != 0 or has_inf(lo, hi)
        f0 = min(T[2, k], T[3, k])
        f1 = max(T[2, k], T[3, k])
        olo = down_rt(f0) if rt else down(f0)
        ohi = up_rt(f1) if rt else up(f1)
        if may_hit(lo, hi, off_max, TWO_PI):
            ohi = vmax
        if may_hit(lo, hi, off_min, TWO_PI):
            olo = vmin
        _set(L, H, N, d, k, olo, ohi, nan)


@njit(**KERNEL)
def _jumps(slot, L, H, N, d, a, n, consts, T, off, vmin, vmax, increasing, rt):
    """A function monotone between jumps (or poles) at ``off + pi j``: tan, cot, atan(tan),
    acot(cot); ``[vmin, vmax]`` where a jump may fall inside; NaN at ±inf."""
    _ends(slot, L, H, a, T, n, consts, -INF, INF)
    for k in range(n):
        lo = L[a, k]
        hi = H[a, k]
        nan = N[a, k] != 0 or has_inf(lo, hi)
        if may_hit(lo, hi, off, PI):
            _set(L, H, N, d, k, vmin, vmax, nan)
            continue
        f0 = T[2, k] if increasing else T[3, k]
        f1 = T[3, k] if increasing else T[2, k]
        if rt:
            _set(L, H, N, d, k, down_rt(f0), up_rt(f1), nan)
        else:
            _set(L, H, N, d, k, down(f0), up(f1), nan)


@njit(**KERNEL)
def _series(L, H, N, d, a, n, consts, base):
    """The sum of eqs. (2)-(4) (row_operations.series): ``2 (x - r(i-1))`` on the segment
    ``[r(i-1), r i)`` that holds x, ``-p <= i <= p``; 0 elsewhere."""
    r = consts[base]
    p = consts[base + 1]
    exact = consts[base + 2] != 0.0
    top = up(2.0 * r + 4.0 * abs(r * (p + 1.0)) * 2.0**-52)
    left = r * (-p - 1.0)
    right = r * p
    for k in range(n):
        lo = L[a, k]
        hi = H[a, k]
        nan = N[a, k] != 0 or not (max(abs(lo), abs(hi)) <= 1e307)
        if exact:
            _set(L, H, N, d, k, -INF, INF, True)
            continue
        if hi < left or lo >= right:
            _set(L, H, N, d, k, 0.0, 0.0, nan)
            continue
        done = False
        if not nan:
            i0 = np.floor(lo / r) + 1.0
            for i in (i0 - 1.0, i0, i0 + 1.0):
                a0 = r * (i - 1.0)
                b0 = r * i
                if -p <= i and i <= p and a0 <= lo and lo < b0 and hi < b0:
                    _set(L, H, N, d, k, 0.0 + 2.0 * (lo - a0), 0.0 + 2.0 * (hi - a0), nan)
                    done = True
                    break
        if not done:
            _set(L, H, N, d, k, 0.0, top, nan)


@njit(**KERNEL)
def _line(consts, q, kind, x):
    if kind == 0.0:
        return (consts[q + 2] * x + consts[q + 3] - consts[q + 4]) / consts[q + 5]
    return consts[q + 2] * x + consts[q + 3]


@njit(**KERNEL)
def _segsum(L, H, N, d, a, n, consts, base):
    """Segment sums (fcc, fcc8): half the selected segment's line ``0.5 (0 + 2 line(x))`` on
    ``[x0, x1)``, 0 outside every segment; NaN where some line is not finite (``0 * inf``)."""
    kind = consts[base]
    nseg = int(consts[base + 1])
    first = consts[base + 2]
    last = consts[base + 2 + 6 * (nseg - 1) + 1]
    gaps = False
    for s in range(nseg - 1):
        q = base + 2 + 6 * s
        if consts[q + 1] != consts[q + 6]:
            gaps = True
    for k in range(n):
        lo = L[a, k]
        hi = H[a, k]
        nan = N[a, k] != 0
        olo = INF
        ohi = -INF
        if lo < first or hi >= last or gaps:
            olo = 0.0
            ohi = 0.0
        for s in range(nseg):
            q = base + 2 + 6 * s
            v0 = _line(consts, q, kind, lo)
            v1 = _line(consts, q, kind, hi)
            if not (abs(v0) < INF and abs(v1) < INF):
                nan = True
            x0 = max(lo, consts[q])
            x1 = min(hi, consts[q + 1])
            if x0 <= x1 and lo < consts[q + 1] and hi >= consts[q]:
                w0 = 0.5 * (0.0 + 2.0 * _line(consts, q, kind, x0))
                w1 = 0.5 * (0.0 + 2.0 * _line(consts, q, kind, x1))
                if w0 != w0 or w1 != w1:
                    nan = True
                    olo, ohi = -INF, INF
                else:
                    olo, ohi = hull(olo, ohi, min(w0, w1), max(w0, w1))
        _set(L, H, N, d, k, olo, ohi, nan)


@njit(**KERNEL)
def _pow_const(L, H, N, d, a, e, T, k):
    """Box k of ``u^e`` with a constant exponent e: T[4], T[5] hold pow at the ends of u
    (clamped to 0 from below for a non-integer e)."""
    lo = L[a, k]
    hi = H[a, k]
    an = N[a, k] != 0
    if e == 0.0:  # the x^c convention: 1 whatever u, NaN too
        _set(L, H, N, d, k, 1.0, 1.0, False)
        return
    if lo > hi:
        _set(L, H, N, d, k, EMPTY_LO, EMPTY_HI, True)
        return
    if e == 1.0:
        _set(L, H, N, d, k, lo, hi, an)
        return
    if e == 2.0:
        s0, s1 = square_rule(lo, hi)
        _set(L, H, N, d, k, s0, s1, an)
        return
    if e == -1.0:
        r0, r1 = recip_rule(lo, hi)
        _set(L, H, N, d, k, r0, r1, an)
        return
    if e == 0.5:
        if hi < 0.0:
            _set(L, H, N, d, k, EMPTY_LO, EMPTY_HI, True)
        else:
            _set(L, H, N, d, k, np.sqrt(max(lo, 0.0)), np.sqrt(hi), an or lo < 0.0)
        return
    p0 = T[4, k]
    p1 = T[5, k]
    if not (abs(e) < INF):
        _set(L, H, N, d, k, 0.0, INF, an)
        return
    z = contains0(lo, hi)
    if is_int(e) and not is_odd(e):  # even: |u|^e
        if e > 0.0:
            o0 = 0.0 if z else min(p0, p1)
            _set(L, H, N, d, k, down(o0), up(max(p0, p1)), an)
        else:
            o1 = INF if z else max(p0, p1)
            _set(L, H, N, d, k, down(min(p0, p1)), up(o1), an)
        return
    if is_odd(e):
        if e > 0.0:
            _set(L, H, N, d, k, down(p0), up(p1), an)
        elif z:
            _set(L, H, N, d, k, -INF, INF, an)
        else:
            _set(L, H, N, d, k, down(p1), up(p0), an)
        return
    # a non-integer exponent: NaN below 0 but at -inf; T[4] is pow at max(lo, 0)
    nan = an or lo < 0.0
    olo = INF
    ohi = -INF
    if hi >= 0.0:
        if e > 0.0:
            olo, ohi = down(p0), up(p1)
        else:
            olo, ohi = down(p1), up(p0)
    if lo == -INF:
        v = INF if e > 0.0 else 0.0
        olo, ohi = hull(olo, ohi, v, v)
    _set(L, H, N, d, k, olo, ohi, nan)


@njit(**KERNEL)
def _pow(L, H, N, d, a, b, n, consts, T):
    """``u^e`` (surfgen's pow with the x^c convention)."""
    for k in range(n):
        lo = L[a, k]
        hi = H[a, k]
        const_e = L[b, k] == H[b, k] and N[b, k] == 0
        e = L[b, k]
        if const_e and not is_int(e) and abs(e) < INF:
            lo = max(lo, 0.0)  # the non-integer exponent's NaN side is handled apart
            hi = max(hi, 0.0)
        T[0, k] = lo
        T[1, k] = hi
        T[2, k] = L[b, k]
        T[3, k] = H[b, k]
    far_row(S_POW, T, 4, 0, 2, 0.0, n, consts, 0)
    far_row(S_POW, T, 5, 1, 2, 0.0, n, consts, 0)
    far_row(S_POW, T, 6, 0, 3, 0.0, n, consts, 0)
    far_row(S_POW, T, 7, 1, 3, 0.0, n, consts, 0)
    for k in range(n):
        alo = L[a, k]
        ahi = H[a, k]
        blo = L[b, k]
        bhi = H[b, k]
        if blo == bhi and N[b, k] == 0:
            _pow_const(L, H, N, d, a, blo, T, k)
            continue
        if alo > ahi or blo > bhi:  # pow(NaN, 0) = pow(1, NaN) = 1
            _set(L, H, N, d, k, 1.0, 1.0, True)
            continue
        nan = N[a, k] != 0 or N[b, k] != 0
        if alo >= 0.0:
            olo, ohi, bad = hull4(T[4, k], T[5, k], T[6, k], T[7, k])
            olo = down(olo)
            ohi = up(ohi)
            if alo == 0.0 and blo < 0.0:  # pow(-0, -odd) = -inf; 1/-0 too
                olo = -INF
            if nan:
                olo, ohi = hull(olo, ohi, 1.0, 1.0)
            _set(L, H, N, d, k, olo, ohi, nan or bad)
        else:
            _set(L, H, N, d, k, -INF, INF, True)


@njit(**KERNEL)
def _atan2(L, H, N, d, a, b, n, consts, T):
    for k in range(n):
        T[0, k] = L[a, k]
        T[1, k] = H[a, k]
        T[2, k] = L[b, k]
        T[3, k] = H[b, k]
    far_row(S_ATAN2, T, 4, 0, 2, 0.0, n, consts, 0)
    far_row(S_ATAN2, T, 5, 0, 3, 0.0, n, consts, 0)
    far_row(S_ATAN2, T, 6, 1, 2, 0.0, n, consts, 0)
    far_row(S_ATAN2, T, 7, 1, 3, 0.0, n, consts, 0)
    for k in range(n):
        nan = N[a, k] != 0 or N[b, k] != 0
        if atan2_corners_ok(L[a, k], H[a, k], L[b, k], H[b, k]):
            lo, hi, bad = hull4(T[4, k], T[5, k], T[6, k], T[7, k])
            _set(L, H, N, d, k, down(lo), up(hi), nan or bad)
        else:
            _set(L, H, N, d, k, down(-PI), up(PI), nan)


@njit(**KERNEL)
def iv_unary(op, L, H, N, d, a, n, consts, imm, T):
    """Code row ``W[d] = op(W[a])`` on intervals."""
    if op == O_COPY:
        for k in range(n):
            _set(L, H, N, d, k, L[a, k], H[a, k], N[a, k] != 0)
    elif op == O_NEG:
        for k in range(n):
            _set(L, H, N, d, k, -H[a, k], -L[a, k], N[a, k] != 0)
    elif op == O_ABS:
        for k in range(n):
            lo, hi = abs_rule(L[a, k], H[a, k])
            _set(L, H, N, d, k, lo, hi, N[a, k] != 0)
    elif op == O_SQUARE:
        for k in range(n):
            lo, hi = square_rule(L[a, k], H[a, k])
            _set(L, H, N, d, k, lo, hi, N[a, k] != 0)
    elif op == O_RECIP:
        for k in range(n):
            lo, hi = recip_rule(L[a, k], H[a, k])
            _set(L, H, N, d, k, lo, hi, N[a, k] != 0)
    elif op == O_SQRT:
        for k in range(n):
            lo = L[a, k]
            hi = H[a, k]
            if hi < 0.0:
                _set(L, H, N, d, k, EMPTY_LO, EMPTY_HI, True)
            else:
                _set(L, H, N, d, k, np.sqrt(max(lo, 0.0)), np.sqrt(hi), N[a, k] != 0 or lo < 0.0)
    elif op == O_SIGN:
        for k in range(n):
            lo, hi = sign_rule(L[a, k], H[a, k])
            _set(L, H, N, d, k, lo, hi, N[a, k] != 0)
    elif op == O_USIGN:
        for k in range(n):
            lo, hi = usign_rule(L[a, k], H[a, k])
            _set(L, H, N, d, k, lo, hi, N[a, k] != 0)
    elif op == O_FLOOR:
        for k in range(n):
            _set(L, H, N, d, k, np.floor(L[a, k]), np.floor(H[a, k]), N[a, k] != 0)
    elif op == O_CEIL:
        for k in range(n):
            _set(L, H, N, d, k, np.ceil(L[a, k]), np.ceil(H[a, k]), N[a, k] != 0)
    elif op == O_TRUNC:
        for k in range(n):
            _set(L, H, N, d, k, trunc1(L[a, k]), trunc1(H[a, k]), N[a, k] != 0)
    elif op == O_NOT:
        for k in range(n):
            t = can_false(L[a, k], H[a, k], N[a, k] != 0)
            f = can_true(L[a, k], H[a, k])
            lo, hi = bool_interval(t, f)
            _set(L, H, N, d, k, lo, hi, False)
    elif op == O_SIN:
        _wave(S_SIN, L, H, N, d, a, n, consts, T, HALF_PI, -HALF_PI, down(-1.0), up(1.0), False)
    elif op == O_COS:
        _wave(S_COS, L, H, N, d, a, n, consts, T, 0.0, PI, down(-1.0), up(1.0), False)
    elif op == O_ASINSIN:
        vlo, vhi = down_rt(-HALF_PI), up_rt(HALF_PI)
        _wave(S_ASINSIN, L, H, N, d, a, n, consts, T, HALF_PI, -HALF_PI, vlo, vhi, True)
    elif op == O_ACOSCOS:
        _wave(S_ACOSCOS, L, H, N, d, a, n, consts, T, PI, 0.0, down_rt(0.0), up_rt(PI), True)
    elif op == O_SEC or op == O_CSC:  # noqa: SIM109 (numba)
        if op == O_SEC:
            _wave(S_COS, L, H, N, d, a, n, consts, T, 0.0, PI, down(-1.0), up(1.0), False)
        else:
            _wave(S_SIN, L, H, N, d, a, n, consts, T, HALF_PI, -HALF_PI, down(-1.0), up(1.0), False)
        for k in range(n):  # 1/cos u, 1/sin u: the same bits as the two operations
            lo, hi = recip_rule(L[d, k], H[d, k])
            L[d, k] = lo
            H[d, k] = hi
    elif op == O_TAN:
        _jumps(S_TAN, L, H, N, d, a, n, consts, T, HALF_PI, -INF, INF, True, False)
    elif op == O_COT:
        _jumps(S_COT, L, H, N, d, a, n, consts, T, 0.0, -INF, INF, False, False)
    elif op == O_ATANTAN:
        vlo, vhi = down_rt(-HALF_PI), up_rt(HALF_PI)
        _jumps(S_ATANTAN, L, H, N, d, a, n, consts, T, HALF_PI, vlo, vhi, True, True)
    elif op == O_ACOTCOT:
        _jumps(S_ACOTCOT, L, H, N, d, a, n, consts, T, 0.0, down_rt(0.0), up_rt(PI), True, True)
    elif op == O_ASIN:
        _monotone(S_ASIN, L, H, N, d, a, n, consts, T, -1.0, 1.0, True)
    elif op == O_ACOS:
        _monotone(S_ACOS, L, H, N, d, a, n, consts, T, -1.0, 1.0, False)
    elif op == O_ATAN:
        _monotone(S_ATAN, L, H, N, d, a, n, consts, T, -INF, INF, True)
    elif op == O_SINH:
        _monotone(S_SINH, L, H, N, d, a, n, consts, T, -INF, INF, True)
    elif op == O_TANH:
        _monotone(S_TANH, L, H, N, d, a, n, consts, T, -INF, INF, True)
    elif op == O_ASINH:
        _monotone(S_ASINH, L, H, N, d, a, n, consts, T, -INF, INF, True)
    elif op == O_ACOSH:
        _monotone(S_ACOSH, L, H, N, d, a, n, consts, T, 1.0, INF, True)
    elif op == O_ATANH:
        _monotone(S_ATANH, L, H, N, d, a, n, consts, T, -1.0, 1.0, True)
    elif op == O_EXP:
        _monotone(S_EXP, L, H, N, d, a, n, consts, T, -INF, INF, True)
    elif op == O_LOG:
        _monotone(S_LOG, L, H, N, d, a, n, consts, T, 0.0, INF, True)
    elif op == O_LOG10:
        _monotone(S_LOG10, L, H, N, d, a, n, consts, T, 0.0, INF, True)
    elif op == O_CBRT:
        _monotone(S_CBRT, L, H, N, d, a, n, consts, T, -INF, INF, True)
    elif op == O_COSH:
        _ends(S_COSH, L, H, a, T, n, consts, -INF, INF)
        for k in range(n):
            lo = L[a, k]
            hi = H[a, k]
            f0 = min(T[2, k], T[3, k])
            f1 = max(T[2, k], T[3, k])
            if contains0(lo, hi):
                f0 = 1.0
            _set(L, H, N, d, k, down(f0), up(f1), N[a, k] != 0)
    elif op == O_POWI:  # u^imm (programs of earlier versions): pow with a constant exponent
        e = float(imm)
        for k in range(n):
            T[0, k] = L[a, k]
            T[1, k] = H[a, k]
            T[2, k] = e
        far_row(S_POW, T, 4, 0, 2, 0.0, n, consts, 0)
        far_row(S_POW, T, 5, 1, 2, 0.0, n, consts, 0)
        for k in range(n):
            _pow_const(L, H, N, d, a, e, T, k)
    elif op == O_SERIES:
        _series(L, H, N, d, a, n, consts, imm)
    elif op == O_SEGSUM:
        _segsum(L, H, N, d, a, n, consts, imm)


@njit(**KERNEL)
def iv_binary(op, L, H, N, d, a, b, n, consts, T):
    """Code row ``W[d] = op(W[a], W[b])`` on intervals."""
    same = a == b
    if op == O_ADD or op == O_SUB or op == O_MUL or op == O_MIN or op == O_MAX:  # noqa: SIM109 (numba)
        for k in range(n):
            alo, ahi, blo, bhi = L[a, k], H[a, k], L[b, k], H[b, k]
            nan = N[a, k] != 0 or N[b, k] != 0
            if op == O_ADD:
                lo, hi, bad = add_rule(alo, ahi, blo, bhi)
            elif op == O_SUB:
                if same:
                    lo, hi, bad = 0.0, 0.0, has_inf(alo, ahi)
                else:
                    lo, hi, bad = sub_rule(alo, ahi, blo, bhi)
            elif op == O_MUL:
                if same:
                    lo, hi = square_rule(alo, ahi)
                    bad = False
                else:
                    lo, hi, bad = mul_rule(alo, ahi, blo, bhi)
            elif op == O_MIN:
                lo, hi, bad = min(alo, blo), min(ahi, bhi), False
            else:
                lo, hi, bad = max(alo, blo), max(ahi, bhi), False
            _set(L, H, N, d, k, lo, hi, nan or bad)
    elif op == O_DIV or op == O_RATIO1:  # noqa: SIM109 (numba)
        for k in range(n):
            alo, ahi, blo, bhi = L[a, k], H[a, k], L[b, k], H[b, k]
            nan = N[a, k] != 0 or N[b, k] != 0
            if same:
                zz = contains0(alo, ahi)
                ii = has_inf(alo, ahi)
                _set(L, H, N, d, k, 1.0, 1.0, nan or ii or (zz and op == O_DIV))
                continue
            lo, hi, zz, ii = div_rule(alo, ahi, blo, bhi)
            if op == O_RATIO1:
                if zz:
                    lo, hi = hull(lo, hi, 1.0, 1.0)
                _set(L, H, N, d, k, lo, hi, nan or ii)
            else:
                _set(L, H, N, d, k, lo, hi, nan or ii or zz)
    elif op == O_FMOD:
        for k in range(n):
            lo, hi, bad = fmod_rule(L[a, k], H[a, k], L[b, k], H[b, k])
            _set(L, H, N, d, k, lo, hi, N[a, k] != 0 or N[b, k] != 0 or bad)
    elif op == O_LT or op == O_LE or op == O_EQ or op == O_NE:  # noqa: SIM109 (numba)
        for k in range(n):
            lo, hi = compare_rule(
                op, L[a, k], H[a, k], N[a, k] != 0, L[b, k], H[b, k], N[b, k] != 0,
                O_LT, O_LE, O_EQ, O_NE,
            )  # fmt: skip
            _set(L, H, N, d, k, lo, hi, False)
    elif op == O_AND or op == O_OR:  # noqa: SIM109 (numba)
        for k in range(n):
            ta = can_true(L[a, k], H[a, k])
            fa = can_false(L[a, k], H[a, k], N[a, k] != 0)
            tb = can_true(L[b, k], H[b, k])
            fb = can_false(L[b, k], H[b, k], N[b, k] != 0)
            if op == O_AND:
                lo, hi = bool_interval(ta and tb, fa or fb)
            else:
                lo, hi = bool_interval(ta or tb, fa and fb)
            _set(L, H, N, d, k, lo, hi, False)
    elif op == O_PICK or op == O_PICKN:  # noqa: SIM109 (numba)
        for k in range(n):
            t = can_true(L[a, k], H[a, k])
            f = can_false(L[a, k], H[a, k], N[a, k] != 0)
            take, zero = (t, f) if op == O_PICK else (f, t)
            lo, hi, nan = EMPTY_LO, EMPTY_HI, False
            if take:
                lo, hi, nan = L[b, k], H[b, k], N[b, k] != 0
            if zero:
                lo, hi = hull(lo, hi, 0.0, 0.0)
            _set(L, H, N, d, k, lo, hi, nan)
    elif op == O_POW:
        _pow(L, H, N, d, a, b, n, consts, T)
    elif op == O_ATAN2:
        _atan2(L, H, N, d, a, b, n, consts, T)


@njit(**KERNEL)
def run_code_iv(code, c0, c1, consts, L, H, N, T, n):
    """Run code rows ``[c0, c1)`` (operand modes v and vv only) on the first n boxes."""
    for pc in range(c0, c1):
        op = code[pc, 0]
        d = code[pc, 2]
        a = code[pc, 3]
        b = code[pc, 4]
        unary = UNARY[op]
        if unary:
            iv_unary(op, L, H, N, d, a, n, consts, code[pc, 5], T)
        else:
            iv_binary(op, L, H, N, d, a, b, n, consts, T)
        if STRICT[op]:  # a NaN operand everywhere: NaN everywhere
            for k in range(n):
                if L[a, k] > H[a, k] or (not unary and L[b, k] > H[b, k]):
                    _set(L, H, N, d, k, EMPTY_LO, EMPTY_HI, True)
