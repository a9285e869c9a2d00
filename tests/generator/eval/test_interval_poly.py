"""Expanded polynomials bounded by their Taylor forms (:mod:`.interval_poly`): found where a
polynomial mixes its variables, nowhere else; the bounds sound for random compositions of
polynomials, parts with poles and jumps and the joining operations (hypothesis), and not once
the rounding margins are taken away; the sparse path samples fewer leaves for the same mesh."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from surfgen.generator.eval import interval_poly
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.interval_poly import polynomial_bounds, polynomial_structure
from surfgen.generator.eval.intervals import grid_point_bounds, program_bounds
from surfgen.generator.formula.parser import parse
from surfgen.generator.model.sampler import SamplerConfig, choose_d, draw_equation
from tests.support.interval_checks import (
    assert_fewer_leaves_same_mesh,
    assert_fewer_leaves_than_without,
    assert_grid_points_within,
    assert_sound,
    grid_blocks,
    random_boxes,
    structure_bounds,
    twist_case,
)

TORUS = "(x^2+y^2+z^2+0.6^2-0.25^2)^2-4*0.6^2*(x^2+y^2)"
TORUS_OUT = (
    "604.334*x^4+1208.67*x^2*y^2+604.334*y^4+825.703*x^2*z^2+825.703*y^2*z^2+282.041*z^4"
    "+1976.64*x^3+1976.64*x*y^2+1350.35*x*z^2+2223.14*x^2+606.845*y^2+685.44*z^2"
    "+992.428*x+151.342"
)


def kinds(text: str) -> list[str] | None:
    found = polynomial_structure(parse(text))
    return None if found is None else [k for k, _, _ in found.nodes]


def test_polynomials_that_mix_their_variables_are_found() -> None:
    """A torus' quartic, written out or not, is one polynomial; a product of two is two joined
    by ``*`` when their product would be too long; sums of one variable's powers (Chmutov's),
    short polynomials and formulas without any are left."""
    assert kinds(TORUS) == ["poly"]
    assert kinds(TORUS_OUT) == ["poly"]
    product = kinds(f"({TORUS_OUT})*({TORUS_OUT.replace('x', 'z')})")
    assert product is not None and product.count("poly") >= 1
    assert kinds(f"({TORUS_OUT})*sin(x*y)/(x^2+y^2+1)") is not None
    # a real power of a polynomial joins it (a twist's lobes: P / Q^1.5), a whole one of a
    # part is a part
    assert kinds(f"x*y/({TORUS_OUT})^1.5") == ["part", "poly", "num", "^", "/"]
    assert "^" not in kinds(f"({TORUS_OUT})+sin(x)^3")
    for text in [
        "32*x^6-48*x^4+18*x^2-1+(32*y^6-48*y^4+18*y^2-1)",  # one variable a term
        "x^2+y^2+z^2-1",  # no monomial of two variables
        "x*y+z",  # one monomial of degree 2
        "sin(x)*cos(y)+abs(z)^2.5",
    ]:
        assert kinds(text) is None, text


TERMS = ["x^2*y", "x*y*z", "y^2*z^2", "x^3", "z^2", "x*y", "y", "x^4*z"]
PARTS = ["sin(3*x*y)", "tan(z)", "saw2(x+y,0.7)", "abs(x)^1.5", "1/(x-0.3)"]


@st.composite
def polynomials(draw) -> str:
    n = draw(st.integers(3, 7))
    terms = draw(st.lists(st.sampled_from(TERMS), min_size=n, max_size=n))
    scale = draw(st.sampled_from([1.0, 1e3, 1e8]))
    coefs = draw(st.lists(st.floats(-1, 1).filter(lambda c: abs(c) > 1e-3), min_size=n,
                          max_size=n))  # fmt: skip
    poly = "".join(
        f"{'+' if c >= 0 else '-'}{abs(c) * scale!r}*{t}" for c, t in zip(coefs, terms, strict=True)
    )
    return f"(x*y+x^2*z+y^2{poly})"


@st.composite
def compositions(draw) -> str:
    a, b = draw(polynomials()), draw(polynomials())
    part = draw(st.sampled_from(PARTS))
    form = draw(st.sampled_from(["{a}*{b}", "{a}+{p}", "abs({a})-{b}", "{a}/({b})",
                                 "-{a}*{p}+0.5", "{a}*{b}*{p}", "({a})^2+{p}",
                                 "{b}/(({a})^2+0.01)^1.5*{p}", "({a})^0.5-{b}",
                                 "(abs({a})+0.1)^-1.3+{p}", "abs({b})^2.7*{a}",
                                 "{a}+{b}*cos({p})-sin({p})*{a}"]))  # fmt: skip
    return form.format(a=a, b=b, p=part)


PROPERTY = settings(max_examples=80, deadline=None, suppress_health_check=list(HealthCheck))


@PROPERTY
@given(compositions(), st.integers(0, 2**32 - 1))
def test_taylor_bounds_are_sound(text: str, seed: int) -> None:
    """Property: for random polynomials (coefficients up to 1e8, so terms of 1e16 that cancel)
    joined by ``+ - * / abs`` and powers (whole, and real: of bases that may be negative),
    with parts that have poles and jumps, and random
    boxes, every value of F at the boxes' corners and random points is NaN or within the
    bounds, and finite where they say so (``level`` None: every box bounded through the
    structure)."""
    rng = np.random.default_rng(seed)
    tree, program, bounds = structure_bounds(text)
    for half in (0.05, 0.5, 3.0):
        blo, bhi = random_boxes(rng, [-half] * 3, [half] * 3, 24)
        assert_sound(tree, {}, blo, bhi, rng, bounds(program, blo, bhi))


def test_without_the_rounding_margins_the_bounds_fail(monkeypatch) -> None:
    """The margins are needed: ``x^2 + y^2 + x y`` written with terms of 1e16 that cancel
    exactly is bounded as the polynomial it is, but the evaluator's value is off by units of
    1e16's last place; with the margins zeroed some point falls outside its bounds."""
    text = "x^2+y^2+x*y+2e8*x+1e16-2e8*x-1e16+3e8*y*z-3e8*y*z"
    rng = np.random.default_rng(2)
    blo, bhi = random_boxes(rng, [-1.5] * 3, [1.5] * 3, 300)
    tree, program, bounds = structure_bounds(text)
    assert kinds(text) == ["poly"]
    assert_sound(tree, {}, blo, bhi, rng, bounds(program, blo, bhi))
    monkeypatch.setattr(interval_poly, "_UNIT", 0.0)
    tree, program, bounds = structure_bounds(text)
    with pytest.raises(AssertionError, match="outside its bounds"):
        assert_sound(tree, {}, blo, bhi, rng, bounds(program, blo, bhi))


