"""Proportions: a stretched draw is the family's shape scaled, on the same samples, its axis
swaps kept."""

from __future__ import annotations

import decimal
import re
from dataclasses import replace

import numpy as np
import pytest

from surfgen.generator.errors import SpecError
from surfgen.generator.eval.evaluate import evaluate, points_evaluator
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.expr import var
from surfgen.generator.model.draw import Draw, only_a, round_significant
from surfgen.generator.model.equation13 import Equation13, PowerFunction, PowerTerm
from surfgen.generator.model.sampler import SamplerConfig, draw_equation
from surfgen.generator.model.stretch import (
    DIGITS,
    _coefficient,
    axis_symmetries,
    draw_scale,
    limit_ratio,
    stretch_box,
    stretch_draw,
    stretch_equation,
    stretch_tree,
)

FAMILIES = ("sculpture", "lattice", "infill", "assembly", "twist", "free")


def polynomial_draw(*terms: tuple[float, float, float, float], absolute: bool = False) -> Draw:
    """The draw of one power function (a body ``P < d``) on the box [-1.5, 1.5]^3."""
    p = PowerFunction(tuple(PowerTerm(*t) for t in terms), absolute)
    return Draw(Equation13(((only_a(p),),)), Box.cube(1.5), d_quantile=0.3)


# x^2 + y^2 + 2 z^4: x <-> y (z fixed); the same with x^2 y + y^2 z + z^2 x: only x -> y -> z;
# x^2 + 2 y^2 + 3 z^2 + x: no symmetry of its axes.
SWAP_Z = ((1, 2, 0, 0), (1, 0, 2, 0), (2, 0, 0, 4))
CYCLIC = ((1, 2, 0, 0), (1, 0, 2, 0), (1, 0, 0, 2), (1, 2, 1, 0), (1, 0, 2, 1), (1, 1, 0, 2))
NONE = ((1, 2, 0, 0), (2, 0, 2, 0), (3, 0, 0, 2), (1, 1, 0, 0))


def test_a_stretched_equation_is_the_field_at_the_scaled_point() -> None:
    """F'(x, y, z) = F(x / sx, y / sy, z / sz), real exponents and |x| included."""
    terms = ((1.5, 2, 0, 0), (-0.7, 0.37, 1.5, 0), (0.25, 1, 1, 3), (2.0, 0, 0, 0))
    rng = np.random.default_rng(3)
    pts = rng.uniform(-2, 2, (200, 3))
    scale = (0.5, 1.87, 1.0)
    for absolute in (True, False):
        body = polynomial_draw(*terms, absolute=absolute).equation
        stretched = stretch_equation(body, scale)
        want = points_evaluator(body.body())(*(pts / scale).T)
        got = points_evaluator(stretched.body())(*pts.T)
        same_nan = np.isnan(want) & np.isnan(got)
        np.testing.assert_array_equal(np.isnan(want), np.isnan(got))
        np.testing.assert_allclose(got[~same_nan], want[~same_nan], rtol=1e-10, atol=1e-12)
    # the constant term is kept as it is, the others get s^-exponent (decimal arithmetic)
    p = stretched.terms[0][0].powers[0]
    assert p.terms[3].a == 2.0 and p.terms[0].a == 6.0
    assert p.terms[1].a == float(f"{-0.7 * 0.5**-0.37 * 1.87**-1.5:.11e}")


@pytest.mark.parametrize("name", FAMILIES)
def test_a_stretched_draw_has_the_family_s_field_at_the_same_samples(name: str) -> None:
    """On its grid the stretched shape has the unstretched one's values (to the rounding of
    12-digit coefficients): what the grid resolved it still resolves, cell for cell."""
    base = replace(SamplerConfig(), family=name, aspect_prob=0.0)
    cfg = replace(base, aspect_prob=1.0)
    checked = 0
    for index in range(12):
        own, stretched = draw_equation(11, index, base), draw_equation(11, index, cfg)
        scale = (stretched.structure or {}).get("aspect")
        if scale is None:  # a three-fold symmetry: kept as it is
            assert stretched == own
            continue
        assert stretched.box == stretch_box(own.box, scale)
        assert stretched.d_quantile == own.d_quantile and stretched.d == own.d
        grid = (16,) * 3  # even: no samples on the planes x, y, z = 0 (poles of 1/|x|^p)
        # the unstretched box's samples are the stretched box's divided by the factors
        # (the stretched box is rounded to 6 digits: take its samples back)
        back = Box(
            tuple(a / s for a, s in zip(stretched.box.lo, scale, strict=True)),
            tuple(b / s for b, s in zip(stretched.box.hi, scale, strict=True)),
        )
        want = evaluate(own.equation.body(), Grid(back, grid)).values
        got = evaluate(stretched.equation.body(), Grid(stretched.box, grid)).values
        # Beyond 1e12 is a pole. The same samples are poles (NaN stays NaN) but in free
        # draws, whose constituents' exact zeros (a saw at a whole period, 1/0 = inf) fall on
        # other samples once the coefficients are not 2-decimal numbers (1e-17, 1/1e-17 = 1e17
        # of either sign); elsewhere the values agree.
        pole_want, pole_got = ~(np.abs(want) < 1e12), ~(np.abs(got) < 1e12)
        if name != "free":
            np.testing.assert_array_equal(pole_want, pole_got)
            np.testing.assert_array_equal(np.isnan(want), np.isnan(got))
        finite = ~pole_want & ~pole_got
        spread = float(np.ptp(want[finite])) if finite.any() else 1.0
        # a bent twist's expanded powers cancel: 12 digits leave errors of 1e-8 of the range
        np.testing.assert_allclose(got[finite], want[finite], rtol=1e-6, atol=1e-7 * spread)
        if own.envelope is not None:
            env = evaluate(own.envelope, Grid(back, grid)).values
            np.testing.assert_allclose(
                evaluate(stretched.envelope, Grid(stretched.box, grid)).values, env, rtol=1e-9
            )
        checked += 1
    assert checked >= 6


