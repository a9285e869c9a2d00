"""The one numba interpreter that runs every compiled formula (tape format: compiler.py).

Kernels are dumb: arrays and scalars in, arrays out; :mod:`surfgen.generator.fast` validates
before calling. ``error_model='numpy'`` so that 0/0 and 1/0 give NaN and inf instead of raising;
no fastmath (NaN and inf are normal values here). Transcendental functions are the C library's
(``math.sin`` -> libm ``sin``), the same calls numpy makes on x86-64 without AVX-512, so results
are bit-identical to the numpy reference.

Layout of a run: the caller allocates the output; the x, y, z and yz stores are computed once
(:func:`_prologue`, :func:`_yz_rows`), then each slab of x indices (:func:`_slab`, one per
thread chunk) computes its xy and xz rows per i and the xyz block per (i, j) row of z values,
in tiles of W rows, writing straight into the output. Scratch is O(tile * n_vector) per thread
plus the yz store.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, prange, types
from numba.core import cgutils
from numba.extending import intrinsic
from surfgen.generator.compiler import M_S, M_SV, M_V, M_VS, M_VV, OP

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

# powi: the double-double power is returned when it stays correctly rounded after moving it
# 1/0.94 of its way to the rounding boundary, i.e. when it is not within 0.03 ulp of a
# midpoint; glibc's pow is within 0.52 ulp, so both then round to the same double.
_POWI_MARGIN = 1.0 / 0.94


@intrinsic
def _fma(typingctx, a, b, c):
    """Fused multiply-add (one rounding): exact products for double-double arithmetic."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(d, [d, d, d]), "llvm.fma.f64"
        )
        return builder.call(fn, args)

    return sig, codegen


# ----------------------------------------------------------------------------- scalar helpers


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
def _pow_scalar_exponent(u, e):
    """np.power with a stride-0 exponent: numpy's fast path, else C pow."""
    if e == 2.0:
        return u * u
    if e == 0.5:
        return math.sqrt(u)
    if e == -1.0:
        return 1.0 / u
    if e == 1.0:
        return u
    if e == 0.0:
        return 1.0
    return u**e


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
                return 2.0 * (x - a)
    return 0.0


# ----------------------------------------------------------------------------- row operations


@njit(**_OPTS)
def _powi(o, a, n, m, T):
    """o = a^m for an integer |m| >= 2 (o is not a). Double-double power, C pow where the
    rounding could differ (about 6% of inputs, and every non-finite or extreme one)."""
    H = T[0]
    L = T[1]
    e = abs(m)
    for k in range(n):
        H[k] = a[k]
        L[k] = 0.0
    for _ in range(e - 1):
        for k in range(n):
            u = a[k]
            h = H[k]
            p = h * u
            s = _fma(h, u, -p) + L[k] * u
            hh = p + s
            L[k] = s - (hh - p)
            H[k] = hh
    if m < 0:
        for k in range(n):
            h = H[k]
            q = 1.0 / h
            c = q * (_fma(-q, h, 1.0) - q * L[k])
            hh = q + c
            L[k] = c - (hh - q)
            H[k] = hh
    bad = 0
    for k in range(n):
        h = H[k]
        ok = (h + L[k] * _POWI_MARGIN == h) and (abs(h) > 1e-300) and (abs(h) < 1e300)
        o[k] = h
        bad += not ok
    if bad:
        fm = float(m)
        for k in range(n):
            h = H[k]
            if not ((h + L[k] * _POWI_MARGIN == h) and (abs(h) > 1e-300) and (abs(h) < 1e300)):
                o[k] = a[k] ** fm


@njit(**_OPTS)
def _segsum(o, a, n, consts, base):
    kind = consts[base]
    nseg = int(consts[base + 1])
    for k in range(n):
        x = a[k]
        total = 0.0
        for s in range(nseg):
            q = base + 2 + 6 * s
            sel = 1.0 - _usign(x - consts[q]) * _usign(x - consts[q + 1])
            if kind == 0.0:  # fcc: ((y1-y0) x + y0 x1 - y1 x0) / (x1 - x0)
                line = (consts[q + 2] * x + consts[q + 3] - consts[q + 4]) / consts[q + 5]
            else:  # fcc8: slope x + intercept
                line = consts[q + 2] * x + consts[q + 3]
            total = total + sel * line
        o[k] = 0.5 * total