def test_the_taylor_form_is_far_tighter_on_a_torus_written_out() -> None:
    """On the blocks of a grid around a torus written out (terms in the hundreds) that the plain
    bounds leave to sample, they are many times wider than the Taylor form's, which decides
    far more blocks and holds every grid point."""
    tree = parse(TORUS_OUT)
    program = compile_tree(tree)
    grid = Grid(Box((-1.6,) * 3, (1.6,) * 3), (65, 61, 67))
    base = grid_point_bounds(grid.axes(), 1)
    bounds = polynomial_bounds(base, program, polynomial_structure(tree), None)
    idx, top, blo, bhi = grid_blocks(grid, 4)
    plo, phi, _ = base(program, blo, bhi)
    flo, fhi, fin = bounds(program, blo, bhi)
    near = (plo < 0) & (phi > 0)  # the blocks the plain bounds leave to sample
    assert fin.all() and near.sum() > 100
    assert np.median((phi - plo)[near] / (fhi - flo)[near]) > 5
    assert np.mean((flo > 0) | (fhi < 0)) > np.mean((plo > 0) | (phi < 0)) + 0.1
    assert_grid_points_within(tree, grid, idx, top, flo, fhi, every=7)


def test_a_structure_that_decides_nothing_is_given_up(monkeypatch) -> None:
    """Once a call of enough boxes finds the structure deciding next to none of them, later
    calls use the base bounds alone."""
    calls = []
    original = interval_poly._structure_bounds

    def counted(*args):
        calls.append(len(args[4]))
        return original(*args)

    monkeypatch.setattr(interval_poly, "_structure_bounds", counted)
    tree = parse(TORUS_OUT)
    program = compile_tree(tree)

    def base(prog, lo, hi):
        return program_bounds(prog, lo, hi)

    bounds = polynomial_bounds(base, program, polynomial_structure(tree), 1e9)
    rng = np.random.default_rng(5)
    blo, bhi = random_boxes(rng, [-1.0] * 3, [1.0] * 3, 3000)
    blo, bhi = blo - 50, bhi + 50  # boxes so large that neither bound decides them
    for _ in range(3):
        bounds(program, blo, bhi)
    assert calls == [3000]


@pytest.mark.parametrize("family", ["assembly", "twist", "infill"])
def test_the_sparse_path_samples_fewer_leaves_for_the_same_mesh(family: str) -> None:
    """A draw of each family whose formula has such polynomials, at an odd grid in a shifted
    box: fewer leaves sampled than with the plain bounds, the same kept, and the mesh the
    dense path's, bit for bit, capped."""
    cfg = SamplerConfig(family=family)
    for index in range(30):
        draw = draw_equation(5, index, cfg)
        d = choose_d(draw, cfg, threads=1)
        if d is None:
            continue
        tree = draw.equation.with_d(d).to_tree()
        if polynomial_structure(tree) is not None:
            break
    else:
        pytest.fail(f"no {family} draw with a polynomial")
    lo, hi = np.array(draw.box.lo), np.array(draw.box.hi)
    box = Box(tuple(lo * 1.03 + 0.02), tuple(hi * 0.98 + 0.02))
    assert_fewer_leaves_same_mesh(tree, box, (121, 113, 127))


