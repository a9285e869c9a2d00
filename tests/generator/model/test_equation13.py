"""Equation (13): the model builds the paper's structure, serialises, and evaluates as written."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.generator.errors import SpecError
from surfgen.generator.eval.reference import evaluate_points
from surfgen.generator.formula.expr import to_string
from surfgen.generator.formula.parser import parse
from surfgen.generator.model.equation13 import (
    Equation13,
    Factor,
    PowerFunction,
    PowerTerm,
    Transform,
)
from surfgen.generator.model.sampler import SamplerConfig, choose_d, draw_equation


def P(*terms, absolute=False) -> PowerFunction:
    return PowerFunction(tuple(PowerTerm(*t) for t in terms), absolute)


def factor(**kw) -> Factor:
    base = dict(
        powers=(
            P((1, 2, 0, 0), (1, 0, 2, 0)),  # P1 = x^2 + y^2
            P((2, 0, 0, 1)),  # P2 = 2 z
            P((1, 1, 0, 0)),  # P3 = x
            P((1, 0, 1, 0)),  # P4 = y
            P((1, 0, 0, 1)),  # P5 = z
            P((1, 0.5, 0, 0), absolute=True),  # P6 = |x|^0.5
            P((3, 0, 0, 0)),  # P7 = 3
            P((1, 0, 0, 0)),  # P8 = 1
        ),
        lambdas=(1, 2, 1, 1, 2, 1, 1, 1),
        mus=(2, 1, 3, 1),
        h=Transform("tan"),
        g=Transform("atan"),
        absolute=(False, True, False, False, False, True),
    )
    base.update(kw)
    return Factor(**base)


def direct(x, y, z):
    """The same factor written by hand from equations (13)-(16)."""
    A = x**2 + y**2
    D = (2 * z) ** 2
    B = np.abs(np.tan(x) ** 2)
    E = np.tan(y)
    C = np.arctan(np.tan(z**2 / np.abs(x) ** 0.5)) ** 3
    F = np.abs(np.arctan(np.tan(3.0)))
    return A / D * (B / E) * (C / F)


def test_factor_tree_evaluates_as_the_paper_writes_it() -> None:
    rng = np.random.default_rng(0)
    x, y, z = rng.uniform(-2, 2, (3, 500))
    eq = Equation13(((factor(),),), d=0.25)
    got = evaluate_points(eq.to_tree(), x, y, z)
    with np.errstate(all="ignore"):
        want = direct(x, y, z) - 0.25
    np.testing.assert_allclose(got, want, rtol=1e-12)


def test_sum_of_products_and_d() -> None:
    f = factor()
    eq = Equation13(((f, f), (f,)), d=-1.5)
    text = to_string(eq.to_tree())
    assert text.endswith("+1.5")
    rng = np.random.default_rng(1)
    x, y, z = rng.uniform(-2, 2, (3, 200))
    with np.errstate(all="ignore"):
        one = direct(x, y, z)
        np.testing.assert_allclose(
            evaluate_points(eq.to_tree(), x, y, z), one * one + one + 1.5, rtol=1e-12
        )


def test_printed_formula_parses_back_to_the_same_tree() -> None:
    tree = Equation13(((factor(),),), d=2).to_tree()
    assert parse(to_string(tree)) == tree
    assert "atan(tan(" in to_string(tree)  # G(H(.)), pasteable into K3DSurf/MathMod


def test_json_round_trip() -> None:
    eq = Equation13(((factor(h=Transform("saw2", (1.5,))),),), d=0.5)
    assert Equation13.from_dict(eq.to_dict()) == eq


def test_omitted_elements_are_exactly_one() -> None:
    f = factor(mus=(0, 0, 0, 0), lambdas=(1, 0, 1, 1, 1, 1, 1, 1))
    assert to_string(f.to_tree()) == "x^2+y^2"


def test_model_validation() -> None:
    with pytest.raises(SpecError, match="unknown transform 'foo'"):
        Transform("foo")
    with pytest.raises(SpecError, match="saw2 takes 1 parameter"):
        Transform("saw2")
    with pytest.raises(SpecError, match="needs 8 powers"):
        factor(powers=(P((1, 0, 0, 0)),))
    with pytest.raises(SpecError, match="finite"):
        PowerTerm(float("nan"))


def test_sampler_draws_are_reproducible_and_cut_the_box() -> None:
    cfg = SamplerConfig()
    draws = [draw_equation(7, i, cfg) for i in range(12)]
    assert draws == [draw_equation(7, i, cfg) for i in range(12)]
    assert len({to_string(d.equation.to_tree()) for d in draws}) == 12
    cut = 0
    for d in draws:
        value = choose_d(d, cfg, evaluator="reference")
        if value is None:
            continue
        from surfgen.generator.eval.grid import Grid
        from surfgen.generator.eval.reference import evaluate_reference

        v = evaluate_reference(
            d.equation.with_d(value).to_tree(), Grid(d.box, (cfg.d_grid,) * 3)
        ).values
        cut += bool((v < 0).any() and (v > 0).any())
    assert cut >= 10  # choosing d at a quantile makes the surface cross the box


def test_trees_are_built_once_and_not_shipped() -> None:
    import pickle
    from dataclasses import fields

    f = factor()
    assert f.to_tree() is f.to_tree()
    p3 = PowerFunction((PowerTerm(2.0, 2.0, 1.0), PowerTerm(-0.5, 0.0, 0.0, 3.0)), True)
    assert to_string(p3.to_tree()) == "2*abs(x)^2*abs(y)-0.5*abs(z)^3"
    assert p3.to_tree() is p3.to_tree()
    assert dict(f.h_arguments())["B"] is dict(f.h_arguments())["B"]  # P3^l3 kept
    for kept in (f, p3):
        copy = pickle.loads(pickle.dumps(kept))
        assert copy == kept and set(copy.__dict__) == {f.name for f in fields(kept)}
        assert copy.to_tree() == kept.to_tree() and copy.to_tree() is not kept.to_tree()


def test_a_power_term_holds_floats_and_names_its_first_bad_number() -> None:
    t = PowerTerm(2, 1, 0, 3)
    assert (t.a, t.b, t.c, t.d) == (2.0, 1.0, 0.0, 3.0)
    assert all(type(v) is float for v in (t.a, t.b, t.c, t.d))
    with pytest.raises(SpecError, match="power term c must be a finite number, got inf"):
        PowerTerm(1.0, 2.0, float("inf"), float("nan"))
    with pytest.raises(SpecError, match="power term a must be a finite number, got nan"):
        PowerTerm(float("nan"), 2.0, 0.0, float("inf"))