@njit(**_OPTS)
def _unary(op, o, a, n, consts, imm, T):
    if op == OP_COPY:
        for k in range(n):
            o[k] = a[k]
    elif op == OP_NEG:
        for k in range(n):
            o[k] = -a[k]
    elif op == OP_ABS:
        for k in range(n):
            o[k] = abs(a[k])
    elif op == OP_SQUARE:
        for k in range(n):
            o[k] = a[k] * a[k]
    elif op == OP_RECIP:
        for k in range(n):
            o[k] = 1.0 / a[k]
    elif op == OP_SQRT:
        for k in range(n):
            o[k] = math.sqrt(a[k])
    elif op == OP_SIN:
        for k in range(n):
            o[k] = math.sin(a[k])
    elif op == OP_COS:
        for k in range(n):
            o[k] = math.cos(a[k])
    elif op == OP_TAN:
        for k in range(n):
            o[k] = math.tan(a[k])
    elif op == OP_ATAN:
        for k in range(n):
            o[k] = math.atan(a[k])
    elif op == OP_ASIN:
        for k in range(n):
            o[k] = math.asin(a[k])
    elif op == OP_ACOS:
        for k in range(n):
            o[k] = math.acos(a[k])
    elif op == OP_POWI:
        _powi(o, a, n, imm, T)
    elif op == OP_USIGN:
        for k in range(n):
            o[k] = _usign(a[k])
    elif op == OP_EXP:
        for k in range(n):
            o[k] = math.exp(a[k])
    elif op == OP_LOG:
        for k in range(n):
            o[k] = math.log(a[k])
    elif op == OP_LOG10:
        for k in range(n):
            o[k] = math.log10(a[k])
    elif op == OP_SINH:
        for k in range(n):
            o[k] = math.sinh(a[k])
    elif op == OP_COSH:
        for k in range(n):
            o[k] = math.cosh(a[k])
    elif op == OP_TANH:
        for k in range(n):
            o[k] = math.tanh(a[k])
    elif op == OP_ASINH:
        for k in range(n):
            o[k] = math.asinh(a[k])
    elif op == OP_ACOSH:
        for k in range(n):
            o[k] = math.acosh(a[k])
    elif op == OP_ATANH:
        for k in range(n):
            o[k] = math.atanh(a[k])
    elif op == OP_CBRT:
        for k in range(n):
            o[k] = np.cbrt(a[k])
    elif op == OP_SIGN:
        for k in range(n):
            o[k] = _sign(a[k])
    elif op == OP_FLOOR:
        for k in range(n):
            o[k] = np.floor(a[k])
    elif op == OP_CEIL:
        for k in range(n):
            o[k] = np.ceil(a[k])
    elif op == OP_SERIES:
        r = consts[imm]
        p = int(consts[imm + 1])
        if consts[imm + 2] != 0.0:
            for k in range(n):
                o[k] = _series_exact(a[k], r, p)
        else:
            for k in range(n):
                o[k] = _series(a[k], r, p)
    elif op == OP_SEGSUM:
        _segsum(o, a, n, consts, imm)


@njit(**_OPTS)
def _binary_vv(op, o, a, b, n):
    if op == OP_MUL:
        for k in range(n):
            o[k] = a[k] * b[k]
    elif op == OP_ADD:
        for k in range(n):
            o[k] = a[k] + b[k]
    elif op == OP_SUB:
        for k in range(n):
            o[k] = a[k] - b[k]
    elif op == OP_DIV:
        for k in range(n):
            o[k] = a[k] / b[k]
    elif op == OP_POW:
        for k in range(n):
            o[k] = a[k] ** b[k]
    elif op == OP_MIN:
        for k in range(n):
            o[k] = _minimum(a[k], b[k])
    elif op == OP_MAX:
        for k in range(n):
            o[k] = _maximum(a[k], b[k])
    elif op == OP_ATAN2:
        for k in range(n):
            o[k] = math.atan2(a[k], b[k])
    elif op == OP_RATIO1:
        for k in range(n):
            o[k] = _ratio1(a[k], b[k])


