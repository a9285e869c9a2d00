"""The registry of elementary functions and the closed-form round trips (integration level: the
accuracy of each function is tested next to its implementation)."""

from __future__ import annotations

import functools
import re

import mpmath
import numpy as np
import pytest

from surfgen.generator import elementary as E
from surfgen.generator.elementary import roundtrip as R
from surfgen.generator.eval import row_functions as row_table
from surfgen.generator.eval.opcodes import OPCODES
from surfgen.generator.formula.functions import FUNCTIONS

TRANSCENDENTAL = "sin cos tan asin acos atan atan2 sinh cosh tanh asinh acosh atanh exp log log10"
TRANSCENDENTAL += " cbrt pow"

SPECIAL = [0.0, -0.0, np.inf, -np.inf, np.nan, 1.0, -1.0, 0.5, -0.5, 2.0, 5e-324, -5e-324]
SPECIAL += [2.2250738585072014e-308, 1e-300, 1e300, -1e300, np.pi, -np.pi, np.pi / 2, 710.0]


def _arguments(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    scale = 10.0 ** rng.uniform(-12, 12, n)
    u = np.concatenate(
        [rng.uniform(-1, 1, n), rng.uniform(-10, 10, n), rng.normal(size=n) * scale, SPECIAL]
    )
    k = np.arange(1.0, 200.0)
    return np.concatenate([u, k * np.pi / 2, -k * np.pi / 2, np.nextafter(k * np.pi, 0)])


def _same(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (a.view(np.int64) == b.view(np.int64)) | (np.isnan(a) & np.isnan(b))


def test_the_registry_covers_every_transcendental_of_the_language():
    assert set(E.UNARY) | set(E.BINARY) == set(TRANSCENDENTAL.split())
    for name in E.UNARY + E.BINARY:
        if name != "pow":
            assert name in FUNCTIONS and name in OPCODES
        entry = E.REGISTRY[name]
        assert entry.arity == (2 if name in E.BINARY else 1)
        rows = (entry.row_vv, entry.row_vs, entry.row_sv) if entry.arity == 2 else (entry.row,)
        assert all(callable(r) for r in rows)


@pytest.mark.parametrize("name", E.UNARY)
def test_unary_row_scalar_and_numpy_twin_agree_bit_for_bit(name):
    u = _arguments(3000)
    entry = E.REGISTRY[name]
    W = np.zeros((3, u.size))
    W[0] = u
    row_table.run(name, W, 2, 0, u.size)  # the row's C function, as the interpreter calls it
    with np.errstate(all="ignore"):
        twin = entry.array(u)
    scalar = np.array([entry.scalar(v) for v in u])
    assert _same(W[2], twin).all() and _same(scalar, twin).all()
    assert _same(E.call(name, u), twin).all()


def _table_vv(slot, W, d, a, b, n):
    row_table.run(slot, W, d, a, n, b=b)


def _table_vs(slot, W, d, a, s, n):
    row_table.run(slot, W, d, a, n, s=s)


def _table_sv(slot, W, d, s, b, n):
    row_table.run(slot, W, d, 0, n, b=b, s=s)


@pytest.mark.parametrize("name", E.BINARY)
def test_binary_rows_in_every_mode_agree_with_the_numpy_twin(name):
    rng = np.random.default_rng(1)
    a = _arguments(500)
    b = rng.permutation(
        np.concatenate([a[: a.size - 8], [2.0, 0.5, -1.0, 3.0, -3.0, 0.0, 1.0, 7.0]])
    )
    entry = E.REGISTRY[name]
    W = np.zeros((3, a.size))
    W[0], W[1] = a, b
    if name == "atan2":  # the rows' C functions, as the interpreter calls them
        vv = functools.partial(_table_vv, "atan2_vv")
        vs = functools.partial(_table_vs, "atan2_vs")
        sv = functools.partial(_table_sv, "atan2_sv")
    else:  # pow's own rows: the table's apply the x^c convention on top (test_row_table.py)
        vv, vs, sv = entry.row_vv, entry.row_vs, entry.row_sv
    with np.errstate(all="ignore"):
        vv(W, 2, 0, 1, a.size)
        assert _same(W[2], entry.array(a, b)).all()
        for s in (2.0, -1.5, 0.0, np.nan, 3.0):
            vs(W, 2, 0, s, a.size)
            assert _same(W[2], entry.array(a, s)).all()
            sv(W, 2, s, 1, a.size)
            assert _same(W[2], entry.array(s, b)).all()
        scalar = np.array([entry.scalar(p, q) for p, q in zip(a, b, strict=True)])
    assert _same(scalar, entry.array(a, b)).all()


def test_power_shortcuts_are_applied_per_element():
    u = np.array([-0.0, -np.inf, 4.0, -2.0, 3.0, np.nan, 0.0])
    with np.errstate(all="ignore"):
        cases = [(2.0, u * u), (0.5, np.sqrt(u)), (-1.0, 1 / u), (1.0, u), (0.0, np.ones_like(u))]
    for e, want in cases:
        with np.errstate(all="ignore"):
            assert _same(E.power(u, e), want).all()
            assert _same(E.power(u, np.full_like(u, e)), want).all()  # varying exponent too
    assert np.signbit(E.power(-0.0, 0.5))  # sqrt(-0) = -0 (C pow would give +0)
    assert np.isnan(E.power(-np.inf, 0.5))
    assert _same(E.power(u, 3.0), E.REGISTRY["pow"].array(u, 3.0)).all()
    with E.numpy_ufuncs():
        assert E.using_numpy_ufuncs()
        assert not np.signbit(E.power(np.array([-0.0]), np.array([0.5]))[0])


# ----------------------------------------------------------------------------- round trips

_DIRECT = {name: E.REGISTRY[name].array for name in ("sin", "cos", "tan", "asin", "acos", "atan")}


def _round_trip_arguments() -> np.ndarray:
    rng = np.random.default_rng(7)
    k = np.arange(-400.0, 400.0)
    near = np.concatenate([k * np.pi / 2, np.nextafter(k * np.pi / 2, np.inf)])
    near = np.concatenate([near, np.nextafter(k * np.pi / 2, -np.inf), k * np.pi])
    big = rng.uniform(1e3, 1e15, 2000) * rng.choice([-1, 1], 2000)
    # Both sides of R.FAST (the vectorised reduction's end), jumps just below it included.
    kf = np.floor(R.FAST / np.pi) - np.arange(4.0)
    fast = np.concatenate([kf * np.pi, (kf + 0.5) * np.pi, [R.FAST, np.nextafter(R.FAST, np.inf)]])
    fast = np.concatenate([fast, -fast, np.nextafter(fast, 0.0)])
    return np.concatenate(
        [rng.uniform(-20, 20, 20000), near, big, fast, SPECIAL, [2.0**50, -(2.0**51)]]
    )


@pytest.mark.parametrize("name", R.ROUND_TRIPS)
def test_round_trip_row_scalar_and_twin_agree_bit_for_bit(name):
    u = _round_trip_arguments()
    W = np.zeros((2, u.size))
    W[0] = u
    R.ROWS[name](W, 1, 0, u.size)
    twin = E.round_trip(name, u)
    assert _same(W[1], twin).all()
    assert _same(np.array([R.SCALARS[name](v) for v in u]), twin).all()


def test_round_trip_conventions_at_zero_and_ranges():
    u = _round_trip_arguments()
    u = u[np.isfinite(u)]
    z = np.array([0.0, -0.0])
    assert list(np.signbit(E.round_trip("atantan", z))) == [False, True]
    assert list(np.signbit(E.round_trip("asinsin", z))) == [False, True]
    assert list(E.round_trip("acotcot", z)) == [0.0, 0.0]  # never pi: the jump's value
    assert not np.signbit(E.round_trip("acotcot", z)).any()
    assert list(E.round_trip("acoscos", z)) == [0.0, 0.0]
    for name, lo, hi, closed in [
        ("atantan", -np.pi / 2, np.pi / 2, False),
        ("asinsin", -np.pi / 2, np.pi / 2, True),
        ("acoscos", 0.0, np.pi, True),
        ("acotcot", 0.0, np.pi, False),
    ]:
        v = E.round_trip(name, u)
        assert (v >= lo).all() and ((v <= hi) if closed else (v < hi + 1e-15)).all(), name
    assert np.isnan(E.round_trip("atantan", np.array([np.inf, np.nan]))).all()


def _exact(name: str, v: float) -> mpmath.mpf:
    x = mpmath.mpf(v)
    k = mpmath.floor(x / mpmath.pi + mpmath.mpf(0.5))
    r = x - k * mpmath.pi
    odd = int(k) % 2 == 1
    if name == "atantan":
        return r
    if name == "asinsin":
        return -r if odd else r
    if name == "acoscos":
        return mpmath.pi - abs(r) if odd else abs(r)
    return r if r >= 0 else mpmath.pi + r


def _ulps(got: np.ndarray, args: np.ndarray, name: str) -> np.ndarray:
    out = []
    for g, v in zip(got, args, strict=True):
        t = _exact(name, float(v))
        ulp = float(np.spacing(abs(float(t)))) if t != 0 else 5e-324
        out.append(float(abs(mpmath.mpf(float(g)) - t)) / ulp)
    return np.array(out)


@pytest.mark.parametrize("name", R.ROUND_TRIPS)
def test_closed_forms_are_correctly_rounded_and_beat_the_direct_forms(name):
    mpmath.mp.dps = 50
    rng = np.random.default_rng(3)
    u = _round_trip_arguments()
    u = u[np.isfinite(u) & (np.abs(u) <= R.LIMIT)]
    u = rng.choice(u, 1500, replace=False)
    closed = _ulps(E.round_trip(name, u), u, name)
    with np.errstate(all="ignore"):
        direct = _ulps(R.direct_array(name, u, _DIRECT), u, name)
    assert closed.max() <= 0.501, f"{name}: {closed.max()} ulp"
    assert direct.max() > 1.0 and direct.mean() > closed.mean()
    big = np.abs(u) > 1e6  # large |u| too
    assert closed[big].max() <= 0.501 and direct[big].max() >= closed[big].max()


@pytest.mark.parametrize("name", R.ROUND_TRIPS)
def test_closed_forms_equal_the_direct_forms_away_from_the_jumps(name):
    # Margin: 2^-30 (relative to pi) around the jumps and kinks, where the direct form may land
    # on either side or loses digits; away from them the two agree within the direct form's
    # own conditioning: 16 eps / (distance to the nearest jump or kink).
    u = _round_trip_arguments()
    u = u[np.isfinite(u) & (np.abs(u) <= R.LIMIT)]
    closed = E.round_trip(name, u)
    with np.errstate(all="ignore"):
        direct = R.direct_array(name, u, _DIRECT)
    r = E.round_trip("atantan", u)  # u mod pi in [-pi/2, pi/2)
    to_jump = np.pi / 2 - np.abs(r)  # jumps of atan(tan), kinks of asin(sin)
    if name in ("acoscos", "acotcot"):
        to_jump = np.minimum(to_jump, np.abs(r))  # kinks of acos(cos), jumps of acot(cot)
    far = to_jump > 2.0**-30
    eps = 2.0**-52
    tol = 16 * eps * np.maximum(1.0, 1.0 / to_jump[far]) * max(1.0, np.pi)
    diff = np.abs(closed[far] - direct[far])
    assert far.mean() > 0.8  # a seventh of the arguments sit on jumps on purpose
    assert (diff <= tol).all(), f"{name}: {(diff > tol).sum()} differ, max {diff.max()}"


# ----------------------------------------------------------------------------- machine code


def test_round_trip_rows_vectorise_without_fused_multiply_add():
    # A fresh compile (numba cannot show the machine code of cached functions). An FMA would
    # round once where the numpy twin rounds twice; LLVM contracts nothing without fastmath.
    from numba import njit

    W = np.zeros((2, 8))
    for name in ("atantan", "acoscos"):
        fresh = njit(error_model="numpy")(R.ROWS[name].py_func)
        fresh(W, 1, 0, 8)
        asm = "\n".join(fresh.inspect_asm().values())
        assert re.search(r"\bv?mulpd\b", asm), f"{name}: no packed multiply, not vectorised"
        assert not re.search(r"\bv?f(n)?m(add|sub)\d", asm), f"{name}: FMA"
