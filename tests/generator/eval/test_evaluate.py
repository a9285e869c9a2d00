"""The evaluator interface (:mod:`surfgen.generator.eval.evaluate`): one registry, the same values
from every evaluator, and the fast evaluator's other operations."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.generator.errors import FormulaError
from surfgen.generator.eval import evaluate as ev
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.parser import parse

FORMULA = "x^2 + y^2 + z^2 - 1 + 0.02*tan(2*x + 0.3) + a*sin(x*y*z)"
PARAMS = {"a": 0.5}


def _tree():
    return parse(FORMULA, PARAMS.keys())


def test_the_registry_names_every_evaluator() -> None:
    assert list(ev.EVALUATORS) == ["fast", "reference", "sparse"]
    with pytest.raises(
        FormulaError, match=r"unknown evaluator 'dense' \(allowed: fast, reference, sparse\)"
    ):
        ev.evaluate(_tree(), Grid(Box.cube(1.0), (4, 4, 4)), PARAMS, evaluator="dense")
    with pytest.raises(FormulaError, match="unknown evaluator 'nope'"):
        ev.evaluate_points(_tree(), 0.0, 0.0, 0.0, PARAMS, evaluator="nope")


def test_every_evaluator_gives_the_same_bits_on_a_grid_and_at_points() -> None:
    grid = Grid(Box.cube(1.3), (9, 7, 11))
    fields = {name: ev.evaluate(_tree(), grid, PARAMS, name, threads=1) for name in ev.EVALUATORS}
    assert np.array_equal(fields["fast"].values, fields["reference"].values, equal_nan=True)
    compiled = ev.evaluate_compiled(compile_tree(_tree(), PARAMS), grid, threads=1)
    assert np.array_equal(compiled.values, fields["fast"].values, equal_nan=True)
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-2, 2, (2, 50))
    z = 0.25  # broadcast with the others
    at = {n: ev.evaluate_points(_tree(), x, y, z, PARAMS, evaluator=n) for n in ev.EVALUATORS}
    assert at["fast"].shape == (50,)
    assert np.array_equal(at["fast"], at["reference"], equal_nan=True)
    points = ev.points_evaluator(_tree(), PARAMS)
    assert np.array_equal(points(x, y, np.full(50, z)), at["fast"], equal_nan=True)


def test_the_fast_evaluators_warm_up_operations() -> None:
    assert ev.warm_interpreter() >= 0.0
    assert isinstance(ev.interpreter_cached(), bool)
    assert hasattr(ev.grid_kernel(), "signatures")  # a numba dispatcher
