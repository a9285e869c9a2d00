"""The rows behind the table (:mod:`surfgen.generator.eval.row_functions`): one C function per slot, each
giving its numpy twin's bits; the interpreter sends every heavy operation there and carries none
of their code."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from surfgen.generator.elementary import REGISTRY, power, round_trip
from surfgen.generator.eval import interpreter
from surfgen.generator.eval import row_calls as far
from surfgen.generator.eval import row_functions as row_table
from surfgen.generator.eval.opcodes import OP

# Hard arguments: zeros, tiny, huge, near the jumps of the round trips, specials.
_HARD = [0.0, -0.0, 1e-310, -1e-300, 0.5, -0.75, 1.0, -1.0, 1.5707963267948966, 3.141592653589793]
_HARD += [2.0, -7.5, 40.0, 710.0, -745.5, 1e22, -1e300, np.inf, -np.inf, np.nan]


def _args() -> np.ndarray:
    rng = np.random.default_rng(3)
    x = np.concatenate([_HARD, rng.uniform(-4.0, 4.0, 300), rng.standard_cauchy(100) * 50])
    return x.astype(np.float64)


@njit
def _call(slot, W, d, a, b, s, n, consts, base):
    far.far_row(slot, W, d, a, b, s, n, consts, base)


def _run(name: str, a_row: np.ndarray, b_row: np.ndarray | None = None, s: float = 0.0):
    """Slot ``name`` on row 0 (and row 1) of a register file, into row 2."""
    n = a_row.size
    W = np.zeros((3, n + 3))
    W[0, :n] = a_row
    if b_row is not None:
        W[1, :n] = b_row
    row_table.load_rows()
    _call(far.SLOT[name], W, 2, 0, 1, s, n, np.zeros(1), 0)
    return W[2, :n]


def _same(got: np.ndarray, want: np.ndarray) -> bool:
    return np.array_equal(got, want, equal_nan=True)


def test_every_slot_has_its_c_function_and_points_to_it_once_loaded():
    assert set(row_table.FUNCTIONS) == set(far.ROWS)
    compiled = row_table.load_rows()
    assert row_table.rows_loaded()
    for name in far.ROWS:
        slot = far.SLOT[name]
        assert far.target(slot) == compiled[name].address != far.first_call(slot), name


def test_every_elementary_function_and_round_trip_has_a_slot():
    for name, e in REGISTRY.items():
        names = [name] if e.arity == 1 else [f"{name}_{m}" for m in ("vv", "vs", "sv")]
        assert set(names) <= set(far.ROWS), name
    rest = ["atantan", "asinsin", "acoscos", "acotcot", "series", "segsum", "sec", "csc", "cot"]
    for name in rest:
        assert interpreter._UNARY_SLOT[OP[name]] == far.SLOT[name]
    unary = [name for name, e in REGISTRY.items() if e.arity == 1]
    assert all(interpreter._UNARY_SLOT[OP[name]] == far.SLOT[name] for name in unary)
    slotted = {int(s) for s in interpreter._UNARY_SLOT if s >= 0}
    assert slotted == {far.SLOT[name] for name in unary + rest}


def test_each_unary_slot_gives_the_numpy_twins_bits():
    x = _args()
    for name, e in REGISTRY.items():
        if e.arity == 1:
            with np.errstate(all="ignore"):
                assert _same(_run(name, x), e.array(x)), name
    for name in ("atantan", "asinsin", "acoscos", "acotcot"):
        with np.errstate(all="ignore"):
            assert _same(_run(name, x), round_trip(name, x)), name


@pytest.mark.parametrize("name, function", [("sec", "cos"), ("csc", "sin"), ("cot", "tan")])
def test_the_fused_reciprocals_give_the_bits_of_the_function_then_one_over(name, function):
    # the slow lanes (|u| > 2**23: Payne-Hanek) included, in rows of every length
    rng = np.random.default_rng(4)
    huge = rng.uniform(2.0**23, 1e300, 40) * rng.choice([-1.0, 1.0], 40)
    x = np.concatenate([_args(), huge, [2.0**23, np.nextafter(2.0**23, np.inf), 5e-324]])

    def bits(got, want):  # signed zeros and infinities told apart; NaN is NaN
        nan = np.isnan(want)
        return np.array_equal(np.isnan(got), nan) and np.array_equal(
            got[~nan].view(np.int64), want[~nan].view(np.int64)
        )

    with np.errstate(all="ignore"):
        want = 1.0 / REGISTRY[function].array(x)
    assert bits(_run(name, x), want), name
    for n in (1, 7, 8, 9, 64):
        part = rng.permutation(x)[:n]
        with np.errstate(all="ignore"):
            assert bits(_run(name, part), 1.0 / REGISTRY[function].array(part)), (name, n)
    zeros = _run(name, np.array([0.0, -0.0]))
    assert list(zeros) == ([1.0, 1.0] if name == "sec" else [np.inf, -np.inf])


def test_the_binary_slots_give_the_numpy_twins_bits_in_every_operand_mode():
    x = _args()
    y = np.roll(x, 7)
    with np.errstate(all="ignore"):
        for s in (0.5, -1.0, 2.0, 0.0, 3.7, -2.5):  # the x^c shortcuts among them
            assert _same(_run("pow_vs", np.abs(x), s=s), power(np.abs(x), s)), s
            assert _same(_run("pow_sv", x, y, s=abs(s)), power(abs(s), y))
            assert _same(_run("atan2_vs", x, s=s), REGISTRY["atan2"].array(x, s)), s
            assert _same(_run("atan2_sv", x, y, s=s), REGISTRY["atan2"].array(s, y)), s
        assert _same(_run("pow_vv", np.abs(x), y), power(np.abs(x), y))
        assert _same(_run("atan2_vv", x, y), REGISTRY["atan2"].array(x, y))


def test_the_interpreter_is_ready_only_with_its_rows(monkeypatch):
    interpreter.load_interpreter()  # compiled and cached, if it was not yet
    assert interpreter.interpreter_cached()
    monkeypatch.setattr(interpreter, "rows_cached", lambda names: False)
    assert not interpreter.interpreter_cached()


def test_run_calls_a_row_from_python_and_refuses_what_could_write_out_of_bounds():
    x = _args()
    W = np.zeros((2, x.size))
    W[0] = x
    row_table.run("tan", W, 1, 0, x.size)
    with np.errstate(all="ignore"):
        assert _same(W[1], REGISTRY["tan"].array(x))
    bad = [
        (("nope", W, 1, 0, 4), "unknown row 'nope'"),
        (("series", W, 1, 0, 4), "unknown row 'series'"),  # needs the interpreter's constants
        (("tan", np.zeros((2, 4), np.float32), 1, 0, 4), "float64"),
        (("tan", W[:, ::2], 1, 0, 4), "C-contiguous"),
        (("tan", W, 2, 0, 4), r"rows d, a, b must be in \[0, 2\)"),
        (("tan", W, 1, -1, 4), "rows d, a, b"),
        (("tan", W, 1, 0, x.size + 1), "n in"),
    ]
    for args, message in bad:
        with pytest.raises(ValueError, match=message):
            row_table.run(*args)
    with pytest.raises(ValueError, match="rows d, a, b"):
        row_table.run("atan2_vv", W, 1, 0, 4, b=5)