@njit(**_OPTS)
def _binary_vs(op, o, a, s, n):
    if op == OP_MUL:
        for k in range(n):
            o[k] = a[k] * s
    elif op == OP_ADD:
        for k in range(n):
            o[k] = a[k] + s
    elif op == OP_SUB:
        for k in range(n):
            o[k] = a[k] - s
    elif op == OP_DIV:
        for k in range(n):
            o[k] = a[k] / s
    elif op == OP_POW:
        if s == 2.0 or s == 0.5 or s == -1.0 or s == 1.0 or s == 0.0:
            for k in range(n):
                o[k] = _pow_scalar_exponent(a[k], s)
        else:
            for k in range(n):
                o[k] = a[k] ** s
    elif op == OP_MIN:
        for k in range(n):
            o[k] = _minimum(a[k], s)
    elif op == OP_MAX:
        for k in range(n):
            o[k] = _maximum(a[k], s)
    elif op == OP_ATAN2:
        for k in range(n):
            o[k] = math.atan2(a[k], s)
    elif op == OP_RATIO1:
        for k in range(n):
            o[k] = _ratio1(a[k], s)


@njit(**_OPTS)
def _binary_sv(op, o, s, b, n):
    if op == OP_MUL:
        for k in range(n):
            o[k] = s * b[k]
    elif op == OP_ADD:
        for k in range(n):
            o[k] = s + b[k]
    elif op == OP_SUB:
        for k in range(n):
            o[k] = s - b[k]
    elif op == OP_DIV:
        for k in range(n):
            o[k] = s / b[k]
    elif op == OP_POW:  # numpy has no fast path for a varying exponent
        for k in range(n):
            o[k] = s ** b[k]
    elif op == OP_MIN:
        for k in range(n):
            o[k] = _minimum(s, b[k])
    elif op == OP_MAX:
        for k in range(n):
            o[k] = _maximum(s, b[k])
    elif op == OP_ATAN2:
        for k in range(n):
            o[k] = math.atan2(s, b[k])
    elif op == OP_RATIO1:
        for k in range(n):
            o[k] = _ratio1(s, b[k])


@njit(**_OPTS)
def _exec(code, c0, c1, consts, W, S, T, n):
    """Run code rows [c0, c1) on the first n entries of the W rows."""
    for pc in range(c0, c1):
        op = code[pc, 0]
        mode = code[pc, 1]
        o = W[code[pc, 2]]
        a = code[pc, 3]
        b = code[pc, 4]
        if mode == M_VV:
            _binary_vv(op, o, W[a], W[b], n)
        elif mode == M_VS:
            _binary_vs(op, o, W[a], S[b], n)
        elif mode == M_V:
            _unary(op, o, W[a], n, consts, code[pc, 5], T)
        elif mode == M_SV:
            _binary_sv(op, o, S[a], W[b], n)
        elif mode == M_S:
            s = S[a]
            for k in range(n):
                o[k] = s


# ----------------------------------------------------------------------------- blocks and drivers


@njit(**_OPTS)
def _run(lv, prog, consts, sx, sy, sz, sxy, sxz, syz, out, W, S, T, i, j, nrun):
    """Run the block of level ``lv`` over ``nrun`` points along its axis at row (i, j)."""
    code, blocks, loads, stores = prog
    c0 = blocks[lv, 0]
    c1 = blocks[lv, 1]
    l0 = blocks[lv, 2]
    l1 = blocks[lv, 3]
    s0 = blocks[lv, 4]
    s1 = blocks[lv, 5]
    if c0 == c1:
        return
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
    tile = W.shape[1]
    r0 = 0
    while r0 < nrun:
        n = min(tile, nrun - r0)
        for q in range(l0, l1):
            if loads[q, 3] == 1:
                kind = loads[q, 0]
                row = loads[q, 1]
                if kind == 4:
                    src = sz[row]
                elif kind == 6:
                    src = syz[row, j]
                elif kind == 5:
                    src = sxz[row]
                elif kind == 2:
                    src = sy[row]
                else:
                    src = sx[row]
                dst = W[loads[q, 2]]
                for k in range(n):
                    dst[k] = src[r0 + k]
        _exec(code, c0, c1, consts, W, S, T, n)
        for q in range(s0, s1):
            src = W[stores[q, 0]]
            kind = stores[q, 1]
            row = stores[q, 2]
            if kind == 7:
                dst = out[i, j]
            elif kind == 6:
                dst = syz[row, j]
            elif kind == 5:
                dst = sxz[row]
            elif kind == 3:
                dst = sxy[row]
            elif kind == 4:
                dst = sz[row]
            elif kind == 2:
                dst = sy[row]
            else:
                dst = sx[row]
            for k in range(n):
                dst[r0 + k] = src[k]
        r0 += n


