"""surfgen's own exp/log/pow family: one result everywhere, accuracy, C99 special cases."""

from __future__ import annotations

import math
import os
import re

import mpmath as mp
import numpy as np
import pytest
from numba import njit

from surfgen.generator.elementary import explog as E
from surfgen.generator.elementary import explog_kernels as K

UNARY = ("exp", "log", "log10", "sinh", "cosh", "tanh", "asinh", "acosh", "atanh", "cbrt")
INF = math.inf
NAN = math.nan

SPECIAL = np.array(
    [
        0.0, -0.0, INF, -INF, NAN, -NAN, 5e-324, -5e-324, 1e-310, -1e-310,
        2.2250738585072014e-308, 2.225073858507201e-308, 1.0, -1.0, 0.5, -0.5, 2.0, 3.0, 8.0,
        27.0, 1000.0, 1e-8, 1.0 - 2.0**-53, 1.0 + 2.0**-52, 0.9999999, 1.0000001,
        709.782712893384, 709.7827128933841, 710.0, 710.4758600739439, 710.476, 711.0, 746.0,
        -708.3964185322641, -708.4, -745.1332191019411, -745.1332191019412, -744.44, -746.0,
        0.34657359027997264, -0.34657359027997264, 0.6931471805599453, 0.125, 0.5, 2.0**-28,
        2.0**28, 2.0**28 + 1, 19.0, 19.1, 20.0, 40.0, 1e300, -1e300, 1.7976931348623157e308,
        -1.7976931348623157e308, 0.9999999999999999, -0.9999999999999999, 1e-20, -1e-20,
    ]
)  # fmt: skip


def _bits(a) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).view(np.int64)


def _mixture(rng: np.random.Generator, n: int) -> np.ndarray:
    """Random scales, exact integers and halves, random bit patterns (every class), specials."""
    sign = rng.choice([-1.0, 1.0], n)
    parts = [
        rng.uniform(-1.0, 1.0, n),
        rng.uniform(-30.0, 30.0, n),
        sign * np.exp(rng.uniform(-745.0, 709.0, n)),
        np.round(rng.uniform(-64.0, 64.0, n) * 2.0) / 2.0,
        1.0 + rng.normal(0.0, 1e-9, n),
        rng.integers(-(2**63), 2**63 - 1, n, dtype=np.int64).view(np.float64),
        np.resize(SPECIAL, n),
    ]
    return np.concatenate(parts)


@njit(error_model="numpy")  # not cached: numba would not see changes in explog.py
def _scalar_loop(fn, x, out):
    for k in range(x.size):
        out[k] = fn(x[k])


@njit(error_model="numpy")  # not cached: numba would not see changes in explog.py
def _scalar_loop2(fn, x, y, out):
    for k in range(x.size):
        out[k] = fn(x[k], y[k])


@pytest.fixture(scope="module")
def args() -> np.ndarray:
    return _mixture(np.random.default_rng(20261201), 12_000)  # ~10^5 arguments


@pytest.mark.parametrize("name", UNARY)
def test_row_scalar_array_agree_bit_for_bit(name: str, args: np.ndarray) -> None:
    row, scalar, array = (getattr(E, f"{name}_{k}") for k in ("row", "scalar", "array"))
    n = args.size
    W = np.zeros((3, n))
    W[0] = args
    row(W, 1, 0, n)  # into another row
    W[2] = args
    row(W, 2, 2, n)  # in place
    out = np.empty(n)
    _scalar_loop(scalar, args, out)
    ref = array(args)
    assert ref.shape == args.shape and ref.dtype == np.float64
    for got in (W[1], W[2], out):
        assert np.array_equal(_bits(got), _bits(ref))
    # A scalar and an n-d array keep their shape.
    assert array(2.0).shape == () and array(args[:24].reshape(2, 3, 4)).shape == (2, 3, 4)
    # Every NaN is the canonical quiet NaN, whatever the input's payload.
    assert np.all(_bits(ref[np.isnan(ref)]) == _bits(np.nan))


