"""The row table (:mod:`surfgen.generator.eval.row_calls`): one slot per heavy row operation, called through
a pointer; a slot called before its row is loaded loads it; a failed load gives NaN; the
interpreter loads the rows of equation (13) with itself."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from surfgen.generator.elementary import REGISTRY
from surfgen.generator.eval import row_calls as far
from surfgen.generator.eval import row_functions as row_table
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.interpreter import rows_called
from surfgen.generator.eval.tape import points_program, rows_program
from surfgen.generator.model.equation13 import (
    TRANSFORMS,
    Factor,
    PowerFunction,
    PowerTerm,
    Transform,
)


@njit
def _call(slot, W, d, a, b, s, n, consts, base):
    far.far_row(slot, W, d, a, b, s, n, consts, base)


def test_the_slots_are_numbered_in_table_order():
    assert list(far.SLOT) == list(far.ROWS)
    assert [far.SLOT[name] for name in far.ROWS] == list(range(len(far.ROWS)))
    assert len(set(far.ROWS)) == len(far.ROWS)


def test_each_slot_runs_its_row_with_its_operands():
    row_table.load_rows()
    x = np.linspace(-3.0, 3.0, 37)
    W = np.zeros((4, 40))
    W[1, :37], W[2, :37] = x, x[::-1] + 0.25
    consts = np.zeros(1)
    cases = {
        "cos": (REGISTRY["cos"].array(x), 1, 0, 0.0),
        "atan2_vv": (REGISTRY["atan2"].array(x, x[::-1] + 0.25), 1, 2, 0.0),
        "atan2_vs": (REGISTRY["atan2"].array(x, 0.5), 1, 0, 0.5),
        "atan2_sv": (REGISTRY["atan2"].array(0.5, x[::-1] + 0.25), 0, 2, 0.5),
    }
    for name, (want, a, b, s) in cases.items():
        W[3] = 7.0
        _call(far.SLOT[name], W, 3, a, b, s, 37, consts, 0)
        assert np.array_equal(W[3, :37], want), name
        assert np.all(W[3, 37:] == 7.0), name  # n values, no more
        assert far.target(far.SLOT[name]) == row_table.COMPILED[name].address


def test_far_row_takes_c_contiguous_float64_arrays_only():
    W, consts = np.zeros((2, 4)), np.zeros(1)
    with pytest.raises(TypingError, match="C-contiguous"):
        _call(0, W[:, ::2], 0, 1, 0, 0.0, 2, consts, 0)
    with pytest.raises(TypingError, match="float64"):
        _call(0, W.astype(np.float32), 0, 1, 0, 0.0, 2, consts, 0)
    with pytest.raises(TypingError, match="float operand"):
        _call(0, W, 0, 1, 0, 1, 2, consts, 0)


def test_a_failed_load_gives_nan_in_the_destination_row(monkeypatch):
    row_table.load_rows()
    slot = far.SLOT["tan"]
    compiled = far.target(slot)

    def broken(names):
        raise MemoryError("no room for the rows")

    monkeypatch.setattr(far, "_load_rows", broken)
    W = np.ones((3, 8))
    try:
        far.fill(slot, far.first_call(slot))  # as before any load
        _call(slot, W, 2, 0, 0, 0.0, 8, np.zeros(1), 0)
    finally:
        far.fill(slot, compiled)
    assert np.isnan(W[2]).all()
    assert (W[:2] == 1.0).all()  # no other row touched


CALLED_FIRST = """
import numpy as np
from numba import njit
from surfgen.generator.eval import row_calls as far, row_functions as row_table
from surfgen.generator.elementary import REGISTRY

@njit(cache=False)
def call(slot, W, consts):
    far.far_row(slot, W, 1, 0, 0, 0.0, 5, consts, 0)

slot = far.SLOT["sinh"]
assert far.target(slot) == far.first_call(slot) and not row_table.COMPILED
W = np.zeros((2, 5))
W[0] = np.linspace(0.1, 2.0, 5)
call(slot, W, np.zeros(1))
print(sorted(row_table.COMPILED), far.target(slot) == row_table.COMPILED["sinh"].address,
      np.array_equal(W[1], REGISTRY["sinh"].array(W[0])))
"""


def test_a_slot_called_before_its_row_is_loaded_loads_it_alone():
    out = subprocess.run(
        [sys.executable, "-c", CALLED_FIRST], capture_output=True, text=True, timeout=600
    )
    assert out.stdout.split() == ["['sinh']", "True", "True"], out.stderr[-2000:]


WITH_THE_INTERPRETER = """
from surfgen.generator.eval import interpreter, row_functions as row_table
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.parser import parse

interpreter.load_interpreter()
print(",".join(sorted(row_table.COMPILED)))
grid = Grid(Box.cube(1.0), (5, 5, 5))
fast = evaluate(parse("cosh(x) + atan2(y, z) - exp(z)"), grid, evaluator="fast").values
reference = evaluate(parse("cosh(x) + atan2(y, z) - exp(z)"), grid, evaluator="reference").values
print(",".join(sorted(row_table.COMPILED)), (fast == reference).all())
"""


def test_the_interpreter_loads_the_rows_of_equation_13_and_the_others_load_when_called():
    out = subprocess.run(
        [sys.executable, "-c", WITH_THE_INTERPRETER], capture_output=True, text=True, timeout=600
    )
    first, then, same = out.stdout.split()
    assert first.split(",") == sorted(far.EQUATION_13_ROWS), out.stderr[-2000:]
    assert set(then.split(",")) == {*far.EQUATION_13_ROWS, "cosh", "atan2_vv", "exp"}
    assert same == "True"


_PARAMS = {"r": 0.8, "p": 3.0, "h": 0.5, "t": 0.3}


def _factor(h: str, g: str, flags: tuple[bool, ...]) -> Factor:
    """A factor of eq. (13) with H = ``h``, G = ``g``: real exponents everywhere, x, y and z."""
    power = PowerFunction((PowerTerm(1.3, 1.5, 0.0, 2.0), PowerTerm(-0.7, 0.0, 3.0, 0.5)))
    plain = PowerFunction((PowerTerm(0.9, 1.0, 1.0, 0.0), PowerTerm(0.4, 0.0, 0.0, 1.0)), True)
    return Factor(
        powers=(power, plain) * 4,
        lambdas=(1.5, 1.0, 0.7, 2.0, 1.3, 0.5, 1.0, 2.5),
        mus=(1.0, 2.0, 1.5, 0.5),
        h=Transform(h, tuple(_PARAMS[k] for k in TRANSFORMS[h])),
        g=Transform(g, tuple(_PARAMS[k] for k in TRANSFORMS[g])),
        absolute=flags,
    )


def test_the_rows_of_equation_13_are_the_rows_its_vocabulary_calls():
    # every H and G of the paper, with and without |.|: what the sampler's formulas can call,
    # and so what the interpreter loads with itself (a row left out would be compiled by
    # every worker inside a shape's timeout; one too many, by every first run for nothing)
    called: set[str] = set()
    for h in TRANSFORMS:
        for g in TRANSFORMS:
            for flags in ((False,) * 6, (True, False) * 3):
                program = compile_tree(_factor(h, g, flags).to_tree())
                called |= rows_called(program.code)  # on a grid
                called |= rows_called(rows_program(program)[0])  # in tiles of rows
                called |= rows_called(points_program(program)[0])  # at points (the walls)
    assert called == set(far.EQUATION_13_ROWS)
