"""The resolution bound: priors the run's grid can resolve.

A factor ``H(P)`` repeats every *period* of H in units of its argument: ``2 pi`` for sin, cos,
sec, csc, ``pi`` for tan, cot. A constituent function jumps or turns a corner: a jump (saw,
staircase: every r; a pulse's edges: its shorter level apart) or a corner (triangles: every
r/2) is drawn by marching cubes as a step or a crease a cell wide, and needs as many cells
around it as a whole smooth period does, so the length counted is the spacing of those
(:func:`period_of`); an element in ``|.|``, or an asin or acos of a sine in C or F, folds H
into corners twice a period, so half a period counts. Where the argument P changes by ``|grad P|`` per unit length, that length
spans ``period / |grad P|`` in space, and ``period / (|grad P| * cell)`` cells of the run's
grid (cell = box size / (grid - 1)).

:func:`cells_per_period` measures that on a coarse grid — the argument P is a power function
(smooth, slow), so a coarse grid samples its gradient well even where ``H(P)`` is far finer — at
the 95th percentile of ``|grad P|`` over the samples considered (the shape's neighbourhood), and
takes the smallest over the factor's H arguments. The families keep it at least
``[sampler] period_cells``: the sculpture lowers its ornament's frequency, the lattice and the
infill their number of periods, the twist its twist and lobes, the free draw redraws.

A pole on a plane through the box's centre (a divisor such as ``y^2 z`` that vanishes on
``y = 0``) is a grid matter too: a grid of odd size samples that plane and an even one steps
over it, so the shape would depend on the grid's parity (the resolution check's nested grid,
of odd size, finds it: ``resolution_singular``). :func:`pole_planes` counts such planes; the
sculpture redraws an ornament that has one, the free draw redraws.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from surfgen.generator.eval.compiler import Program
from surfgen.generator.eval.evaluate import evaluate, evaluate_compiled
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.model.draw import round_significant
from surfgen.generator.model.equation13 import Factor, PowerFunction, PowerTerm, Transform
from surfgen.generator.model.order_stats import quantile

_TWO_PI = 2.0 * math.pi
_ARGUMENT_POWERS = (2, 3, 4, 6)  # P3, P4, P5, P7: the arguments of H (P6, P8 divide P5, P7)


def period_of(t: Transform) -> float:
    """The length, in units of its argument, that must span ``period_cells`` cells: a smooth
    H's period; for a constituent with jumps or corners, the spacing of those (a jump or a
    corner needs the cells a whole smooth period does: see the module docstring)."""
    name, p = t.name, t.params
    if name in ("sin", "cos", "sec", "csc"):
        return _TWO_PI
    if name in ("tan", "cot"):
        return math.pi
    if name == "rect1":  # period 2, 1 where sin(pi x) < -t: a share (pi - 2 asin t) / 2 pi
        share = (math.pi - 2.0 * math.asin(max(-1.0, min(1.0, p[0])))) / _TWO_PI
        return 2.0 * min(share, 1.0 - share)
    if name == "rect2":  # period r, a pulse of (t/r mod 1) of it
        share = (p[1] / p[0]) % 1.0
        return p[0] * min(share, 1.0 - share)
    if name == "rect3":  # period 1, a pulse of (t mod 1)
        share = p[0] % 1.0
        return min(share, 1.0 - share)
    if name in ("tri1", "tri2", "tri3"):  # two corners per period r
        return float(p[0]) / 2.0
    if name in ("asin", "acos", "atan", "acot"):  # not periodic: no bound of its own
        return math.inf
    return float(p[0])  # saw1, stair1, saw2, stair2: one jump per base r


def cells_per_period(
    factor: Factor, box: Box, n: int, cell: float, where: np.ndarray | None = None
) -> float:
    """How many cells of size ``cell`` the factor's finest period spans (``inf`` without an
    H; 0 where an argument is non-finite everywhere considered), its arguments sampled on an
    ``n``-per-axis grid of ``box``; ``where`` (an ``n^3`` mask) restricts the samples."""
    # Deferred on purpose (as the carving's kernels): reading the registry loads no numba
    from surfgen.generator.model.slope import gradient_norm

    base = period_of(factor.h)
    if not math.isfinite(base):
        return math.inf
    grid = Grid(box, (n,) * 3)
    steps = tuple((hi - lo) / (n - 1) for lo, hi in zip(box.lo, box.hi, strict=True))
    worst = math.inf
    for element, arg in factor.h_arguments():
        period = base / 2 if _folded(factor, element) else base
        slope = gradient_norm(evaluate(arg, grid, threads=1).values, steps)
        ok = np.isfinite(slope)
        if where is not None:
            ok &= where
        if not ok.any():
            return 0.0
        fastest = float(quantile(slope[ok], 0.95))
        if fastest > 0:
            worst = min(worst, period / (fastest * cell))
    return worst


def pole_planes(program: Program, box: Box, cell: float, n: int = 24) -> int:
    """How many of the three planes through the centre of ``box`` hold a pole of the compiled
    formula ``program`` (:func:`~surfgen.generator.eval.compiler.compile_tree`): on more than a
    line's worth (``n``) of the plane's ``n x n`` samples it is not finite, where it is finite half a ``cell`` to either side (where the
    nearest samples of an even grid of that cell lie). A pole on a line or at a point, which
    the resolution check tolerates, stays within ``n``: ``n`` is even, so the plane's samples
    miss the other planes through the centre."""
    planes = 0
    for axis in range(3):
        lo, hi, shape = list(box.lo), list(box.hi), [n] * 3
        centre = (lo[axis] + hi[axis]) / 2
        # 5 samples across the plane, a half cell apart: the middle three are the two nearest
        # samples of the even grid and the plane between them
        lo[axis], hi[axis], shape[axis] = centre - cell, centre + cell, 5
        grid = Grid(Box(tuple(lo), tuple(hi)), tuple(shape))  # type: ignore[arg-type]
        values = evaluate_compiled(program, grid, threads=1).values
        finite = np.isfinite(np.moveaxis(values, axis, 0))
        planes += int(np.count_nonzero(finite[1] & ~finite[2] & finite[3])) > n
    return planes


_ELEMENT = {"A": 0, "B": 1, "C": 2, "D": 3, "E": 4, "F": 5}


def _folded(factor: Factor, element: str) -> bool:
    """Whether the element folds H into corners twice a period: ``|H(.)|`` (a crease at each
    zero), or G = asin, acos of a sine or cosine in C or F (a triangle wave, a corner at each
    extreme)."""
    if factor.absolute[_ELEMENT[element]]:
        return True
    smooth = factor.h.name in ("sin", "cos")
    return element in "CF" and smooth and factor.g.name in ("asin", "acos")


def scale_arguments(factor: Factor, alpha: float) -> Factor:
    """The factor with the coefficients of H's arguments (P3, P4, P5, P7) times ``alpha``
    (4 significant digits): each period of H then spans ``1/alpha^lambda`` times the space."""
    powers = tuple(
        PowerFunction(
            tuple(PowerTerm(round_significant(t.a * alpha, 4), t.b, t.c, t.d) for t in p.terms),
            p.absolute,
        )
        if k in _ARGUMENT_POWERS
        else p
        for k, p in enumerate(factor.powers)
    )
    return replace(factor, powers=powers)


def fit_factor(
    factor: Factor,
    box: Box,
    n: int,
    cell: float,
    period_cells: float,
    where: np.ndarray | None = None,
    rounds: int = 3,
) -> tuple[Factor, float, float]:
    """The factor slowed down (its arguments scaled) until its finest period spans at least
    ``period_cells`` cells: ``(factor, total scale, cells per period)``. An exponent lambda on
    an argument makes the scale act as its power, so it is refined for ``rounds`` rounds; an
    argument with a pole (a divisor vanishing) cannot be slowed enough and stays below."""
    cells = cells_per_period(factor, box, n, cell, where)
    total = 1.0
    for _ in range(rounds):
        if period_cells <= 0 or cells >= period_cells or not cells > 0:
            break
        alpha = round_significant(cells / period_cells * 0.98, 3)
        factor = scale_arguments(factor, alpha)
        total *= alpha
        cells = cells_per_period(factor, box, n, cell, where)
    return factor, total, cells


def fit_terms(
    terms: list[tuple[Factor, ...]],
    box: Box,
    cell: float,
    period_cells: float,
    n: int = 8,
    where: np.ndarray | None = None,
) -> tuple[list[tuple[Factor, ...]], float, float]:
    """Sum terms slowed down together (every factor with an H has its arguments scaled by one
    factor, so a pattern keeps its proportions) until their finest period spans at least
    ``period_cells`` cells: ``(terms, scale, cells per period)``. Exact in one round for linear
    arguments (lattices); ``n`` samples per axis of ``box`` (``where``: a mask of them)."""

    def finest(ts: list[tuple[Factor, ...]]) -> float:
        cells = [cells_per_period(f, box, n, cell, where) for t in ts for f in t if any(f.mus)]
        return min(cells, default=math.inf)

    cells = finest(terms)
    total = 1.0
    for _ in range(3):
        if period_cells <= 0 or cells >= period_cells or not cells > 0:
            break
        alpha = round_significant(cells / period_cells * 0.98, 3)
        terms = [tuple(scale_arguments(f, alpha) if any(f.mus) else f for f in t) for t in terms]
        total *= alpha
        cells = finest(terms)
    return terms, total, cells
