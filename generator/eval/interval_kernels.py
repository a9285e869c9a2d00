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

from surfgen.generator.eval.interval_rows import (
    atan2_rows,
    ends,
    jumps,
    monotone,
    pow_const,
    pow_rows,
    put,
    segsum_rows,
    series_rows,
    wave,
)
from surfgen.generator.eval.interval_rules import (
    EMPTY_HI,
    EMPTY_LO,
    HALF_PI,
    INF,
    PI,
    abs_rule,
    add_rule,
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
S_ACOTCOT, S_POW = SLOT["acotcot"], SLOT["pow_vv"]

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
def iv_unary(op, L, H, N, d, a, n, consts, imm, T):
    """Code row ``W[d] = op(W[a])`` on intervals."""
    if op == O_COPY:
        for k in range(n):
            put(L, H, N, d, k, L[a, k], H[a, k], N[a, k] != 0)
    elif op == O_NEG:
        for k in range(n):
            put(L, H, N, d, k, -H[a, k], -L[a, k], N[a, k] != 0)
    elif op == O_ABS:
        for k in range(n):
            lo, hi = abs_rule(L[a, k], H[a, k])
            put(L, H, N, d, k, lo, hi, N[a, k] != 0)
    elif op == O_SQUARE:
        for k in range(n):
            lo, hi = square_rule(L[a, k], H[a, k])
            put(L, H, N, d, k, lo, hi, N[a, k] != 0)
    elif op == O_RECIP:
        for k in range(n):
            lo, hi = recip_rule(L[a, k], H[a, k])
            put(L, H, N, d, k, lo, hi, N[a, k] != 0)
    elif op == O_SQRT:
        for k in range(n):
            lo = L[a, k]
            hi = H[a, k]
            if hi < 0.0:
                put(L, H, N, d, k, EMPTY_LO, EMPTY_HI, True)
            else:
                put(L, H, N, d, k, np.sqrt(max(lo, 0.0)), np.sqrt(hi), N[a, k] != 0 or lo < 0.0)
    elif op == O_SIGN:
        for k in range(n):
            lo, hi = sign_rule(L[a, k], H[a, k])
            put(L, H, N, d, k, lo, hi, N[a, k] != 0)
    elif op == O_USIGN:
        for k in range(n):
            lo, hi = usign_rule(L[a, k], H[a, k])
            put(L, H, N, d, k, lo, hi, N[a, k] != 0)
    elif op == O_FLOOR:
        for k in range(n):
            put(L, H, N, d, k, np.floor(L[a, k]), np.floor(H[a, k]), N[a, k] != 0)
    elif op == O_CEIL:
        for k in range(n):
            put(L, H, N, d, k, np.ceil(L[a, k]), np.ceil(H[a, k]), N[a, k] != 0)
    elif op == O_TRUNC:
        for k in range(n):
            put(L, H, N, d, k, trunc1(L[a, k]), trunc1(H[a, k]), N[a, k] != 0)
    elif op == O_NOT:
        for k in range(n):
            t = can_false(L[a, k], H[a, k], N[a, k] != 0)
            f = can_true(L[a, k], H[a, k])
            lo, hi = bool_interval(t, f)
            put(L, H, N, d, k, lo, hi, False)
    elif op == O_SIN:
        wave(S_SIN, L, H, N, d, a, n, consts, T, HALF_PI, -HALF_PI, down(-1.0), up(1.0), False)
    elif op == O_COS:
        wave(S_COS, L, H, N, d, a, n, consts, T, 0.0, PI, down(-1.0), up(1.0), False)
    elif op == O_ASINSIN:
        vlo, vhi = down_rt(-HALF_PI), up_rt(HALF_PI)
        wave(S_ASINSIN, L, H, N, d, a, n, consts, T, HALF_PI, -HALF_PI, vlo, vhi, True)
    elif op == O_ACOSCOS:
        wave(S_ACOSCOS, L, H, N, d, a, n, consts, T, PI, 0.0, down_rt(0.0), up_rt(PI), True)
    elif op == O_SEC or op == O_CSC:  # noqa: SIM109 (numba)
        if op == O_SEC:
            wave(S_COS, L, H, N, d, a, n, consts, T, 0.0, PI, down(-1.0), up(1.0), False)
        else:
            wave(S_SIN, L, H, N, d, a, n, consts, T, HALF_PI, -HALF_PI, down(-1.0), up(1.0), False)
        for k in range(n):  # 1/cos u, 1/sin u: the same bits as the two operations
            lo, hi = recip_rule(L[d, k], H[d, k])
            L[d, k] = lo
            H[d, k] = hi
    elif op == O_TAN:
        jumps(S_TAN, L, H, N, d, a, n, consts, T, HALF_PI, -INF, INF, True, False)
    elif op == O_COT:
        jumps(S_COT, L, H, N, d, a, n, consts, T, 0.0, -INF, INF, False, False)
    elif op == O_ATANTAN:
        vlo, vhi = down_rt(-HALF_PI), up_rt(HALF_PI)
        jumps(S_ATANTAN, L, H, N, d, a, n, consts, T, HALF_PI, vlo, vhi, True, True)
    elif op == O_ACOTCOT:
        jumps(S_ACOTCOT, L, H, N, d, a, n, consts, T, 0.0, down_rt(0.0), up_rt(PI), True, True)
    elif op == O_ASIN:
        monotone(S_ASIN, L, H, N, d, a, n, consts, T, -1.0, 1.0, True)
    elif op == O_ACOS:
        monotone(S_ACOS, L, H, N, d, a, n, consts, T, -1.0, 1.0, False)
    elif op == O_ATAN:
        monotone(S_ATAN, L, H, N, d, a, n, consts, T, -INF, INF, True)
    elif op == O_SINH:
        monotone(S_SINH, L, H, N, d, a, n, consts, T, -INF, INF, True)
    elif op == O_TANH:
        monotone(S_TANH, L, H, N, d, a, n, consts, T, -INF, INF, True)
    elif op == O_ASINH:
        monotone(S_ASINH, L, H, N, d, a, n, consts, T, -INF, INF, True)
    elif op == O_ACOSH:
        monotone(S_ACOSH, L, H, N, d, a, n, consts, T, 1.0, INF, True)
    elif op == O_ATANH:
        monotone(S_ATANH, L, H, N, d, a, n, consts, T, -1.0, 1.0, True)
    elif op == O_EXP:
        monotone(S_EXP, L, H, N, d, a, n, consts, T, -INF, INF, True)
    elif op == O_LOG:
        monotone(S_LOG, L, H, N, d, a, n, consts, T, 0.0, INF, True)
    elif op == O_LOG10:
        monotone(S_LOG10, L, H, N, d, a, n, consts, T, 0.0, INF, True)
    elif op == O_CBRT:
        monotone(S_CBRT, L, H, N, d, a, n, consts, T, -INF, INF, True)
    elif op == O_COSH:
        ends(S_COSH, L, H, a, T, n, consts, -INF, INF)
        for k in range(n):
            lo = L[a, k]
            hi = H[a, k]
            f0 = min(T[2, k], T[3, k])
            f1 = max(T[2, k], T[3, k])
            if contains0(lo, hi):
                f0 = 1.0
            put(L, H, N, d, k, down(f0), up(f1), N[a, k] != 0)
    elif op == O_POWI:  # u^imm (programs of earlier versions): pow with a constant exponent
        e = float(imm)
        for k in range(n):
            T[0, k] = L[a, k]
            T[1, k] = H[a, k]
            T[2, k] = e
        far_row(S_POW, T, 4, 0, 2, 0.0, n, consts, 0)
        far_row(S_POW, T, 5, 1, 2, 0.0, n, consts, 0)
        for k in range(n):
            pow_const(L, H, N, d, a, e, T, k)
    elif op == O_SERIES:
        series_rows(L, H, N, d, a, n, consts, imm)
    elif op == O_SEGSUM:
        segsum_rows(L, H, N, d, a, n, consts, imm)


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
            put(L, H, N, d, k, lo, hi, nan or bad)
    elif op == O_DIV or op == O_RATIO1:  # noqa: SIM109 (numba)
        for k in range(n):
            alo, ahi, blo, bhi = L[a, k], H[a, k], L[b, k], H[b, k]
            nan = N[a, k] != 0 or N[b, k] != 0
            if same:
                zz = contains0(alo, ahi)
                ii = has_inf(alo, ahi)
                put(L, H, N, d, k, 1.0, 1.0, nan or ii or (zz and op == O_DIV))
                continue
            lo, hi, zz, ii = div_rule(alo, ahi, blo, bhi)
            if op == O_RATIO1:
                if zz:
                    lo, hi = hull(lo, hi, 1.0, 1.0)
                put(L, H, N, d, k, lo, hi, nan or ii)
            else:
                put(L, H, N, d, k, lo, hi, nan or ii or zz)
    elif op == O_FMOD:
        for k in range(n):
            lo, hi, bad = fmod_rule(L[a, k], H[a, k], L[b, k], H[b, k])
            put(L, H, N, d, k, lo, hi, N[a, k] != 0 or N[b, k] != 0 or bad)
    elif op == O_LT or op == O_LE or op == O_EQ or op == O_NE:  # noqa: SIM109 (numba)
        for k in range(n):
            lo, hi = compare_rule(
                op, L[a, k], H[a, k], N[a, k] != 0, L[b, k], H[b, k], N[b, k] != 0,
                O_LT, O_LE, O_EQ, O_NE,
            )  # fmt: skip
            put(L, H, N, d, k, lo, hi, False)
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
            put(L, H, N, d, k, lo, hi, False)
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
            put(L, H, N, d, k, lo, hi, nan)
    elif op == O_POW:
        pow_rows(L, H, N, d, a, b, n, consts, T)
    elif op == O_ATAN2:
        atan2_rows(L, H, N, d, a, b, n, consts, T)


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
                    put(L, H, N, d, k, EMPTY_LO, EMPTY_HI, True)


@njit(**KERNEL)
def run_boxes(prog, tile, levels, counts, offsets, item_map, SL, SH, SN, out_lo, out_hi, out_nan):
    """Bounds of a program (``points_program`` form) over the items of each level.

    Level ``lv`` has ``counts[lv]`` items (distinct x ranges for level x, distinct pairs of
    ranges for xy, the boxes for xyz), stored from column ``offsets[lv]`` of the stores
    ``SL``, ``SH`` and the may-be-NaN flags ``SN`` (rows: the level's store rows; row 0 of
    levels x, y, z holds the ranges of the axis, filled by the caller; ``SN`` zeros);
    ``item_map[s, offsets[lv] + i]`` is the column of the item of level ``s`` that item i of
    level lv reads. Only the levels in ``levels`` run (the stores of the others are the
    caller's). The output is one value per box."""
    code, blocks, loads, stores, consts = prog[0], prog[1], prog[2], prog[3], prog[4]
    n_rows = prog[6]
    L = np.empty((n_rows, tile))
    H = np.empty((n_rows, tile))
    N = np.zeros((n_rows, tile), dtype=np.uint8)
    T = np.empty((8, tile))
    for lv in levels:
        c0 = blocks[lv, 0]
        c1 = blocks[lv, 1]
        if c0 == c1:
            continue
        base = offsets[lv]
        total = counts[lv]
        for p0 in range(0, total, tile):
            n = min(tile, total - p0)
            for q in range(blocks[lv, 2], blocks[lv, 3]):
                kind = loads[q, 0]
                row = loads[q, 1]
                slot = loads[q, 2]
                if kind == 0:
                    v = consts[row]
                    vlo, vhi, vn = (v, v, 0) if v == v else (EMPTY_LO, EMPTY_HI, 1)
                    for k in range(n):
                        L[slot, k] = vlo
                        H[slot, k] = vhi
                        N[slot, k] = vn
                else:
                    for k in range(n):
                        g = item_map[kind, base + p0 + k]
                        L[slot, k] = SL[row, g]
                        H[slot, k] = SH[row, g]
                        N[slot, k] = SN[row, g]
            run_code_iv(code, c0, c1, consts, L, H, N, T, n)
            for q in range(blocks[lv, 4], blocks[lv, 5]):
                slot = stores[q, 0]
                kind = stores[q, 1]
                row = stores[q, 2]
                if kind == 7:
                    for k in range(n):
                        out_lo[p0 + k] = L[slot, k]
                        out_hi[p0 + k] = H[slot, k]
                        out_nan[p0 + k] = N[slot, k]
                else:
                    for k in range(n):
                        SL[row, base + p0 + k] = L[slot, k]
                        SH[row, base + p0 + k] = H[slot, k]
                        SN[row, base + p0 + k] = N[slot, k]
