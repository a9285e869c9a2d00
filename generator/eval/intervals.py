"""Interval arithmetic on the tape: bounds of a formula over boxes (issue 41).

    flo, fhi, finite = program_bounds(program, lo, hi)   # K boxes [lo[k], hi[k]], (K, 3) each

For every point p of box k, the value the fast evaluator computes, F(p), is NaN or lies in
``[flo[k], fhi[k]]`` (``±inf`` allowed), and ``finite[k]`` guarantees that F is finite (not NaN,
not ±inf) everywhere in the box. A sparse evaluator skips a box as all outside when
``flo > level`` and as all inside when ``finite and fhi < level``.

The interval interpreter runs the program's blocks like the points interpreter
(:func:`surfgen.generator.eval.point_driver.run_points`, with the program rewritten by
:func:`surfgen.generator.eval.tape.points_program`): each level's store holds one interval per
box, so a value of level x is bounded over the box's x range only. The rules of every opcode:
:mod:`surfgen.generator.eval.interval_kernels` and :mod:`surfgen.generator.eval.interval_rules`;
the plain-numpy reference they are tested against: :mod:`surfgen.generator.eval.intervals_reference`.
docs/reference/intervals.md explains how the rules are built.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

import numpy as np
from numba import njit

from surfgen.generator.errors import GridError
from surfgen.generator.eval import interpreter
from surfgen.generator.eval.compiler import Program, compile_tree
from surfgen.generator.eval.interval_kernels import run_code_iv
from surfgen.generator.eval.interval_rules import EMPTY_HI, EMPTY_LO
from surfgen.generator.eval.opcodes import LEVEL_ORDER
from surfgen.generator.eval.tape import COMPILED_CACHE, points_program
from surfgen.generator.formula.expr import Expr
from surfgen.generator.jit.options import KERNEL

BOXES_TILE = 256  # boxes per register row
_LEVELS = np.array(LEVEL_ORDER, dtype=np.int64)


@njit(**KERNEL)
def run_boxes(prog, tile, levels, blo, bhi, out_lo, out_hi, out_nan):
    """Bounds of a program (``points_program`` form) over the boxes ``[blo[k], bhi[k]]``."""
    code, blocks, loads, stores, consts, rows = prog[0], prog[1], prog[2], prog[3], prog[4], prog[5]
    n_rows = prog[6]
    depth = 1
    for lv in range(8):
        depth = max(depth, rows[lv])
    SL = np.empty((8, depth, tile))
    SH = np.empty((8, depth, tile))
    SN = np.zeros((8, depth, tile), dtype=np.uint8)
    L = np.empty((n_rows, tile))
    H = np.empty((n_rows, tile))
    N = np.zeros((n_rows, tile), dtype=np.uint8)
    T = np.empty((8, tile))
    total = blo.shape[0]
    for p0 in range(0, total, tile):
        n = min(tile, total - p0)
        for axis in range(3):
            kind = 1 << axis
            for k in range(n):
                SL[kind, 0, k] = blo[p0 + k, axis]
                SH[kind, 0, k] = bhi[p0 + k, axis]
                SN[kind, 0, k] = 0
        for lv in levels:
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
                    vlo, vhi, vn = (v, v, 0) if v == v else (EMPTY_LO, EMPTY_HI, 1)
                    for k in range(n):
                        L[slot, k] = vlo
                        H[slot, k] = vhi
                        N[slot, k] = vn
                else:
                    for k in range(n):
                        L[slot, k] = SL[kind, row, k]
                        H[slot, k] = SH[kind, row, k]
                        N[slot, k] = SN[kind, row, k]
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
                        SL[kind, row, k] = L[slot, k]
                        SH[kind, row, k] = H[slot, k]
                        SN[kind, row, k] = N[slot, k]


def check_boxes(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``lo`` and ``hi`` as C-contiguous float64 ``(K, 3)`` arrays; :class:`GridError` when the
    shapes differ or are not ``(K, 3)``, a bound is NaN, or ``lo > hi`` somewhere."""
    blo = np.ascontiguousarray(lo, dtype=np.float64)
    bhi = np.ascontiguousarray(hi, dtype=np.float64)
    if blo.ndim != 2 or blo.shape[1:] != (3,) or blo.shape != bhi.shape:
        raise GridError(
            f"boxes: lo and hi must both have shape (K, 3), got {blo.shape} and {bhi.shape}"
        )
    if np.isnan(blo).any() or np.isnan(bhi).any():
        raise GridError("boxes: a bound is NaN (allowed: numbers and ±inf)")
    if (blo > bhi).any():
        k = int(np.argmax((blo > bhi).any(axis=1)))
        raise GridError(f"boxes: box {k} has lo > hi ({blo[k].tolist()} > {bhi[k].tolist()})")
    return blo, bhi


def finish(flo: np.ndarray, fhi: np.ndarray, nan: np.ndarray) -> tuple[np.ndarray, ...]:
    """``(flo, fhi, finite)`` of the API from the bounds and the may-be-NaN flags."""
    finite = (nan == 0) & (flo > -np.inf) & (fhi < np.inf) & (flo <= fhi)
    return flo, fhi, finite


@functools.lru_cache(maxsize=COMPILED_CACHE)
def _boxes_program(program: Program) -> tuple:
    return points_program(program)


def program_bounds(
    program: Program, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bounds of F over K closed boxes ``[lo[k], hi[k]]`` (float64 ``(K, 3)``, world coordinates).

    Returns float64 ``flo``, ``fhi`` ``(K,)`` and bool ``finite`` ``(K,)``: for every point p of
    box k, F(p) as the fast evaluator computes it is NaN or lies in ``[flo[k], fhi[k]]`` (±inf
    allowed as values and bounds), and ``finite[k]`` True guarantees F(p) is finite (not NaN,
    not ±inf) everywhere in box k. A box where F is NaN everywhere gets ``flo = +inf``,
    ``fhi = -inf``. Raises :class:`GridError` for malformed boxes, :class:`TypeError` for a
    ``program`` that is not a :class:`Program`.
    """
    if not isinstance(program, Program):
        raise TypeError(f"expected a Program, got {type(program).__name__}")
    blo, bhi = check_boxes(lo, hi)
    K = blo.shape[0]
    flo = np.empty(K)
    fhi = np.empty(K)
    nan = np.zeros(K, dtype=np.uint8)
    if K:
        interpreter.load_interpreter()  # the elementary rows the rules call
        run_boxes(_boxes_program(program), BOXES_TILE, _LEVELS, blo, bhi, flo, fhi, nan)
    return finish(flo, fhi, nan)


@functools.lru_cache(maxsize=COMPILED_CACHE)
def _compiled(tree: Expr, params: tuple[tuple[str, float], ...]) -> Program:
    return compile_tree(tree, dict(params))


def tree_bounds(
    tree: Expr, params: Mapping[str, float] | None, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`program_bounds` of ``tree`` with ``params`` (compiled programs of recent trees
    are kept). Raises :class:`~surfgen.generator.errors.FormulaError` as
    :func:`~surfgen.generator.eval.compiler.compile_tree` does."""
    return program_bounds(_compiled(tree, tuple(sorted((params or {}).items()))), lo, hi)


__all__ = ["BOXES_TILE", "program_bounds", "run_boxes", "tree_bounds"]
