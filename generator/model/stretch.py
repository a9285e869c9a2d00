"""Proportions: every family's shape stretched along the axes, its symmetry kept.

A family draws its shape in proportions of its own (a ball of a sculpture, a column of a twist);
:func:`stretch_draw` then scales it by ``(sx, sy, sz)``: ``F'(x, y, z) = F(x / sx, y / sy, z / sz)``
on the box scaled alike. Equation (13) holds it exactly: every variable of an eq. (13) instance is
inside a power function ``a x^b y^c z^d`` (eq. 8), and ``a (x/s)^b = (a s^-b) x^b`` for ``s > 0``
(for ``|x|`` too), so the stretched shape is the same equation with new coefficients
(:func:`stretch_equation`). The grid keeps its points per axis, so the field on the stretched box
is the field of the family's shape at the same samples: what the grid resolved it resolves, and
the filters see the same cells.

Which axes stretch (:func:`draw_scale`, a stream of its own, so the family's draw is untouched):
with probability ``aspect_prob`` a shape is stretched, by factors log-uniform in ``aspect``.
A shape that is mapped onto itself by swapping two axes (``x <-> y``) is stretched along the third
only, which keeps that symmetry; one with only a three-fold symmetry (``x -> y -> z``) is left as
it is (any stretch breaks it); one with no symmetry of its axes is stretched along each axis on
its own. The symmetries are those of the shape's inside on the coarse grid that chooses d
(:func:`axis_symmetries`).
"""

from __future__ import annotations

import decimal
import functools
import itertools
import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from surfgen.generator.eval.grid import Box
from surfgen.generator.formula.expr import Expr, scale_variables
from surfgen.generator.model.draw import Draw, DrawSettings, coarse_values, round_significant
from surfgen.generator.model.equation13 import Equation13, PowerFunction, PowerTerm

DIGITS = 12  # significant digits of a stretched coefficient (a bent twist cancels to 1e-4)
BOX_DIGITS = 6  # significant digits of the stretched box's bounds
MISMATCH = 0.05  # share of samples whose side a symmetry may change (axis_symmetries)
SWAPS = ((1, 0, 2), (2, 1, 0), (0, 2, 1))  # x <-> y, x <-> z, y <-> z: axis 2, 1, 0 fixed
CYCLES = ((1, 2, 0), (2, 0, 1))
_CONTEXT = decimal.Context(prec=40)


