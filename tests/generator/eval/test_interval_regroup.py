"""Powers of sums multiplied out, folded back for tighter bounds (:mod:`.interval_regroup`):
found in the sculptures that have them and nowhere else; F within ``compact ± spread`` at
random points; the tightened bounds sound for random expansions and boxes (hypothesis), and not
once the rounding margin is taken away; the sparse path samples fewer leaves for the same mesh."""

from __future__ import annotations

from itertools import combinations_with_replacement

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from surfgen.generator.eval import interval_regroup
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.interval_regroup import regroup, regrouped_bounds
from surfgen.generator.eval.intervals import grid_point_bounds, program_bounds
from surfgen.generator.formula.expr import to_string
from surfgen.generator.formula.parser import parse
from surfgen.generator.model.sampler import SamplerConfig, choose_d, draw_equation
from tests.support.interval_checks import (
    assert_fewer_leaves_same_mesh,
    assert_grid_points_within,
    assert_margin_needed,
    assert_sound,
    assert_within_spread,
    grid_blocks,
    random_boxes,
    regrouped,
)

# Factors of the random expansions: of one, two or three axes, with poles and jumps.
FACTORS = [
    "abs(x)^1.3-0.5",
    "sin(3*y)*abs(x)",
    "(-1.09*abs(y)*abs(z)+0.73*abs(x)*abs(z)^2)/(-0.18*abs(y)^0.49-0.17*abs(x)^2)",
    "atan(cos((1.156*abs(x)^1.82*abs(y)^0.45)^0.5))",
    "tan(z)",
    "saw2(x*y,1.07)",
    "x-y*z",
    "1/cos(0.8*y*z)",
]


def multinomial(factors: list[str], k: int, a: float, wobble: float = 0.0, rng=None) -> str:
    """``(factors[0] + ...)^k`` multiplied out as the sampler writes it: ``c*(O_i)*(O_j)...``
    with c = a times the multinomial coefficient (times ``1 + wobble * u``, u in [-1, 1])."""
    n, out = len(factors), []
    for combo in combinations_with_replacement(range(n), k):
        c = a * interval_regroup._multinomial(combo)
        if wobble:
            c *= 1 + wobble * rng.uniform(-1, 1)
        sign = "-" if c < 0 else "+"
        out.append(f"{sign}{abs(float(c))!r}*" + "*".join(f"({factors[i]})" for i in combo))
    return "".join(out)


def test_the_sculptures_powers_of_sums_are_found_and_nothing_else() -> None:
    """Every sculpture drawn with k = 2 or 3 over three copies has its expansion found (three
    factors, power k, its coefficients' a); k = 3 of one copy too (``O*O*O``); k = 1, and
    k = 2 of one copy (a square, which the rules already bound as one), none (a gem's
    envelope, a maximum, is found as one: :mod:`.interval_extrema`)."""
    cfg = SamplerConfig(family="sculpture")
    seen = set()
    for index in range(48):
        draw = draw_equation(5, index, cfg)
        k, copies = draw.structure["k"], draw.structure["group"]
        found = regroup(draw.equation.to_tree())
        gem = draw.structure["envelope"]["kind"] == "gem"
        assert gem == bool(found and found.extrema), index
        three = copies.startswith("cyclic")
        if k >= 2 and three or k == 3:
            assert found is not None, (index, k, copies)
            (e,) = found.expansions
            assert (len(e.factors), e.power) == ((3 if three else 1), k)
            assert e.terms == {(3, 2): 6, (3, 3): 10, (1, 3): 1}[(len(e.factors), k)]
            seen.add((len(e.factors), k))
        else:
            assert found is None or not found.expansions, (index, k, copies)
    assert seen == {(3, 2), (3, 3), (1, 3)}