@njit(**_OPTS)
def _scratch(nv, ns, tile):
    return np.empty((nv, tile)), np.empty(ns), np.empty((2, tile))


@njit(**_OPTS)
def _stores(rows, ax, ay, az):
    sx = np.empty((rows[1], ax.size))
    sy = np.empty((rows[2], ay.size))
    sz = np.empty((rows[4], az.size))
    sx[0] = ax
    sy[0] = ay
    sz[0] = az
    syz = np.empty((rows[6], ay.size, az.size))
    return sx, sy, sz, syz


@njit(**_OPTS)
def _prologue(prog, consts, rows, nv, ns, tile, sx, sy, sz, syz, out):
    """The x, y and z blocks (1-D, once per grid)."""
    W, S, T = _scratch(nv, ns, tile)
    empty = np.empty((0, 1))
    _run(1, prog, consts, sx, sy, sz, empty, empty, syz, out, W, S, T, 0, 0, sx.shape[1])
    _run(2, prog, consts, sx, sy, sz, empty, empty, syz, out, W, S, T, 0, 0, sy.shape[1])
    _run(4, prog, consts, sx, sy, sz, empty, empty, syz, out, W, S, T, 0, 0, sz.shape[1])


@njit(**_OPTS)
def _yz_rows(j0, j1, prog, consts, rows, nv, ns, tile, sx, sy, sz, syz, out):
    """The yz block for rows j0 <= j < j1 (once per grid)."""
    W, S, T = _scratch(nv, ns, tile)
    empty = np.empty((0, 1))
    for j in range(j0, j1):
        _run(6, prog, consts, sx, sy, sz, empty, empty, syz, out, W, S, T, 0, j, sz.shape[1])


@njit(**_OPTS)
def _slab(i0, i1, prog, consts, rows, nv, ns, tile, sx, sy, sz, syz, out):
    """x indices i0 <= i < i1: per i the xy and xz rows, then the xyz block row by row."""
    W, S, T = _scratch(nv, ns, tile)
    ny = sy.shape[1]
    nz = sz.shape[1]
    sxy = np.empty((rows[3], ny))
    sxz = np.empty((rows[5], nz))
    for i in range(i0, i1):
        _run(3, prog, consts, sx, sy, sz, sxy, sxz, syz, out, W, S, T, i, 0, ny)
        _run(5, prog, consts, sx, sy, sz, sxy, sxz, syz, out, W, S, T, i, 0, nz)
        for j in range(ny):
            _run(7, prog, consts, sx, sy, sz, sxy, sxz, syz, out, W, S, T, i, j, nz)


@njit(**_OPTS)
def run_serial(code, blocks, loads, stores, consts, rows, nv, ns, tile, ax, ay, az, out):
    """Evaluate a program into ``out`` (Nx, Ny, Nz) on one thread."""
    prog = (code, blocks, loads, stores)
    sx, sy, sz, syz = _stores(rows, ax, ay, az)
    _prologue(prog, consts, rows, nv, ns, tile, sx, sy, sz, syz, out)
    _yz_rows(0, ay.size, prog, consts, rows, nv, ns, tile, sx, sy, sz, syz, out)
    _slab(0, ax.size, prog, consts, rows, nv, ns, tile, sx, sy, sz, syz, out)


@njit(parallel=True, **_OPTS)
def run_parallel(code, blocks, loads, stores, consts, rows, nv, ns, tile, ax, ay, az, out, chunks):
    """Evaluate a program into ``out`` with ``chunks`` slabs of x (and of y for the yz
    plane) shared among numba's threads."""
    prog = (code, blocks, loads, stores)
    sx, sy, sz, syz = _stores(rows, ax, ay, az)
    _prologue(prog, consts, rows, nv, ns, tile, sx, sy, sz, syz, out)
    ny = ay.size
    nx = ax.size
    if rows[6] > 0:
        cy = min(chunks, ny)
        for c in prange(cy):
            _yz_rows(c * ny // cy, (c + 1) * ny // cy, prog, consts, rows, nv, ns, tile, sx, sy, sz, syz, out)
    cx = min(chunks, nx)
    for c in prange(cx):
        _slab(c * nx // cx, (c + 1) * nx // cx, prog, consts, rows, nv, ns, tile, sx, sy, sz, syz, out)
