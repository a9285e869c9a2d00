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
from collections.abc import Callable, Mapping

import numpy as np

from surfgen.generator.errors import GridError
from surfgen.generator.eval import interpreter
from surfgen.generator.eval.compiler import Program, compile_tree
from surfgen.generator.eval.interval_kernels import run_boxes
from surfgen.generator.eval.interval_plan import plan_kernel, range_reduce_into, range_tables
from surfgen.generator.eval.interval_rules import EMPTY_HI, EMPTY_LO
from surfgen.generator.eval.opcodes import LEVEL_ORDER
from surfgen.generator.eval.tape import COMPILED_CACHE, points_program, run_at_once
from surfgen.generator.formula.expr import Expr

BOXES_TILE = 256  # boxes per register row
# Boxes planned and run at a time: the stores hold up to 7 intervals per box and store row
# (about 40 MB for 16384 boxes of a program with 20 store rows and nothing shared)
BOXES_CHUNK = 16384
#: Boxes a thread takes at least (:func:`program_bounds`): about 0.1 µs a box on the
#: sculptures' last levels, a thread's wake-up up to a millisecond.
THREAD_BOXES = 8192
_LEVELS = np.array(LEVEL_ORDER, dtype=np.int64)
_AXIS_LEVELS = np.array([lv for lv in LEVEL_ORDER if lv in (1, 2, 4)], dtype=np.int64)
_MIXED_LEVELS = np.array([lv for lv in LEVEL_ORDER if lv not in (1, 2, 4)], dtype=np.int64)