def test_the_stretch_keeps_a_swap_of_two_axes() -> None:
    """A shape mapped onto itself by x <-> y is stretched along z only, so it keeps that swap;
    one with only x -> y -> z is not stretched; one without either, along each axis."""
    cfg = replace(SamplerConfig(), aspect_prob=1.0)
    swap, cyclic, none = polynomial_draw(*SWAP_Z), polynomial_draw(*CYCLIC), polynomial_draw(*NONE)
    assert axis_symmetries(swap, cfg) == ((2,), False)
    assert axis_symmetries(cyclic, cfg) == ((), True)
    assert axis_symmetries(none, cfg) == ((), False)
    whole = polynomial_draw((1, 2, 0, 0), (1, 0, 2, 0), (1, 0, 0, 2))  # a ball: every swap
    assert axis_symmetries(whole, cfg) == ((0, 1, 2), True)
    free_axes = set()
    for seed in range(40):
        rng = np.random.default_rng(seed)
        sx, sy, sz = draw_scale(rng, cfg, swap)
        assert sx == sy == 1.0 and cfg.aspect[0] <= sz <= cfg.aspect[1]
        assert draw_scale(np.random.default_rng(seed), cfg, cyclic) == (1.0, 1.0, 1.0)
        scale = draw_scale(np.random.default_rng(seed), cfg, none)
        assert all(cfg.aspect[0] <= s <= cfg.aspect[1] for s in scale)
        free_axes.add(len(set(scale)))
        stretched = stretch_draw(seed, 0, cfg, swap)
        assert axis_symmetries(stretched, cfg)[0] == (2,)  # the swap survives the stretch
        kept = [sum(s != 1 for s in draw_scale(np.random.default_rng(seed), cfg, whole))]
        assert kept == [1]
    assert 3 in free_axes
    off = replace(cfg, aspect_prob=0.0)
    assert stretch_draw(5, 0, off, none) is none


def test_a_symmetry_is_the_inside_s_within_the_tolerance() -> None:
    """A shape barely off its swap (a small term in x alone) still counts as symmetric at the
    default tolerance, and not at 0; a box that the swap does not map onto itself never does."""
    cfg = SamplerConfig()
    nearly = polynomial_draw(*SWAP_Z, (0.01, 3, 0, 0))
    assert axis_symmetries(nearly, cfg) == ((2,), False)
    assert axis_symmetries(nearly, cfg, tolerance=0.0) == ((), False)
    lopsided = replace(polynomial_draw(*SWAP_Z), box=Box((-1.5, -1.2, -1.5), (1.5, 1.5, 1.5)))
    assert axis_symmetries(lopsided, cfg) == ((), False)


def test_a_stretched_tree_scales_its_variables() -> None:
    tree = var("x") * var("x") + var("y") - var("z")
    got = stretch_tree(tree, (2.0, 1.0, 0.5))
    f = points_evaluator(got)
    assert f(np.array([4.0]), np.array([3.0]), np.array([1.0]))[0] == 4.0 + 3.0 - 2.0
    assert "y*" not in str(got)  # an axis not stretched is left alone


