"""The row table (:mod:`surfgen.generator.eval.row_calls`): one slot per heavy row operation, called through
a pointer; a slot called before the rows are loaded loads them; a failed load gives NaN."""

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

    def broken():
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

slot = far.SLOT["sin"]
assert far.target(slot) == far.first_call(slot) and not row_table.rows_loaded()
W = np.zeros((2, 5))
W[0] = np.linspace(0.1, 2.0, 5)
call(slot, W, np.zeros(1))
print(row_table.rows_loaded(), far.target(slot) == row_table.COMPILED["sin"].address,
      np.array_equal(W[1], REGISTRY["sin"].array(W[0])))
"""


def test_a_slot_called_before_the_rows_are_loaded_loads_them():
    out = subprocess.run(
        [sys.executable, "-c", CALLED_FIRST], capture_output=True, text=True, timeout=600
    )
    assert out.stdout.split() == ["True", "True", "True"], out.stderr[-2000:]