def stretch_rng(seed: int, index: int) -> np.random.Generator:
    """The stream the proportions of shape ``index`` are drawn from (not the family's own)."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index, 2)))


def stretch_draw(
    seed: int, index: int, cfg: DrawSettings, draw: Draw, limit: float | None = None
) -> Draw:
    """``draw`` stretched by :func:`draw_scale` (the draw itself when it keeps its proportions);
    the factors are recorded in its structure (``aspect``). ``limit``: the family's
    ``aspect_limit`` (:func:`limit_ratio`)."""
    scale = draw_scale(stretch_rng(seed, index), cfg, draw)
    if limit is not None:
        scale = limit_ratio(scale, limit)
    if scale == (1.0, 1.0, 1.0):
        return draw
    structure = {**(draw.structure or {}), "aspect": list(scale)}
    return replace(
        draw,
        equation=stretch_equation(draw.equation, scale),
        box=stretch_box(draw.box, scale),
        structure=structure,
        envelope=None if draw.envelope is None else stretch_tree(draw.envelope, scale),
    )


def draw_scale(
    rng: np.random.Generator, cfg: DrawSettings, draw: Draw
) -> tuple[float, float, float]:
    """The factors ``(sx, sy, sz)`` of the draw (module doc), each to 2 decimals."""
    if not rng.random() < cfg.aspect_prob:
        return (1.0, 1.0, 1.0)
    low, high = math.log(cfg.aspect[0]), math.log(cfg.aspect[1])
    factors = [round(math.exp(v), 2) for v in rng.uniform(low, high, 3)]
    which = int(rng.integers(0, 3))  # the swap kept, among those the field has
    swaps, cyclic = axis_symmetries(draw, cfg)
    if swaps:
        axis = swaps[which % len(swaps)]
        return tuple(factors[0] if k == axis else 1.0 for k in range(3))  # type: ignore[return-value]
    if cyclic:
        return (1.0, 1.0, 1.0)
    return tuple(factors)  # type: ignore[return-value]


def limit_ratio(scale: Sequence[float], limit: float) -> tuple[float, float, float]:
    """``scale`` with the ratio of its largest factor to its smallest brought down to
    ``limit``: the logarithms drawn towards their middle, each factor to 2 decimals (``scale``
    itself when within ``limit``). Equal factors stay equal, so a swap of axes the stretch
    kept is kept."""
    logs = [math.log(s) for s in scale]
    low, high = min(logs), max(logs)
    if high - low <= math.log(limit):
        return tuple(scale)  # type: ignore[return-value]
    middle, shrink = (high + low) / 2, math.log(limit) / (high - low)
    x, y, z = (round(math.exp(middle + (v - middle) * shrink), 2) for v in logs)
    return x, y, z


def axis_symmetries(
    draw: Draw, cfg: DrawSettings, tolerance: float = MISMATCH
) -> tuple[tuple[int, ...], bool]:
    """The axes fixed by the swaps of two axes that map the shape and its box onto themselves
    (2 for ``x <-> y``, ...; with any signs: a quarter turn about z swaps x and y too), and
    whether a three-fold turn ``x -> y -> z`` (with any signs) does.

    Tested on the grid of ``d_grid`` points per axis that chooses d (:func:`coarse_values`):
    a signed permutation that maps the box onto itself maps its samples onto one another, so
    the shape is symmetric when the image of its inside (``F < d``) is its inside, but for
    ``tolerance`` of the smaller of inside and outside (the surface of a shape symmetric to the
    eye passes between the samples a little differently)."""
    values, level = coarse_values(draw, cfg, threads=1)  # 20^3 samples: threads never pay
    if level is None:
        return (), False
    inside = values < level  # NaN: outside
    allowed = tolerance * max(1, min(int(inside.sum()), inside.size - int(inside.sum())))
    lo, hi = tuple(map(float, draw.box.lo)), tuple(map(float, draw.box.hi))

    def holds(perm: tuple[int, ...], signs: tuple[int, ...]) -> bool:
        # the box's image (the box's own floats, compared exactly): onto itself, or no symmetry
        for k, (p, s) in enumerate(zip(perm, signs, strict=True)):
            image = (-hi[p], -lo[p]) if s < 0 else (lo[p], hi[p])
            if image != (lo[k], hi[k]):
                return False
        # the image of sample (i, j, k) under x' = s x[perm]: the array's axes permuted, the
        # negated ones reversed
        image = np.transpose(inside, perm)
        image = np.flip(image, axis=tuple(k for k, s in enumerate(signs) if s < 0))
        return int(np.count_nonzero(image != inside)) <= allowed

    def any_signs(perm: tuple[int, ...]) -> bool:
        return any(holds(perm, signs) for signs in itertools.product((1, -1), repeat=3))

    swaps = tuple(sorted(2 - k for k, perm in enumerate(SWAPS) if any_signs(perm)))
    return swaps, any(any_signs(perm) for perm in CYCLES)


def stretch_equation(equation: Equation13, scale: Sequence[float]) -> Equation13:
    """``equation`` with every power function's term ``a x^b y^c z^d`` turned into
    ``a sx^-b sy^-c sz^-d x^b y^c z^d``: the field ``F(x / sx, y / sy, z / sz)`` (``d`` kept)."""
    memo: dict[int, PowerFunction] = {}

    def power(p: PowerFunction) -> PowerFunction:
        out = memo.get(id(p))
        if out is None:
            terms = tuple(PowerTerm(_coefficient(t, scale), t.b, t.c, t.d) for t in p.terms)
            out = memo[id(p)] = PowerFunction(terms, p.absolute)
        return out

    terms = tuple(
        tuple(replace(f, powers=tuple(power(p) for p in f.powers)) for f in product)
        for product in equation.terms
    )
    return Equation13(terms, equation.d)


def _coefficient(term: PowerTerm, scale: Sequence[float]) -> float:
    """``a sx^-b sy^-c sz^-d`` to :data:`DIGITS` significant digits, in decimal arithmetic (the
    same digits on every machine, whatever its libm); ``a`` itself when every exponent is 0."""
    if term.b == term.c == term.d == 0:
        return term.a
    value = decimal.Decimal(term.a)
    for s, e in zip(scale, (term.b, term.c, term.d), strict=True):
        if e != 0 and s != 1:
            value = _CONTEXT.multiply(value, _inverse_power(s, e))
    return round_significant(float(value), DIGITS)


@functools.lru_cache(maxsize=1024, typed=True)  # 2 and 2.0: not the same repr
def _inverse_power(s: float, e: float) -> decimal.Decimal:
    """``s^-e`` in :data:`_CONTEXT`'s decimal arithmetic (a draw's three factors meet the same
    few exponents in every term: computed once each)."""
    return _CONTEXT.power(decimal.Decimal(repr(s)), decimal.Decimal(repr(-e)))


def stretch_box(box: Box, scale: Sequence[float]) -> Box:
    """The box scaled by ``scale`` about the origin, bounds to :data:`BOX_DIGITS` digits."""
    lo = tuple(round_significant(v * s, BOX_DIGITS) for v, s in zip(box.lo, scale, strict=True))
    hi = tuple(round_significant(v * s, BOX_DIGITS) for v, s in zip(box.hi, scale, strict=True))
    return Box(lo, hi)  # type: ignore[arg-type]


def stretch_tree(tree: Expr, scale: Sequence[float]) -> Expr:
    """The formula ``tree`` of the stretched shape: each variable divided by its factor."""
    return scale_variables(tree, {n: 1.0 / s for n, s in zip("xyz", scale, strict=True) if s != 1})
