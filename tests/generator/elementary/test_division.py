"""A row divided by one scalar with FMAs (generator/elementary/division.py) gives the bits of
IEEE division (numpy's ``/``) for every dividend and divisor, the hard cases included."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.generator.elementary import division as D
from tests.support.division_cases import midpoint_row

DIV = D.div_row_by_scalar_call


def _divide(x: np.ndarray, s: float, in_place: bool = False, fast: bool | None = None):
    """x / s through the row function, on a register file of two rows (source 1, dest 0);
    ``fast``: whether the FMA path must (True) or must not (False) be the one that ran."""
    n = x.size
    W = np.full((2, n), 7.0)
    W[1] = x
    if in_place:
        took = DIV(W, 1, 1, s, n)
        got = W[1].copy()
    else:
        took = DIV(W, 0, 1, s, n)
        assert np.array_equal(W[1].view(np.uint64), x.view(np.uint64))  # the source is intact
        got = W[0].copy()
    if fast is not None:
        assert took == fast, f"the {'FMA' if fast else 'plain'} path did not run"
    return got


def _inside(x: np.ndarray) -> np.ndarray:
    ax = np.abs(x)
    return x[(ax == 0) | ((ax >= D.X_MIN) & (ax <= D.X_MAX))]


def _assert_bits(x: np.ndarray, s: float, got: np.ndarray) -> None:
    with np.errstate(all="ignore"):
        want = x / s
    diff = got.view(np.uint64) != want.view(np.uint64)
    assert not diff.any(), f"{int(diff.sum())} of {x.size} differ, e.g. {x[diff][:3]!r} / {s!r}"


def test_the_fast_path_is_the_one_the_interpreter_takes_on_these_machines():
    # every CPU of this project (AMD EPYC with AVX2, Intel Xeon and AMD Zen 5 with AVX-512) has
    # FMA: the interpreter's x / s goes through div_row_by_scalar there
    assert D.ROW_DIVISION


def test_random_quotients_over_the_whole_exponent_range():
    rng = np.random.default_rng(1)
    n = 1 << 16
    for _ in range(40):
        x = _inside(rng.standard_normal(n) * np.exp2(rng.integers(-900, 901, n)))
        s = float(rng.uniform(-2, 2) * 2.0 ** rng.integers(-99, 100))
        _assert_bits(x, s, _divide(x, s, fast=True))
        x[x.size // 2] = 2.0 * D.X_MAX  # one value out of the fast range: the whole row plain
        _assert_bits(x, s, _divide(x, s, fast=False))


def test_random_bit_patterns():
    rng = np.random.default_rng(2)
    n = 4096
    for _ in range(50):
        s = float(rng.integers(0, 1 << 64, 1, dtype=np.uint64).view(np.float64)[0])
        x = rng.integers(0, 1 << 64, n, dtype=np.uint64).view(np.float64)
        _assert_bits(x, s, _divide(x, s, fast=False))  # some value is out of the fast range
        s_inside = D.S_MIN <= abs(s) <= D.S_MAX
        _assert_bits(_inside(x), s, _divide(_inside(x), s, fast=s_inside))


def _near_midpoints(count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Dividends X and divisors S (53-bit odd integers) whose exact quotient lies within
    |t|/S of an ulp, t = +-1, +-3, of a rounding midpoint: X*2**54 = S*M + t, M odd (54 bits).
    Then X/S = (M + t/S) / 2**54 and M is the midpoint of two 53-bit quotients: the hardest
    cases there are for rounding a quotient (a division that rounds the wrong way fails here)."""
    rng = np.random.default_rng(seed)
    xs, ss = [], []
    while len(xs) < count:
        S = int(rng.integers(1 << 52, 1 << 53)) | 1
        t = int(rng.choice([-3, -1, 1, 3]))
        M = (-t * pow(S, -1, 1 << 54)) % (1 << 54)
        if M < (1 << 53) or M % 2 == 0:
            continue
        num = S * M + t
        assert num % (1 << 54) == 0
        X = num >> 54
        if (1 << 52) <= X < (1 << 53):
            xs.append(float(X))
            ss.append(float(S))
    return np.array(xs), np.array(ss)