@pytest.mark.parametrize(
    "text",
    [
        "0.4*(x+1)*(y+2)+x",  # one product: not every multiset of its factors
        "0.4*(x+1)*(x+1)+0.8*(x+1)*(y+2)+0.4*(y+2)*(y+3)",  # a factor not in the others
        "0.4*(x+1)*(x+1)+0.8*(x+1)*(y+2)+0.4*(y+2)*(y+2)*(z)",  # products of other sizes
        "0.4*(x+1)*(x+1)+0.3*(x+1)*(y+2)+0.4*(y+2)*(y+2)",  # coefficients not in proportion
        "0.4*(x+1)*(x+1)-0.8*(x+1)*(y+2)+0.4*(y+2)*(y+2)",  # (U - V)^2: signs not a's
        "(x+1)*(x+1)+1",  # a square: bounded as one already
    ],
)
def test_what_is_not_a_power_of_a_sum_is_left(text: str) -> None:
    assert regroup(parse(text)) is None


def test_the_terms_and_their_coefficients_are_read_with_their_signs() -> None:
    """Subtracted, negated and nested terms; a negative a; a sum of two expansions."""
    u, v, w = "x+1", "y-2", "sin(z)"
    text = f"x^2-(1-y){multinomial([u, v], 2, -0.25)}+3*(z){multinomial([u, w], 3, 0.125)}-2"
    found = regroup(parse(text))
    assert found is not None
    got = {(tuple(to_string(f) for f in e.factors), e.power, e.a) for e in found.expansions}
    assert got == {(("x+1", "y-2"), 2, -0.25), (("x+1", "sin(z)"), 3, 0.125)}
    assert to_string(found.compact).count("^") == 3  # x^2 and the two powers


def test_f_lies_within_the_spread_of_the_folded_formula() -> None:
    """At random points, |F - compact| <= spread for expansions of every kind of factor,
    with coefficients off their proportion by up to 1e-3, and cancellations of 1e8."""
    rng = np.random.default_rng(1)
    cases = [
        multinomial(FACTORS[:3], 2, 0.411) + "+abs(x)^4.5-1.9",
        multinomial(FACTORS[2:5], 3, -0.07, 1e-3, rng) + "+x^3",
        multinomial(["x+1e8", "y-1e8"], 2, 1.0) + "-3",  # (x + y)^2, from terms of 1e16
        multinomial(FACTORS[5:8], 2, 2.5, 1e-4, rng) + "-0.5",
        multinomial([FACTORS[1]], 3, 0.3),
    ]
    for text in cases:
        found = regroup(parse(text))
        assert found is not None, text
        assert_within_spread(text, found, rng)


PROPERTY = settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))


@PROPERTY
@given(
    st.lists(
        st.sampled_from(FACTORS + ["x+1e8", "y-1e8", "z"]), min_size=1, max_size=3, unique=True
    ),  # fmt: skip
    st.integers(2, 3),
    st.floats(-3, 3).filter(lambda a: abs(a) > 1e-3),
    st.sampled_from(["", "+abs(x)^2.9-1", "-x*y*z+0.5", "+tan(x)"]),
    st.integers(0, 2**32 - 1),
)
def test_tightened_bounds_are_sound(factors, k, a, rest, seed) -> None:
    """Property: for random expansions (factors with poles and jumps, cancellations of 1e16,
    coefficients off their proportion) plus other terms, and random boxes, every value of
    F at the boxes' corners and random points is NaN or within the tightened bounds, and
    finite where they say so."""
    if len(factors) == 1 and k == 2:
        k = 3
    rng = np.random.default_rng(seed)
    text = multinomial(factors, k, a, 1e-3 * rng.integers(0, 2), rng) + rest
    tree, program, bounds = regrouped(text)
    for half in (0.2, 2.0):
        blo, bhi = random_boxes(rng, [-half] * 3, [half] * 3, 24)
        assert_sound(tree, {}, blo, bhi, rng, bounds(program, blo, bhi))


def test_without_the_rounding_margin_the_bounds_fail(monkeypatch) -> None:
    """The spread is needed: (x + y)^2 multiplied out from terms of 1e16 is off by units in
    the last place of 1e16, so with the spread zeroed some point falls outside its bounds."""
    text = multinomial(["x+1e8", "y-1e8"], 2, 1.0)
    assert_margin_needed(text, interval_regroup, monkeypatch)