LOBE = "(x^4-6*x^2*y^2+y^4)"  # Re (x + i y)^4: a twist's lobe, r^4 cos 4φ
RADIUS = "(x^2+y^2+0.01)"


def test_quotients_of_polynomials_are_found() -> None:
    """``P / D`` and ``P / D^k`` (k real) of polynomials carry their quotient, with the power;
    a quotient by anything else does not."""
    for text, power in [(f"{LOBE}/{RADIUS}*z", 1.0), (f"{LOBE}/{RADIUS}^1.5+z", 1.5)]:
        found = polynomial_structure(parse(text))
        quotients = [p for k, p, _ in found.nodes if k == "/" and p is not None]
        assert len(quotients) == 1 and quotients[0].power == power, text
    found = polynomial_structure(parse(f"{LOBE}/sin(x*y+2)"))
    assert all(p is None for k, p, _ in found.nodes if k == "/")


@pytest.mark.parametrize(("power", "gain"), [("", 1.4), ("^1.5", 1.3), ("^0.5", 1.08)])
def test_the_centred_quotient_is_sound_and_tighter(power: str, gain: float) -> None:
    """A twist's lobe over its radius on a grid's blocks: the centred form alone holds every
    grid point of the blocks, and is several times narrower than the quotient of the two
    Taylor forms where the lobe is large (the median over the blocks 1.59, 1.49 and 1.14 times
    for D, D^1.5 and D^0.5: the power's own range is not centred)."""
    tree = parse(f"{LOBE}/{RADIUS}{power}")
    grid = Grid(Box((-2.1, -1.9, -0.5), (1.9, 2.2, 0.5)), (65, 67, 9))
    structure = polynomial_structure(tree)
    idx, top, blo, bhi = grid_blocks(grid, 2)
    q = structure.nodes[-1][1]
    lobe, radius = (interval_poly._poly_bounds(p, blo, bhi) for p in (q.num, q.den))
    ones = np.ones(len(blo), dtype=np.bool_)
    with np.errstate(all="ignore"):
        clo, chi = interval_poly._centred(q, blo, bhi, radius, 1)
        power = (np.full(len(blo), q.power),) * 2
        divisor = radius if q.power == 1.0 else interval_poly._join("^", [radius, power], ones)
        plain = interval_poly._join("/", [lobe, divisor], ones)
    held = np.isfinite(clo) & np.isfinite(chi)  # elsewhere not used (a divisor's bound <= 0)
    assert held.mean() > 0.9
    clo, chi = np.where(held, clo, -np.inf), np.where(held, chi, np.inf)
    assert_grid_points_within(tree, grid, idx, top, clo, chi)
    far = held & (np.hypot(blo[:, 0] + bhi[:, 0], blo[:, 1] + bhi[:, 1]) / 2 > 1.0)
    ratio = (plain[1] - plain[0])[far] / (chi - clo)[far]
    assert np.median(ratio) > gain


def test_without_the_rounding_margins_the_centred_form_fails(monkeypatch) -> None:
    """The centred form's margins are needed: a lobe written with terms of 1e16 that cancel,
    over points, is bounded as the quotient it is, but the evaluator's value is off by units
    of 1e16's last place; with the margins zeroed some point falls outside."""
    text = f"({LOBE}+3e8*x*y*z+1e16-3e8*x*y*z-1e16)/{RADIUS}"
    rng = np.random.default_rng(6)
    blo, bhi = random_boxes(rng, [-1.5] * 3, [1.5] * 3, 300)
    blo[:200] = bhi[:200]
    tree = parse(text)
    structure = polynomial_structure(tree)
    q = structure.nodes[-1][1]

    def centred():
        den = interval_poly._poly_bounds(q.den, blo, bhi)
        with np.errstate(all="ignore"):
            return interval_poly._centred(q, blo, bhi, den, 1)

    lo, hi = centred()
    assert_sound(tree, {}, blo, bhi, rng, (lo, hi, np.isfinite(lo) & np.isfinite(hi)))
    monkeypatch.setattr(interval_poly, "_UNIT", 0.0)
    lo, hi = centred()
    with pytest.raises(AssertionError, match="outside its bounds"):
        assert_sound(tree, {}, blo, bhi, rng, (lo, hi, np.isfinite(lo) & np.isfinite(hi)))


def test_a_twist_samples_fewer_leaves_with_its_quotients_centred(monkeypatch) -> None:
    """A twist draw at an odd grid in a shifted box: fewer leaves sampled with its quotients
    centred than without, the same kept, and the mesh the dense path's, bit for bit."""
    tree, box, shape = twist_case()
    assert_fewer_leaves_than_without(tree, box, shape, monkeypatch, interval_poly, "_quotient_of",
                                     lambda node, made, polys: None)  # fmt: skip