def test_the_proportions_are_recorded_and_deterministic() -> None:
    cfg = SamplerConfig()
    stretched = 0
    for index in range(30):
        draw = draw_equation(7, index, cfg)
        assert draw.model_dict() == draw_equation(7, index, cfg).model_dict()
        scale = (draw.structure or {}).get("aspect")
        if scale is not None:
            stretched += 1
            assert draw.model_dict()["structure"]["aspect"] == scale
            assert all(round(s, 2) == s and 0.45 <= s <= 2.2 for s in scale)
    assert 15 <= stretched <= 29  # about aspect_prob = 0.8, less the three-fold ones


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("aspect_prob", 1.5, "aspect_prob"),
        ("aspect", (0.05, 2.0), "aspect must lie within [0.1, 10]"),
        ("aspect", (2.0, 1.0), "aspect must be [low, high]"),
    ],
)
def test_bad_proportions_are_one_line_errors(key: str, value, message: str) -> None:
    with pytest.raises(SpecError, match=re.escape(message)) as err:
        replace(SamplerConfig(), **{key: value})
    assert "\n" not in str(err.value)


def test_every_family_is_stretched_in_the_mix() -> None:
    """Stretched shapes of every family (a lattice, a twist...) come out of the mix."""
    cfg = SamplerConfig()
    seen = set()
    for index in range(60):
        draw = draw_equation(7, index, cfg)
        if (draw.structure or {}).get("aspect"):
            seen.add(draw.family)
    assert {"sculpture", "infill", "assembly", "twist"} <= seen


def test_a_symmetry_must_map_the_box_onto_itself() -> None:
    """An ellipsoid as long as its box along z has samples that x <-> z maps onto one another
    (index for index), but the box is no longer itself under that swap: only x <-> y stays.
    Shifted along x, the same ball keeps y <-> z and loses the sign of x."""
    cfg = replace(SamplerConfig(), aspect_prob=1.0)
    ellipsoid = polynomial_draw((1, 2, 0, 0), (1, 0, 2, 0), (1 / 2.25, 0, 0, 2))
    tall = replace(ellipsoid, box=Box((-1.5, -1.5, -2.25), (1.5, 1.5, 2.25)))
    assert axis_symmetries(tall, cfg) == ((2,), False)
    ball = polynomial_draw((1, 2, 0, 0), (1, 0, 2, 0), (1, 0, 0, 2))
    shifted = replace(ball, box=Box((-1.5, -1.5, -1.5), (1.875, 1.5, 1.5)))
    assert axis_symmetries(shifted, cfg) == ((0,), False)


def test_a_family_limits_how_far_its_shapes_are_stretched() -> None:
    """``limit_ratio`` draws the factors' logarithms towards their middle until the largest
    over the smallest is the limit (to the factors' two decimals); equal factors stay equal, so
    a kept swap of axes is kept; factors within the limit are left as drawn."""
    assert limit_ratio((0.5, 1.0, 2.0), 2.0) == (0.71, 1.0, 1.41)
    assert limit_ratio((0.45, 1.0, 1.0), 1.5)[1:] == (0.82, 0.82)
    assert limit_ratio((0.8, 1.1, 1.0), 1.5) == (0.8, 1.1, 1.0)
    rng = np.random.default_rng(1)
    for _ in range(200):
        scale = tuple(round(float(v), 2) for v in np.exp(rng.uniform(-0.8, 0.8, 3)))
        out = limit_ratio(scale, 1.5)
        assert max(out) / min(out) <= 1.5 * 1.02, (scale, out)
        for a in range(3):  # the order of the factors kept (rounding may make two equal)
            for b in range(3):
                assert scale[a] >= scale[b] or out[a] <= out[b], (scale, out)
    # the twist family's shapes (squashed further, a column is a lens or a stack of plates)
    cfg = replace(SamplerConfig(), family="twist")
    ratios = []
    for i in range(60):
        aspect = draw_equation(7, i, cfg).structure.get("aspect")
        if aspect:
            ratios.append(max(aspect) / min(aspect))
    assert len(ratios) > 30 and max(ratios) <= 1.5 * 1.02 and max(ratios) > 1.3


def test_coefficients_are_the_decimal_product_whatever_the_exponents_type() -> None:
    """A stretched coefficient ``a sx^-b sy^-c sz^-d`` is the 40-digit decimal product rounded
    to DIGITS, its powers cached per factor and exponent as computed afresh (integer, float and
    fractional exponents)."""
    ctx = decimal.Context(prec=40)

    def fresh(term, scale):
        value = decimal.Decimal(term.a)
        for s, e in zip(scale, (term.b, term.c, term.d), strict=True):
            if e != 0 and s != 1:
                power = ctx.power(decimal.Decimal(repr(s)), decimal.Decimal(repr(-e)))
                value = ctx.multiply(value, power)
        return round_significant(float(value), DIGITS)

    scale = (1.37, 0.81, 1.0)
    for term in (
        PowerTerm(1.25, 2, 1, 0),
        PowerTerm(1.25, 2.0, 1.0, 0),
        PowerTerm(-0.7, 3, 0, 2),
        PowerTerm(0.3, 0.5, 1.5, 0),
    ):
        assert _coefficient(term, scale) == fresh(term, scale)