def test_quotients_next_to_a_rounding_midpoint():
    X, S = _near_midpoints(3000, seed=3)
    rng = np.random.default_rng(4)
    for shift_x, shift_s, sign in [(0, 0, 1.0), (-700, 40, -1.0), (800, -90, 1.0), (-60, 99, -1.0)]:
        x = np.ldexp(X, shift_x) * sign
        for s0 in S[rng.choice(S.size, 5, replace=False)]:
            s = float(np.ldexp(s0, shift_s - 52))
            _assert_bits(x, s, _divide(x, s, fast=True))
        # each dividend with its own divisor (the hard pairs): one row per pair
        for xi, si in zip(x[:300], S[:300], strict=True):
            s = float(np.ldexp(si, shift_s - 52))
            row = np.array([xi, -xi, 0.5 * xi])
            _assert_bits(row, s, _divide(row, s, fast=True))


def test_rows_of_quotients_next_to_a_midpoint_with_their_own_divisor():
    rng = np.random.default_rng(8)
    cases = 0
    for _ in range(400):
        row = midpoint_row(rng)
        if row is not None:
            x, s = row
            _assert_bits(x, s, _divide(x, s, fast=True))
            cases += x.size
    assert cases > 5000


def test_exact_quotients_and_signed_zeros():
    rng = np.random.default_rng(5)
    q = rng.integers(-(1 << 20), 1 << 20, 5000).astype(np.float64)
    for s in (3.0, -5.0, 0.375, 1.0, -1.0, 2.0**-100, 2.0**100, 7.0 * 2.0**60):
        x = q * s  # exact: short significands
        got = _divide(x, s, fast=True)
        _assert_bits(x, s, got)
        assert np.array_equal(got, q)
    for s in (2.5, -2.5):
        x = np.array([0.0, -0.0, 0.0, 1.0, -0.0])
        _assert_bits(x, s, _divide(x, s, fast=True))


@pytest.mark.parametrize(
    "s",
    [
        0.0,
        -0.0,
        np.inf,
        -np.inf,
        np.nan,
        5e-324,
        -1e-310,
        2.0**-100,
        -(2.0**-100),
        np.nextafter(2.0**-100, 0),
        2.0**100,
        np.nextafter(2.0**100, np.inf),
        1e300,
        -3.0,
    ],
)
def test_every_special_value_and_the_range_bounds(s):
    specials = [0.0, -0.0, np.inf, -np.inf, np.nan, 5e-324, -2.2e-308, 1e-300, -1e300, 1.7e308]
    bounds = [D.X_MIN, D.X_MAX, np.nextafter(D.X_MIN, 0), np.nextafter(D.X_MAX, np.inf)]
    bounds += [np.nextafter(D.X_MIN, 1), np.nextafter(D.X_MAX, 0)]
    plain = np.random.default_rng(6).standard_normal(61)
    s_inside = bool(D.S_MIN <= abs(s) <= D.S_MAX)
    for odd in specials + bounds:
        x = plain.copy()
        x[17] = odd  # one odd value sends its whole row to the plain division
        fast = s_inside and bool(odd == 0 or D.X_MIN <= abs(odd) <= D.X_MAX)
        _assert_bits(x, s, _divide(x, s, fast=fast))
    x = np.array(bounds + [-b for b in bounds] + [1.0, -0.0])
    _assert_bits(x, s, _divide(x, s, fast=False))
    _assert_bits(_inside(x), s, _divide(_inside(x), s, fast=s_inside))


def test_in_place_and_short_rows():
    rng = np.random.default_rng(7)
    for n in (0, 1, 3, 8, 9, 1023, 1024):
        x = rng.standard_normal(n) * 1e5
        _assert_bits(x, 0.7, _divide(x, 0.7, fast=True))
        _assert_bits(x, 0.7, _divide(x, 0.7, in_place=True, fast=False))