def test_pow_rows_scalar_array_agree_bit_for_bit(args: np.ndarray) -> None:
    rng = np.random.default_rng(7)
    x = args
    y = np.concatenate(
        [
            rng.uniform(-4.0, 4.0, x.size // 2),
            np.resize(
                np.concatenate([SPECIAL, np.round(rng.uniform(-40, 40, 64))]), x.size - x.size // 2
            ),
        ]
    )
    rng.shuffle(y)
    n = x.size
    ref = E.pow_array(x, y)
    W = np.zeros((4, n))
    W[0], W[1] = x, y
    E.pow_row_vv(W, 2, 0, 1, n)
    assert np.array_equal(_bits(W[2]), _bits(ref))
    W[3] = x
    E.pow_row_vv(W, 3, 3, 1, n)  # d == a
    assert np.array_equal(_bits(W[3]), _bits(ref))
    W[3] = y
    E.pow_row_vv(W, 3, 0, 3, n)  # d == b
    assert np.array_equal(_bits(W[3]), _bits(ref))
    out = np.empty(n)
    _scalar_loop2(E.pow_scalar, x, y, out)
    assert np.array_equal(_bits(out), _bits(ref))
    for s in (2.5, -3.0, 0.5, 1e-300, -INF, NAN):
        E.pow_row_vs(W, 2, 0, s, n)
        assert np.array_equal(_bits(W[2]), _bits(E.pow_array(x, s)))
        E.pow_row_sv(W, 2, s, 1, n)
        assert np.array_equal(_bits(W[2]), _bits(E.pow_array(s, y)))
    assert E.pow_array(x[:12].reshape(3, 4), 2.0).shape == (3, 4)


@njit(error_model="numpy")  # not cached: numba would not see changes in explog.py
def _tape(W, n):
    """A few instructions the way the interpreter runs them on its register file."""
    E.exp_row(W, 1, 0, n)
    E.log_row(W, 2, 1, n)
    E.pow_row_vs(W, 3, 0, 2.5, n)
    E.pow_row_vv(W, 4, 1, 0, n)
    E.sinh_row(W, 5, 0, n)
    E.cbrt_row(W, 5, 5, n)
    E.tanh_row(W, 6, 0, n)
    E.log10_row(W, 7, 1, n)


def test_rows_run_inside_a_numba_interpreter() -> None:
    x = np.linspace(-3.0, 3.0, 301)
    W = np.zeros((8, 320))
    W[0, :301] = x
    _tape(W, 301)
    expect = [
        E.exp_array(x),
        E.log_array(E.exp_array(x)),
        E.pow_array(x, 2.5),
        E.pow_array(E.exp_array(x), x),
        E.cbrt_array(E.sinh_array(x)),
        E.tanh_array(x),
        E.log10_array(E.exp_array(x)),
    ]
    for row, want in enumerate(expect, start=1):
        assert np.array_equal(_bits(W[row, :301]), _bits(want))
    assert np.all(W[1:, 301:] == 0.0)  # nothing beyond n is written


# ----------------------------------------------------------------------------- accuracy

mp.mp.dps = 40
_MAX = mp.mpf(2) ** 1024 * (1 - mp.mpf(2) ** -54)  # anything at least this rounds to inf


def _ulps(got: float, ref) -> float:
    """|got - ref| in units of the last place of the true value ref (an mpf)."""
    if mp.isnan(ref):
        return 0.0 if math.isnan(got) else math.inf
    if mp.isinf(ref) or abs(ref) >= _MAX:
        return 0.0 if got == (INF if ref > 0 else -INF) else math.inf
    if not math.isfinite(got):
        return math.inf
    if ref == 0:
        return 0.0 if got == 0 else math.inf
    e = max(int(mp.floor(mp.log(abs(ref), 2))), -1022)
    return float(abs(mp.mpf(got) - ref) / mp.ldexp(1, e - 52))


def _ref(name: str, v: float):
    x = mp.mpf(v)
    if name == "cbrt":
        return mp.sign(x) * mp.cbrt(abs(x))
    if name in ("log", "log10") and x <= 0:
        return -mp.inf if x == 0 else mp.nan
    if name == "acosh" and x < 1 or name == "atanh" and abs(x) > 1:
        return mp.nan
    if name == "atanh" and abs(x) == 1:
        return mp.inf * mp.sign(x)
    return getattr(mp, name)(x)


def _hard(name: str, rng: np.random.Generator) -> np.ndarray:
    """Ranges where each function is hardest."""
    k = np.arange(-1074, 1024, 7).astype(float)
    near = {
        "exp": np.concatenate(
            [k * math.log(2), rng.uniform(-745.2, -708, 200), rng.uniform(700, 709.79, 200)]
        ),
        "log": np.concatenate(
            [1.0 + rng.normal(0, 1e-6, 200), 2.0**k, np.exp(rng.uniform(-744, -708, 100))]
        ),
        "log10": np.concatenate([10.0 ** np.arange(-300, 300, 9), 1.0 + rng.normal(0, 1e-9, 100)]),
        "sinh": np.concatenate(
            [rng.uniform(0.45, 0.55, 150), rng.uniform(700, 710.5, 100), 2.0 ** -k[k > 0] * 3]
        ),
        "cosh": np.concatenate([rng.uniform(-1e-3, 1e-3, 100), rng.uniform(700, 710.5, 100)]),
        "tanh": np.concatenate(
            [rng.uniform(0.11, 0.14, 150), rng.uniform(15, 25, 50), 2.0 ** -k[k > 0]]
        ),
        "asinh": np.concatenate(
            [rng.uniform(-1e-4, 1e-4, 100), 2.0 ** rng.uniform(26, 30, 100), [1e300, -1e-300]]
        ),
        "acosh": np.concatenate(
            [1.0 + np.abs(rng.normal(0, 1e-10, 150)), 2.0 ** rng.uniform(26, 30, 100), [1e300]]
        ),
        "atanh": np.concatenate(
            [1.0 - np.abs(rng.normal(0, 1e-9, 150)), rng.uniform(-1e-4, 1e-4, 100)]
        ),
        "cbrt": np.concatenate(
            [np.arange(-40.0, 41.0) ** 3, 2.0**k, rng.uniform(-1e-310, 1e-310, 50)]
        ),
    }
    return near[name]


@pytest.mark.parametrize("name", UNARY)
def test_accuracy_against_mpmath(name: str) -> None:
    rng = np.random.default_rng(sum(map(ord, name)))
    sign = rng.choice([-1.0, 1.0], 1200)
    x = np.concatenate(
        [
            rng.uniform(-2.0, 2.0, 1200),
            sign * np.exp(rng.uniform(-50.0, 6.6, 1200)),
            sign[:400] * 10.0 ** rng.uniform(-307, 307, 400),
            _hard(name, rng),
        ]
    )
    if name == "acosh":
        x = 1.0 + np.abs(x)
    if name == "atanh":
        x = np.clip(x, -1.0, 1.0)
    got = getattr(E, f"{name}_array")(x)
    err = np.array([_ulps(float(g), _ref(name, float(v))) for g, v in zip(got, x, strict=True)])
    worst = int(np.argmax(err))
    assert err.max() <= 1.0, f"{name}({x[worst]!r}) = {got[worst]!r}: {err.max():.3f} ulp"


def test_pow_accuracy_against_mpmath() -> None:
    rng = np.random.default_rng(99)
    n = 2500
    x = np.concatenate(
        [
            np.exp(rng.uniform(-8.0, 8.0, n)),
            1.0 + rng.normal(0.0, 1e-7, 300),  # log x tiny, y huge
            np.exp(rng.uniform(-700.0, 700.0, 300)),
            -np.round(rng.uniform(1.0, 40.0, 200)),  # negative bases, integer exponents
        ]
    )
    y = np.concatenate(
        [
            rng.uniform(-30.0, 30.0, n),
            rng.choice([-1.0, 1.0], 300) * 10.0 ** rng.uniform(5, 9, 300),
            rng.uniform(-1.0, 1.0, 300),
            np.round(rng.uniform(-200.0, 200.0, 200)),
        ]
    )
    # Results near overflow and underflow: y chosen so that x^y is within a factor e^2 of the edges.
    xe = np.exp(rng.uniform(0.1, 5.0, 300))
    ye = (rng.choice([709.0, -744.0], 300) + rng.uniform(-1.0, 1.0, 300)) / np.log(xe)
    x = np.concatenate([x, xe])
    y = np.concatenate([y, ye])
    got = E.pow_array(x, y)
    err = np.array(
        [_ulps(float(g), mp.power(mp.mpf(a), mp.mpf(b))) for g, a, b in zip(got, x, y, strict=True)]
    )
    worst = int(np.argmax(err))
    assert err.max() <= 1.0, (
        f"pow({x[worst]!r}, {y[worst]!r}) = {got[worst]!r}: {err.max():.3f} ulp"
    )


def test_exactly_representable_results_are_exact() -> None:
    k = np.arange(-1074.0, 1024.0)
    assert np.array_equal(E.pow_array(2.0, k), 2.0**k)
    ln2 = mp.log(2)
    assert np.array_equal(E.log_array(2.0**k), [float(v * ln2) for v in k])  # correctly rounded
    assert np.array_equal(E.log10_array(10.0 ** np.arange(0, 23)), np.arange(0.0, 23.0))
    ints = np.arange(-60.0, 61.0)
    assert np.array_equal(E.cbrt_array(ints**3), ints)
    assert np.array_equal(E.pow_array(ints, 3.0), ints**3)
    assert np.array_equal(E.pow_array(ints, 2.0), ints**2)
    assert np.array_equal(E.pow_array(ints**2, 0.5), np.abs(ints))
    rng = np.random.default_rng(3)
    x = np.exp(rng.uniform(-700, 700, 2000))
    assert np.array_equal(E.pow_array(x, 1.0), x)
    assert E.exp_scalar(0.0) == 1.0 and E.exp_scalar(1.0) == math.e


def test_close_to_the_c_library_on_many_arguments() -> None:
    """An independent cross-check against glibc (through numpy's ufuncs): glibc's exp, log and
    log10 are within about 0.5 ulp, cbrt and the hyperbolic functions within 2-3 ulp (ours 0.5)."""
    rng = np.random.default_rng(11)
    x = np.concatenate([rng.uniform(-20, 20, 20000), np.exp(rng.uniform(-740, 700, 20000))])
    pairs = {
        "exp": (x, np.exp, 1.0),
        "log": (np.abs(x), np.log, 1.0),
        "log10": (np.abs(x), np.log10, 1.0),
        "cbrt": (x, np.cbrt, 4.0),  # glibc cbrt: up to 3 ulp (its libm-test-ulps)
        "sinh": (x / 30.0, np.sinh, 2.5),
        "cosh": (x / 30.0, np.cosh, 2.5),
        "tanh": (x / 30.0, np.tanh, 2.5),
        "asinh": (x, np.arcsinh, 2.5),
        "acosh": (1.0 + np.abs(x), np.arccosh, 2.5),
        "atanh": (np.tanh(x / 30.0), np.arctanh, 2.5),
    }
    for name, (a, ufunc, tol) in pairs.items():
        ours = getattr(E, f"{name}_array")(a)
        with np.errstate(all="ignore"):
            theirs = ufunc(a)
        ok = np.isfinite(theirs) & (theirs != 0)
        ulp = np.spacing(np.abs(theirs[ok]))
        assert np.max(np.abs(ours[ok] - theirs[ok]) / ulp) <= tol, name
        assert np.array_equal(ours[~ok], theirs[~ok], equal_nan=True), name
    y = rng.uniform(-3.0, 3.0, x.size)
    ours = E.pow_array(np.abs(x) ** 0.1, y)
    theirs = np.power(np.abs(x) ** 0.1, y)
    assert np.max(np.abs(ours - theirs) / np.spacing(np.abs(theirs))) <= 1.0


# ----------------------------------------------------------------------------- special cases


def _same(a: float, b: float) -> bool:
    """Equal including the sign of zero, NaN equal to NaN."""
    return (math.isnan(a) and math.isnan(b)) or (
        a == b and math.copysign(1, a) == math.copysign(1, b)
    )


@pytest.mark.parametrize(
    ("name", "x", "want"),
    [
        ("exp", NAN, NAN), ("exp", INF, INF), ("exp", -INF, 0.0), ("exp", 0.0, 1.0), ("exp", -0.0, 1.0),
        ("exp", 709.782712893384, 1.7976931348622732e308), ("exp", 709.7827128933841, INF),
        ("exp", -745.1332191019411, 5e-324), ("exp", -745.1332191019412, 0.0),
        ("exp", -740.0, 4.2e-322), ("exp", 1e300, INF), ("exp", -1e300, 0.0),
        ("log", 0.0, -INF), ("log", -0.0, -INF), ("log", -1.0, NAN), ("log", -INF, NAN), ("log", INF, INF),
        ("log", NAN, NAN), ("log", 1.0, 0.0), ("log", 5e-324, -744.4400719213812),
        ("log", 1.7976931348623157e308, 709.782712893384),
        ("log10", 0.0, -INF), ("log10", -2.0, NAN), ("log10", INF, INF), ("log10", 1.0, 0.0), ("log10", 1e-300, -300.0),
        ("sinh", 0.0, 0.0), ("sinh", -0.0, -0.0), ("sinh", INF, INF), ("sinh", -INF, -INF), ("sinh", NAN, NAN),
        ("sinh", 710.4758600739439, 1.7976931348621744e308), ("sinh", 710.476, INF), ("sinh", -800.0, -INF),
        ("cosh", 0.0, 1.0), ("cosh", -0.0, 1.0), ("cosh", -INF, INF), ("cosh", NAN, NAN), ("cosh", 710.476, INF),
        ("tanh", 0.0, 0.0), ("tanh", -0.0, -0.0), ("tanh", INF, 1.0), ("tanh", -INF, -1.0), ("tanh", 20.0, 1.0),
        ("tanh", NAN, NAN), ("tanh", 5e-324, 5e-324),
        ("asinh", -0.0, -0.0), ("asinh", -INF, -INF), ("asinh", NAN, NAN), ("asinh", 1e-310, 1e-310),
        ("asinh", 1.7976931348623157e308, 710.475860073944),
        ("acosh", 1.0, 0.0), ("acosh", 0.999, NAN), ("acosh", -INF, NAN), ("acosh", INF, INF), ("acosh", NAN, NAN),
        ("acosh", 1.7976931348623157e308, 710.475860073944),
        ("atanh", 1.0, INF), ("atanh", -1.0, -INF), ("atanh", 1.5, NAN), ("atanh", -INF, NAN), ("atanh", -0.0, -0.0),
        ("atanh", NAN, NAN),
        ("cbrt", -0.0, -0.0), ("cbrt", 0.0, 0.0), ("cbrt", -INF, -INF), ("cbrt", NAN, NAN), ("cbrt", -27.0, -3.0),
        ("cbrt", 5e-324, 1.7031839360032603e-108),
    ],
)  # fmt: skip
def test_unary_special_cases(name: str, x: float, want: float) -> None:
    for got in (getattr(E, f"{name}_scalar")(x), float(getattr(E, f"{name}_array")(x))):
        assert _same(got, want), f"{name}({x!r}) = {got!r}, want {want!r}"


POW_VALUES = [
    0.0, -0.0, INF, -INF, NAN, 1.0, -1.0, 0.5, -0.5, 2.0, -2.0, 3.0, -3.0, 2.5, -2.5, 1e300, -1e300,
    5e-324, -5e-324, 2.0**52 + 1, -(2.0**52 + 1), 2.0**53, -(2.0**53), 2.0**53 + 2, 1e20, -1e20,
    0.9999999999999999, 1.0000000000000002, 1075.0, -1075.0, 1024.0, -1024.0, 0.3, -0.3,
    1.5, -1.5, 2.0**-300, 2.0**300, 2.0**-301, 2.0**301,
]  # fmt: skip


def test_pow_special_cases_match_c() -> None:
    """Every pair of special values: C's pow (numpy's np.power on float64) exactly, where it is
    exact (0, ±inf, ±1, NaN and signed zeros), else within 1 ulp."""
    v = np.array(POW_VALUES)
    x, y = (a.ravel() for a in np.meshgrid(v, v, indexing="ij"))
    ours = E.pow_array(x, y)
    with np.errstate(all="ignore"):
        c = np.power(x, y)
    for a, b, got, want in zip(x, y, ours, c, strict=True):
        if math.isnan(want) or want == 0 or math.isinf(want) or abs(want) == 1:
            assert _same(got, want), f"pow({a!r}, {b!r}) = {got!r}, C gives {want!r}"
        else:
            assert abs(got - want) <= np.spacing(abs(want)), (
                f"pow({a!r}, {b!r}) = {got!r}, C {want!r}"
            )


@pytest.mark.parametrize(
    ("x", "y", "want"),
    [
        (NAN, 0.0, 1.0), (NAN, -0.0, 1.0), (1.0, NAN, 1.0), (1.0, INF, 1.0), (-1.0, INF, 1.0), (-1.0, -INF, 1.0),
        (0.0, -1.0, INF), (-0.0, -1.0, -INF), (-0.0, -2.0, INF), (-0.0, -0.5, INF), (0.0, -INF, INF),
        (-0.0, 3.0, -0.0), (-0.0, 2.0, 0.0), (-0.0, 0.5, 0.0), (0.0, INF, 0.0),
        (-8.0, 1.0 / 3.0, NAN), (-2.0, 0.5, NAN), (-2.0, 3.0, -8.0), (-2.0, -3.0, -0.125), (-2.0, 2.0, 4.0),
        (-INF, 3.0, -INF), (-INF, -3.0, -0.0), (-INF, 2.0, INF), (-INF, 0.5, INF), (-INF, -0.5, 0.0),
        (INF, -1.0, 0.0), (INF, 0.5, INF), (0.5, INF, 0.0), (0.5, -INF, INF), (2.0, INF, INF), (2.0, -INF, 0.0),
        (-0.5, INF, 0.0), (-2.0, -INF, 0.0), (NAN, 1.0, NAN), (2.0, NAN, NAN),
        (10.0, 308.0, 1e308), (10.0, 309.0, INF), (10.0, -323.0, 1e-323), (10.0, -324.0, 0.0),
        (2.0, -1074.0, 5e-324), (2.0, -1075.0, 0.0), (2.0, 1023.0, 8.98846567431158e307), (2.0, 1024.0, INF),
        (-2.0, 1025.0, -INF), (-2.0, -1075.0, -0.0), (1.0000000000000002, 2.0**62, INF),
        (-1.0000000000000002, 2.0**62, INF), (-1.0000000000000002, -(2.0**62), 0.0), (-1.0000000000000002, -(2.0**53), 0.13533528323661273),
        (-(2.0**-1074), 2.0**52 + 1, -0.0), (-1.0, 2.0**53 - 1, -1.0), (-1.0, 2.0**53, 1.0),
    ],
)  # fmt: skip
def test_pow_c99_table(x: float, y: float, want: float) -> None:
    for got in (E.pow_scalar(x, y), float(E.pow_array(x, y))):
        assert _same(got, want), f"pow({x!r}, {y!r}) = {got!r}, want {want!r}"


@pytest.mark.parametrize("c", [1.5, 3.0])
def test_pow_exact_exponents_agree_and_are_correctly_rounded(c: float) -> None:
    """x^1.5 and x^3 take the exact-product path (|x| in [2^-300, 2^300], 0, inf, NaN): the
    row's fast loop, the row with a lane outside that range (then every lane through the
    selecting kernel), pow_row_vv, the scalar and the numpy twin agree bit for bit, and the
    results are within 0.5 ulp + 2^-100 of mpmath's."""
    rng = np.random.default_rng(15)
    lo, hi = K.POW_EXACT_LO, K.POW_EXACT_HI
    edges = np.array([lo, hi, np.nextafter(lo, 0), np.nextafter(hi, INF), -lo, -hi])
    inside = np.concatenate(
        [
            rng.uniform(0.0, 4.0, 3000),
            rng.choice([-1.0, 1.0], 3000) * 2.0 ** rng.uniform(-299.9, 299.9, 3000),
            np.round(rng.uniform(1, 2**26, 500)) ** 2,  # exact results for 1.5
            [0.0, -0.0, INF, -INF, NAN, lo, hi, -lo, -hi, 1.0, -1.0, -2.0],
        ]
    )
    W = np.zeros((3, inside.size))
    W[0] = inside
    E.pow_row_vs(W, 1, 0, c, inside.size)
    twin = E.pow_array(inside, c)
    assert E._NP_GLOBALS["_pow_exact_lane"](inside, c).all()
    assert np.array_equal(_bits(W[1]), _bits(twin))
    mixed = np.concatenate([inside, edges, [5e-324, 1e308, -1e308]])
    W = np.zeros((3, mixed.size))
    W[0] = mixed
    W[2] = c
    E.pow_row_vs(W, 1, 0, c, mixed.size)
    twin = E.pow_array(mixed, c)
    assert np.array_equal(_bits(W[1]), _bits(twin))
    E.pow_row_vv(W, 1, 0, 2, mixed.size)
    assert np.array_equal(_bits(W[1]), _bits(twin))
    out = np.empty_like(mixed)
    _scalar_loop2(E.pow_scalar, mixed, np.full_like(mixed, c), out)
    assert np.array_equal(_bits(out), _bits(twin))
    with np.errstate(all="ignore"):
        c_pow = np.power(mixed, c)
    special = ~np.isfinite(c_pow) | (c_pow == 0)
    assert np.array_equal(
        _bits(twin[special]), _bits(np.where(np.isnan(c_pow), NAN, c_pow)[special])
    )
    finite = np.flatnonzero(np.isfinite(twin[: inside.size]) & (twin[: inside.size] != 0))
    sample = rng.choice(finite, 1500, replace=False)
    err = [_ulps(float(twin[i]), mp.power(mp.mpf(mixed[i]), mp.mpf(c))) for i in sample]
    assert max(err) <= 0.5001, f"{max(err)} ulp"  # one rounding of a 2^-100-accurate sum


def test_the_rows_vectorise() -> None:
    """No call and no branch is left in the kernels: LLVM vectorises pow's row (which holds
    log's and exp's kernels). Compiled afresh: numba cannot inspect cached code."""
    if (
        os.environ.get("SURFGEN_NO_VECTORIZE") == "1"
        or os.environ.get("NUMBA_LOOP_VECTORIZE") == "0"
    ):
        pytest.skip("vectorisation switched off by the environment")
    fresh = njit(error_model="numpy")(E.pow_row_vs.py_func)
    fresh(np.ones((2, 8)), 1, 0, 2.5, 8)
    llvm = fresh.inspect_llvm(fresh.signatures[0])
    assert re.search(r"<(4|8) x double>", llvm)
    assert re.search(r"llvm\.sqrt\.v(4|8)f64", llvm)  # the x^1.5 loop
