"""Maxima and minima written through ``|·|``, bounded as such (:mod:`.interval_extrema`): found in
the families that write them (the assembly's booleans, the infill's envelopes, the gems'
cuts) and nowhere else; F within ``compact ± spread`` at random points; the bounds sound for
random groups and boxes (hypothesis), and not once the rounding margin is taken away; the
sparse path samples fewer leaves for the same mesh."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from surfgen.generator.eval import interval_extrema
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.interval_regroup import regroup, regrouped_bounds
from surfgen.generator.eval.intervals import grid_point_bounds
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

# Operands of the random groups: sums over atoms with poles and jumps, polynomials whose terms
# cancel, products of sums.
OPERANDS = [
    ["1.77778*z^2", "2.56821*y^2", "3.3544*x^2", "-1"],
    ["-55.8617*z^4", "-161.398*y^2*z^2", "-304.533*x^2*y^2", "88.2548*y*z^2", "-10.8233*y"],
    ["abs(x)^2.9", "abs(y)^2.9", "-15.55*abs(z)^10", "1"],
    ["0.4*tan(z)", "sin(3*y)*abs(x)", "-0.3"],
    ["1e8*x", "-1e8*y", "3"],
    ["saw2(x*y,1.07)", "-1*(1/cos(0.8*y*z))"],
]


def written(terms: list[str], scale: float = 1.0) -> str:
    """A sum of ``terms`` (each ``c*rest`` or a number), every coefficient times ``scale``."""
    out = []
    for t in terms:
        c, _, rest = t.partition("*")
        try:
            value = float(c) * scale
        except ValueError:
            value, rest = scale, t
        text = repr(value) if not rest else f"{value!r}*{rest}"
        out.append(text if text.startswith("-") else "+" + text)
    return "".join(out).lstrip("+")


def group(a: list[str], b: list[str] | None, c: float, sigma: int, wobble: float = 0.0) -> str:
    """``c A + c B + σ |c| |A - B|`` as the families write it (``B`` None: ``c A + σ |c| |A|``),
    the difference written out term by term, each coefficient times ``1 + wobble``."""
    diff = a + ([] if b is None else [written([t], -1.0) for t in b])
    inner = written(diff, 1.0 + wobble)
    text = f"{c!r}*({written(a)})"
    if b is not None:
        text += f"+{c!r}*({written(b)})"
    return text + ("+" if sigma > 0 else "-") + f"{abs(c)!r}*abs({inner})"


def test_the_families_extrema_are_found_and_nothing_else() -> None:
    """Every boolean assembly has one group (min for a union, max otherwise), every infill
    draw its envelopes' ramps (``max(X, 0)``), every gem sculpture its cut (a max of two);
    lattices, twists and free draws none."""
    seen = set()
    for family in ("assembly", "infill", "sculpture", "lattice", "twist", "free"):
        cfg = SamplerConfig(family=family)
        for index in range(30):
            draw = draw_equation(5, index, cfg)
            found = regroup(draw.equation.with_d(0.1).to_tree())
            got = [(e.kind, e.terms[1] is None) for e in (found.extrema if found else ())]
            if draw.structure.get("join") == "boolean":
                union = " union " in draw.structure["operation"]
                assert got == [("min" if union else "max", False)], index
                seen.add(("assembly", got[0][0]))
            elif family == "infill":
                assert got and set(got) == {("max", True)}, index
                seen.add(("infill", len(got)))
            elif family == "sculpture" and draw.structure["envelope"]["kind"] == "gem":
                assert got == [("max", False)], index
                seen.add(("gem", "max"))
            else:
                assert got == [], (family, index)
    assert {("assembly", "min"), ("assembly", "max"), ("gem", "max")} <= seen
    assert len({n for kind, n in seen if kind == "infill"}) >= 2


@pytest.mark.parametrize(
    "text",
    [
        "0.5*(x^2+y)+0.5*z+0.5*abs(x^2+y-z+0.01)",  # A - B off by more than a rounding
        "0.5*x+0.4*abs(x)",  # coefficients that differ
        "0.5*x+0.5*abs(y)",  # another operand
        "x*y+abs(x)*y",  # a factor outside |·|
        "0.5*x^2+0.5*abs(x)^2",  # |x|^2 is not |·| of a term
        "3*abs(2)+x",  # a constant
    ],
)
def test_what_is_not_an_extremum_is_left(text: str) -> None:
    found = regroup(parse(text))
    assert found is None or not found.extrema


def test_the_groups_their_kinds_and_signs() -> None:
    """Pairs and single terms, either sign of c and of the ``|·|`` term, subtracted terms, the
    difference either way round, ``|P| |Q|`` as ``|P Q|``; other terms kept in the compact
    form."""
    cases = {
        "0.5*(x^2+y^2-1)+0.5*(z^2-0.25)-0.5*abs(x^2+y^2-1-z^2+0.25)+sin(x)": ("min", (0, 1, 2)),
        "3*(x*y-0.2)+3*abs(x*y-0.2)": ("max", (0, None, 1)),
        "cos(z)-2*(x-y)+2*abs(y-x)": ("max", (1, None, 2)),
        "-0.7*(x+z)-0.7*y^3-0.7*abs(y^3-x-z)": ("min", (0, 1, 2)),
        "27.8*(abs(x)^3.8-1)*(abs(y)^1.7-0.5)+27.8*abs(abs(x)^3.8-1)*abs(abs(y)^1.7-0.5)": (
            "max",
            (0, None, 1),
        ),
    }
    for text, (kind, terms) in cases.items():
        found = regroup(parse(text))
        assert found is not None, text
        (e,) = found.extrema
        assert (e.kind, e.terms) == (kind, terms), text
        assert f"2*{kind}(" in to_string(found.compact)
    found = regroup(parse("0.5*(x^2+y^2-1)+0.5*(z^2-0.25)-0.5*abs(x^2+y^2-1-z^2+0.25)+sin(x)"))
    assert "sin(x)" in to_string(found.compact)


def test_f_lies_within_the_spread_of_the_compact_formula() -> None:
    """At random points, |F - compact| <= spread for groups of every kind of operand, with
    differences off by up to 1e-5 and cancellations of 1e8."""
    rng = np.random.default_rng(1)
    cases = [
        group(OPERANDS[0], OPERANDS[1], 0.5, 1),
        group(OPERANDS[2], OPERANDS[3], -0.5, 1, 1e-7),
        group(OPERANDS[4], OPERANDS[0], 2.0, -1),
        group(OPERANDS[5], None, 150.5, 1, 1e-5),
        group(OPERANDS[1], None, -6.55, -1) + "+sin(4*x)*cos(4*y)",
    ]
    for text in cases:
        found = regroup(parse(text))
        assert found is not None and len(found.extrema) == 1, text
        assert_within_spread(text, found, rng)


PROPERTY = settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))


@PROPERTY
@given(
    st.sampled_from(range(len(OPERANDS))),
    st.sampled_from([None, *range(len(OPERANDS))]),
    st.floats(-200, 200).filter(lambda c: abs(c) > 1e-3),
    st.sampled_from([1, -1]),
    st.sampled_from([0.0, 1e-9, 1e-5]),
    st.sampled_from(["", "+abs(x)^4.5-1.9", "-x*y*z+0.5", "+tan(x)"]),
    st.integers(0, 2**32 - 1),
)
def test_tightened_bounds_are_sound(a, b, c, sigma, wobble, rest, seed) -> None:
    """Property: for random groups (operands with poles and jumps, terms of 1e8 that cancel,
    differences off by a residual) plus other terms, and random boxes, every value of F at
    the boxes' corners and random points is NaN or within the tightened bounds, and finite
    where they say so."""
    rng = np.random.default_rng(seed)
    second = None if b is None or b == a else OPERANDS[b]
    text = group(OPERANDS[a], second, c, sigma, wobble) + rest
    tree, program, bounds = regrouped(text)
    for half in (0.2, 2.0):
        blo, bhi = random_boxes(rng, [-half] * 3, [half] * 3, 24)
        assert_sound(tree, {}, blo, bhi, rng, bounds(program, blo, bhi))


def test_without_the_rounding_margin_the_bounds_fail(monkeypatch) -> None:
    """The margin is needed: ``|x - y + 1e8 - 1e8|`` is ``|x - y|`` rounded to the units in the
    last place of 1e8, so with the rounding margin zeroed some point falls outside its
    bounds."""
    text = "0.5*x+0.5*y+0.5*abs(x-y+1e8-1e8)"
    assert_margin_needed(text, interval_extrema, monkeypatch)


def test_the_bounds_are_tighter_on_a_grid_and_hold_its_points() -> None:
    """An intersection of a ball and a torus written out (the assembly's way): on a grid's
    blocks the compact bounds are far tighter than the formula's own, and every grid point
    is within them."""
    ball = ["3.3544*x^2", "2.56821*y^2", "1.77778*z^2", "-1"]
    torus = ["-55.8617*z^4", "-161.398*y^2*z^2", "-116.579*y^4", "-210.805*x^2*z^2",
             "-304.533*x^2*y^2", "-198.879*x^4", "88.2548*y*z^2", "127.495*y^3",
             "166.523*x^2*y", "-33.0515*z^2", "-15.0646*y^2", "25.8524*x^2", "-10.8233*y",
             "0.159856"]  # fmt: skip
    text = group(ball, torus, 0.5, 1) + "-0.0958751"
    tree = parse(text)
    program = compile_tree(tree)
    grid = Grid(Box((-1.08,) * 3, (1.08,) * 3), (65, 61, 67))
    base = grid_point_bounds(grid.axes(), 1)
    idx, top, blo, bhi = grid_blocks(grid, 8)
    plo, phi, _ = base(program, blo, bhi)
    flo, fhi, fin = regrouped_bounds(base, program, regroup(tree))(program, blo, bhi)
    assert fin.all()
    assert np.median((fhi - flo) / (phi - plo)) < 0.5
    assert_grid_points_within(tree, grid, idx, top, flo, fhi)


@pytest.mark.parametrize("family", ["assembly", "infill"])
def test_the_sparse_path_samples_fewer_leaves_for_the_same_mesh(family: str) -> None:
    """A boolean assembly and an infill draw at an odd grid in a shifted box: the sparse path
    with the compact bounds samples fewer leaves than with the plain ones, keeps the same, and
    meshes as the dense path does, bit for bit, capped."""
    cfg = SamplerConfig(family=family)
    draw = next(
        d
        for d in (draw_equation(5, i, cfg) for i in range(40))
        if family == "infill" or d.structure.get("join") == "boolean"
    )
    tree = draw.equation.with_d(choose_d(draw, cfg, threads=1)).to_tree()
    lo, hi = np.array(draw.box.lo), np.array(draw.box.hi)
    box = Box(tuple(lo * 1.05 + 0.03), tuple(hi * 0.97 + 0.03))
    assert_fewer_leaves_same_mesh(tree, box, (97, 90, 103))