def plan_levels(
    blo: np.ndarray, bhi: np.ndarray, share: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[np.ndarray]]:
    """The items of each level for :func:`~.interval_kernels.run_boxes`:
    ``(counts, offsets, item_map, firsts)``.

    With ``share``, a level of some axes gets one item per distinct combination of the boxes'
    ranges on those axes (boxes on a grid share them: the x level of a 32^3 grid of boxes runs
    32 times, not 32768), told apart by their bits; level xyz keeps one item per box. Without,
    every level has one item per box (the check of the sharing). ``firsts[lv]``: a box of each
    item of level lv. Distinct values are found by hashing (:func:`.point_driver.dedupe`), in
    one compiled pass (:func:`.interval_plan.plan_kernel`)."""
    blo = np.ascontiguousarray(blo, dtype=np.float64)
    bhi = np.ascontiguousarray(bhi, dtype=np.float64)
    counts, offsets, item_map, first_rows = plan_kernel(blo, bhi, bool(share))
    firsts = [np.arange(blo.shape[0], dtype=np.int64)]
    firsts += [first_rows[lv, : counts[lv]] for lv in range(1, 8)]
    return counts, offsets, item_map, firsts


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
    program: Program,
    lo: np.ndarray,
    hi: np.ndarray,
    share: bool = True,
    samples: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    axis_points: dict | None = None,
    threads: int = 1,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bounds of F over K closed boxes ``[lo[k], hi[k]]`` (float64 ``(K, 3)``, world coordinates).

    Returns float64 ``flo``, ``fhi`` ``(K,)`` and bool ``finite`` ``(K,)``: for every point p of
    box k, F(p) as the fast evaluator computes it is NaN or lies in ``[flo[k], fhi[k]]`` (±inf
    allowed as values and bounds), and ``finite[k]`` True guarantees F(p) is finite (not NaN,
    not ±inf) everywhere in box k. A box where F is NaN everywhere gets ``flo = +inf``,
    ``fhi = -inf``. Raises :class:`GridError` for malformed boxes, :class:`TypeError` for a
    ``program`` that is not a :class:`Program`.

    A value of some axes is bounded once per distinct combination of the boxes' ranges on
    those axes (:func:`plan_levels`); ``share=False`` bounds every level once per box (the
    same bounds, slower: the check of the sharing).

    ``samples``, the grid's coordinates along x, y and z (sorted), bounds F over the **grid
    points** of each box instead (:func:`grid_point_bounds`): a value of one axis (``tan(m x)``,
    ``|y|^0.3``) is bounded by its values at that axis's coordinates in the box's range, each
    bounded over the point itself (a box of zero width), so a pole between two samples costs
    nothing; the other values are bounded from those as before. Every grid point's F is then
    NaN or within the bounds; points between the samples are not covered. ``axis_points``: a
    dict, per program, of those one-axis bounds, kept for calls with the same ``samples``
    (:func:`grid_point_bounds` keeps one: a sparse classification bounds every level of
    blocks with the same program and axes; sculpture-1 at 512^3: four times 0.85 ms).

    ``threads``: the boxes in that many runs at once, where each has :data:`THREAD_BOXES` or
    more (each box's bounds are its own: the same bounds however many).
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
        prog = _boxes_program(program)
        depth = max(1, int(np.max(program.rows)))
        points = None
        if samples is not None:
            kept = {} if axis_points is None else axis_points
            if program not in kept:
                kept[program] = _axis_points(prog, depth, samples)
            points = kept[program]
        runs = max(1, min(int(threads), K // THREAD_BOXES))
        chunks = runs * -(-K // (runs * BOXES_CHUNK))  # equal chunks, as many on every run
        cuts = [K * c // chunks for c in range(chunks + 1)]

        def run(first: int) -> None:
            for c in range(first, chunks, runs):
                view = slice(cuts[c], cuts[c + 1])
                _run_chunk(prog, depth, blo[view], bhi[view], share, flo[view], fhi[view],
                           nan[view], points)  # fmt: skip

        run_at_once([lambda r=r: run(r) for r in range(runs)])
    return finish(flo, fhi, nan)


def grid_point_bounds(
    samples: tuple[np.ndarray, np.ndarray, np.ndarray],
    threads: int = 1,
) -> Callable[[Program, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``program_bounds`` over the grid points of boxes of a grid with these coordinates along
    x, y and z (sorted, copied when it is made): what a sparse evaluator of that grid needs
    (:func:`program_bounds`), each program's one-axis bounds made once; on ``threads``."""
    axes = tuple(np.array(a, dtype=np.float64) for a in samples)
    made: dict = {}

    def bounds(program: Program, lo: np.ndarray, hi: np.ndarray):
        return program_bounds(  # type: ignore[arg-type]
            program, lo, hi, samples=axes, axis_points=made, threads=threads
        )

    return bounds


def _run_chunk(prog, depth, blo, bhi, share, flo, fhi, nan, points=None) -> None:
    """Bounds of the boxes of one chunk into the views ``flo``, ``fhi``, ``nan``; with
    ``points`` (:func:`_axis_points`), the one-axis levels over the samples in the ranges."""
    counts, offsets, item_map, firsts = plan_levels(blo, bhi, share)
    SL = np.empty((depth, item_map.shape[1]))
    SH = np.empty((depth, item_map.shape[1]))
    SN = np.zeros((depth, item_map.shape[1]), dtype=np.uint8)
    for a, lv in enumerate((1, 2, 4)):  # row 0 of the x, y, z levels: the axis ranges
        cols = slice(offsets[lv], offsets[lv] + counts[lv])
        SL[0, cols] = blo[firsts[lv], a]
        SH[0, cols] = bhi[firsts[lv], a]
    levels = _LEVELS
    if points is not None:
        for a, lv in enumerate((1, 2, 4)):
            axis, lows, highs, nans = points[a]
            first = np.searchsorted(axis, blo[firsts[lv], a], side="left")
            last = np.searchsorted(axis, bhi[firsts[lv], a], side="right")
            c0 = int(offsets[lv])
            range_reduce_into(lows, first, last, False, EMPTY_LO, SL, c0)
            range_reduce_into(highs, first, last, True, EMPTY_HI, SH, c0)
            range_reduce_into(nans, first, last, True, 0, SN, c0)
        levels = _MIXED_LEVELS
    run_boxes(prog, BOXES_TILE, levels, counts, offsets, item_map, SL, SH, SN, flo, fhi, nan)


def _axis_points(prog, depth, samples) -> list[tuple[np.ndarray, ...]]:
    """Per axis: its coordinates and the one-axis level's stores at each of them, bounded over
    the point (a box of zero width): ``(axis, L, H, N)``, stores ``(depth, n)``."""
    n = [len(a) for a in samples]
    counts = np.array([0, n[0], n[1], 0, n[2], 0, 0, 0], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    total = int(counts.sum())
    item_map = np.zeros((8, total), dtype=np.int64)
    SL = np.empty((depth, total))
    SH = np.empty((depth, total))
    SN = np.zeros((depth, total), dtype=np.uint8)
    for a, lv in enumerate((1, 2, 4)):
        cols = slice(offsets[lv], offsets[lv] + counts[lv])
        item_map[lv, cols] = np.arange(offsets[lv], offsets[lv] + counts[lv])
        SL[0, cols] = samples[a]
        SH[0, cols] = samples[a]
    out_lo, out_hi = np.empty(total), np.empty(total)  # unused: the output is level xyz's
    out_nan = np.zeros(total, dtype=np.uint8)
    run_boxes(
        prog,
        BOXES_TILE,
        _AXIS_LEVELS,
        counts,
        offsets,
        item_map,
        SL,
        SH,
        SN,
        out_lo,
        out_hi,
        out_nan,
    )
    out = []
    for a, lv in enumerate((1, 2, 4)):
        cols = slice(offsets[lv], offsets[lv] + counts[lv])
        out.append(
            (
                samples[a],
                range_tables(np.ascontiguousarray(SL[:, cols]), False),
                range_tables(np.ascontiguousarray(SH[:, cols]), True),
                range_tables(np.ascontiguousarray(SN[:, cols]), True),
            )
        )
    return out


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


__all__ = ["BOXES_TILE", "plan_levels", "program_bounds", "grid_point_bounds", "tree_bounds"]