def test_the_bounds_are_tighter_and_the_plain_ones_where_they_cannot_be() -> None:
    """Where U, V and W have mixed signs the folded bound is far tighter, and never looser
    than the plain one by more than the spread; boxes where a term can be infinite (a pole of
    tan) get the plain bounds; other programs are bounded as they were."""
    text = multinomial(FACTORS[:3], 2, 0.411) + "+abs(x)^4.5-0.58*x^3-1.9+tan(1.1*y)"
    tree, program, bounds = regrouped(text)
    rng = np.random.default_rng(4)
    blo, bhi = random_boxes(rng, [-2.0] * 3, [2.0] * 3, 400)
    plo, phi, pfin = program_bounds(program, blo, bhi)
    flo, fhi, fin = bounds(program, blo, bhi)
    slack = 1e-9 * np.maximum(1.0, np.abs(plo))
    assert np.all((flo >= plo - slack) | ~fin) and np.all(fin | ~pfin)
    both = np.isfinite(plo) & np.isfinite(phi) & fin
    assert both.sum() > 100
    assert np.median((fhi - flo)[both] / (phi - plo)[both]) < 0.8
    pole = (blo[:, 1] <= np.pi / 2.2) & (bhi[:, 1] >= np.pi / 2.2)
    assert pole.any() and not fin[pole].any()
    assert np.array_equal(flo[pole], plo[pole]) and np.array_equal(fhi[pole], phi[pole])
    other = compile_tree(parse("x+y"))
    assert np.array_equal(bounds(other, blo, bhi)[0], program_bounds(other, blo, bhi)[0])


def test_the_terms_of_one_axis_are_summed_together(monkeypatch) -> None:
    """``|x|^4.5 - 0.58 x^3`` bounded term by term takes each term's extremes; summed as one
    value of x, the folded formula bounds it at the grid's coordinates, exactly: on a grid's
    blocks the bounds are tighter than with the terms apart, and hold every grid point. A
    formula with no expansion is left as it is."""
    cubic = "abs(x)^4.5+abs(y)^4.5+abs(z)^4.5-1-0.58*x^3-0.58*y^3-0.58*z^3"
    assert regroup(parse(cubic + "+0.3*sin(3*x*y*z)")) is None
    text = cubic + multinomial(["sin(2*x*y)", "cos(y*z)"], 2, 0.05)
    tree = parse(text)
    program = compile_tree(tree)
    grid = Grid(Box((-1.3,) * 3, (1.3,) * 3), (41, 37, 45))
    base = grid_point_bounds(grid.axes(), 1)
    idx, top, blo, bhi = grid_blocks(grid, 4)
    flo, fhi, fin = regrouped_bounds(base, program, regroup(tree))(program, blo, bhi)
    with monkeypatch.context() as m:
        m.setattr(interval_regroup, "_by_axis", lambda terms, _: terms)
        alo, ahi, _ = regrouped_bounds(base, program, regroup(tree))(program, blo, bhi)
    ratio = (fhi - flo) / (ahi - alo)
    assert fin.all() and np.median(ratio) < 0.85 and ratio.max() < 1 + 1e-9
    assert_grid_points_within(tree, grid, idx, top, flo, fhi)


def test_the_sparse_path_samples_fewer_leaves_for_the_same_mesh() -> None:
    """A k = 2 sculpture at an odd grid in a shifted box: the sparse path with the folded
    bounds samples fewer leaves than with the plain ones, keeps the same, and meshes as the
    dense path does, bit for bit, capped."""
    cfg = SamplerConfig(family="sculpture")
    draw = next(
        d
        for d in (draw_equation(5, i, cfg) for i in range(40))
        if d.structure["k"] == 2 and d.structure["group"].startswith("cyclic")
    )
    tree = draw.equation.with_d(choose_d(draw, cfg, threads=1)).to_tree()
    lo, hi = np.array(draw.box.lo), np.array(draw.box.hi)
    box = Box(tuple(lo * 1.05 + 0.03), tuple(hi * 0.97 + 0.03))
    assert_fewer_leaves_same_mesh(tree, box, (97, 90, 103))
