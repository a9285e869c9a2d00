"""surfgen's own sin, cos, tan, asin, acos, atan, atan2 (generator/elementary/trig.py).

- the numba rows, the numba scalars and the numpy twins agree bit for bit (NaN bits included)
  on ~10^5 arguments mixing every scale and special value, also in place (d == a);
- accuracy <= 1 ulp against mpmath (40 digits) on a few thousand arguments per function,
  hard ranges included (nearest doubles to k*pi/2 and k*pi/4, huge arguments, near +-1, ...);
- C99 Annex F special cases (signed zeros, infinities, NaN, domain errors);
- the rows run inside a jitted function over a 2-D register file like the interpreter's;
- the tables (2/pi digits, Cody–Waite parts, polynomial coefficients) are what they claim.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap

import mpmath as mp
import numpy as np
import pytest
from numba import njit

from surfgen.generator.elementary import trig as T
from surfgen.generator.elementary import trig_tables as TT
from surfgen.generator.eval import row_functions as row_table

UNARY = ["sin", "cos", "tan", "asin", "acos", "atan"]
MP = {
    "sin": mp.sin,
    "cos": mp.cos,
    "tan": mp.tan,
    "asin": mp.asin,
    "acos": mp.acos,
    "atan": mp.atan,
}
SPECIAL = np.array(
    [0.0, -0.0, np.inf, -np.inf, np.nan, -np.nan, 5e-324, -5e-324, 2.2250738585072014e-308,
     1e-310, 1.0, -1.0, 0.5, -0.5, 1.0000000000000002, -1.0000000000000002, 0.9999999999999999,
     np.pi, np.pi / 2, np.pi / 4, -np.pi / 2, 7 / 16, 11 / 16, 19 / 16, 39 / 16, 2.0**60,
     2.0**23, -(2.0**23), 8388608.000000001, 1e22, 1e300, -1e300, 1.7976931348623157e308,
     -1.7976931348623157e308, 2.0**-27, 2.0**-28, 1e-200]
)  # fmt: skip


def _near_multiples(rng: np.random.Generator, count: int, step: mp.mpf) -> np.ndarray:
    """Nearest doubles to k*step (and their neighbours) for k of every size up to 2**60."""
    ks = np.unique(
        np.concatenate(
            [np.arange(1, 200), rng.integers(1, 2**24, count), 2 ** rng.uniform(24, 60, count)]
        ).astype(np.int64)
    )
    with mp.workdps(40):
        base = np.array([float(step * int(k)) for k in ks])
    out = np.concatenate([base, np.nextafter(base, np.inf), np.nextafter(base, 0.0)])
    return np.concatenate([out, -out])


def _arguments(name: str, n: int, seed: int = 0) -> np.ndarray:
    """Random arguments over many scales plus the hard ranges of ``name``."""
    rng = np.random.default_rng(seed)
    sign = rng.choice([-1.0, 1.0], n)
    if name in ("asin", "acos"):
        parts = [
            rng.uniform(-1.0, 1.0, n),
            sign * (1.0 - 2.0 ** -rng.uniform(1, 53, n)),  # near +-1
            sign * 10 ** rng.uniform(-320, 0, n),  # tiny, subnormal
            sign * (0.5 + rng.uniform(-1e-3, 1e-3, n)),  # the switch at 1/2
            sign[: n // 8] * rng.uniform(1.0, 3.0, n // 8),  # domain error
        ]
    elif name == "atan":
        parts = [
            rng.uniform(-4.0, 4.0, n),
            sign * 10 ** rng.uniform(-320, 308, n),
            sign
            * rng.choice([7 / 16, 11 / 16, 19 / 16, 39 / 16], n)
            * (1 + rng.normal(0, 1e-9, n)),
        ]
    else:
        with mp.workdps(40):
            step = mp.pi / 4 if name == "tan" else mp.pi / 2
        parts = [
            rng.uniform(-10.0, 10.0, n),
            sign * 10 ** rng.uniform(-320, 7, n),
            sign[: n // 2] * 10 ** rng.uniform(6, 308, n // 2),  # Payne–Hanek beyond 2**23
            _near_multiples(rng, n // 16, step),
        ]
    return np.concatenate([np.asarray(p, dtype=np.float64) for p in parts + [SPECIAL]])


def _ulp_errors(exact: list, got: np.ndarray) -> np.ndarray:
    """|got - exact| in units of the last place of the exact value (0 for matching NaN/inf)."""
    out = np.zeros(got.size)
    for i, (e, g) in enumerate(zip(exact, got, strict=True)):
        if mp.isnan(e) or g != g:
            out[i] = 0.0 if (mp.isnan(e) and g != g) else np.inf
            continue
        if mp.isinf(e) or e == 0:
            out[i] = 0.0 if mp.mpf(float(g)) == e else np.inf
            continue
        exp = max(int(mp.floor(mp.log(abs(e), 2))) - 52, -1074)
        out[i] = float(abs(mp.mpf(float(g)) - e) / mp.ldexp(1, exp))
    return out


def _row(name: str, x: np.ndarray, inplace: bool = False) -> np.ndarray:
    W = np.zeros((3, x.size))
    W[1] = x
    d = 1 if inplace else 2
    row_table.run(name, W, d, 1, x.size)  # the row's C function, as the interpreter calls it
    return W[d].copy()


def _bits(v: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(v, dtype=np.float64).view(np.int64)


# ----------------------------------------------------------------------------- bit identity


@pytest.mark.parametrize("name", UNARY)
def test_row_scalar_array_agree_bit_for_bit(name: str) -> None:
    x = _arguments(name, 12000, seed=1)
    rng = np.random.default_rng(2)
    x = np.concatenate([x, rng.normal(0, 1, 4000) * 10.0 ** rng.integers(-8, 9, 4000)])
    want = getattr(T, f"{name}_array")(x)
    assert want.dtype == np.float64 and want.shape == x.shape
    np.testing.assert_array_equal(_bits(_row(name, x)), _bits(want))
    np.testing.assert_array_equal(_bits(_row(name, x, inplace=True)), _bits(want))
    scalar = getattr(T, f"{name}_scalar")
    np.testing.assert_array_equal(_bits(np.array([scalar(v) for v in x[::7]])), _bits(want[::7]))
    # a few slow lanes in a long row of fast ones (the gather/patch path), partial rows
    W = np.full((2, 300), 7.0)
    W[0, :] = x[:300]
    row_table.run(name, W, 1, 0, 250)
    np.testing.assert_array_equal(_bits(W[1, :250]), _bits(want[:250]))
    assert np.all(W[1, 250:] == 7.0)


def _atan2_arguments(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    y = rng.normal(0, 1, n) * 10.0 ** rng.integers(-6, 7, n)
    x = rng.normal(0, 1, n) * 10.0 ** rng.integers(-6, 7, n)
    m = max(n // 10, 50)  # extreme magnitudes take the (slow in numpy) scalar path
    wide_y = rng.choice([-1.0, 1.0], m) * 10 ** rng.uniform(-320, 308, m)
    wide_x = rng.choice([-1.0, 1.0], m) * 10 ** rng.uniform(-320, 308, m)
    s = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 1.0, -1.0, 5e-324, -1e-310, 1e300, -1e300,
                  1.7976931348623157e308, -1.7976931348623157e308, 2.0**-500, 2.0**500])  # fmt: skip
    sy, sx = (v.ravel() for v in np.meshgrid(s, s))
    # ratios at the interval switches, with both signs of x
    r = rng.choice([7 / 16, 11 / 16, 19 / 16, 39 / 16], n) * (1 + rng.normal(0, 1e-12, n))
    bx = rng.choice([-1.0, 1.0], n) * rng.uniform(0.5, 2.0, n)
    return (
        np.concatenate([y, wide_y, wide_y, sy, r * np.abs(bx)]),
        np.concatenate([x, wide_x, x[:m], sx, bx]),
    )


def test_atan2_rows_scalar_array_agree_bit_for_bit() -> None:
    y, x = _atan2_arguments(12000, seed=3)
    want = T.atan2_array(y, x)
    W = np.zeros((3, y.size))
    W[0], W[1] = y, x
    row_table.run("atan2_vv", W, 2, 0, y.size, b=1)
    np.testing.assert_array_equal(_bits(W[2]), _bits(want))
    row_table.run("atan2_vv", W, 0, 0, y.size, b=1)  # in place
    np.testing.assert_array_equal(_bits(W[0]), _bits(want))
    got = np.array([T.atan2_scalar(a, b) for a, b in zip(y[::5], x[::5], strict=True)])
    np.testing.assert_array_equal(_bits(got), _bits(want[::5]))
    for s in [0.0, -0.0, 1.5, -2.5, np.inf, -np.inf, np.nan, 1e-320, 1e305]:
        W[0], W[1] = y, x
        row_table.run("atan2_vs", W, 0, 0, y.size, s=s)
        np.testing.assert_array_equal(_bits(W[0]), _bits(T.atan2_array(y, s)))
        W[1] = x
        row_table.run("atan2_sv", W, 1, 0, x.size, b=1, s=s)
        np.testing.assert_array_equal(_bits(W[1]), _bits(T.atan2_array(s, x)))


def test_array_shapes_and_scalars() -> None:
    x = np.linspace(-3, 3, 24).reshape(2, 3, 4)
    for name in UNARY:
        f = getattr(T, f"{name}_array")
        r = f(x)
        assert r.shape == x.shape and r.dtype == np.float64
        z = f(0.25)
        assert (
            isinstance(z, np.ndarray) and z.shape == () and z == getattr(T, f"{name}_scalar")(0.25)
        )
        assert f(np.zeros(0)).shape == (0,)
    r = T.atan2_array(x, np.array([1.0, -1.0, 2.0, -0.0]))  # broadcasting
    assert r.shape == x.shape
    assert T.atan2_array(1.0, -1.0).shape == ()
    # non-contiguous input views
    np.testing.assert_array_equal(T.sin_array(x[:, ::2, 1:]), T.sin_array(x[:, ::2, 1:].copy()))


# ----------------------------------------------------------------------------- accuracy


@pytest.mark.parametrize("name", UNARY)
def test_accuracy_within_one_ulp(name: str) -> None:
    x = _arguments(name, 500, seed=4)
    got = getattr(T, f"{name}_array")(x)
    f = MP[name]
    with mp.workdps(40):
        exact = []
        for v in x:
            if (
                name in ("asin", "acos")
                and abs(v) > 1
                or math.isinf(v)
                and name in ("sin", "cos", "tan")
            ):
                exact.append(mp.nan)
            else:
                exact.append(f(mp.mpf(float(v))) if v == v else mp.nan)
    err = _ulp_errors(exact, got)
    worst = int(np.argmax(err))
    assert err.max() <= 1.0, f"{name}({x[worst]!r}) = {got[worst]!r}: {err.max():.3f} ulp"
    # and mostly correctly rounded
    assert np.mean(err > 0.5) < 0.05


def test_atan2_accuracy_within_one_ulp() -> None:
    y, x = _atan2_arguments(400, seed=5)
    got = T.atan2_array(y, x)
    with mp.workdps(40):
        exact = [
            mp.nan if (a != a or b != b) else mp.atan2(mp.mpf(float(a)), mp.mpf(float(b)))
            for a, b in zip(y, x, strict=True)
        ]
    # mpmath's atan2 knows no signed zeros or infinities: compare those in the special table
    keep = np.isfinite(y) & np.isfinite(x) & (y != 0) & (x != 0)
    err = _ulp_errors([e for e, k in zip(exact, keep, strict=True) if k], got[keep])
    worst = int(np.argmax(err))
    assert err.max() <= 1.0, f"atan2({y[keep][worst]!r}, {x[keep][worst]!r}): {err.max():.3f} ulp"


# ----------------------------------------------------------------------------- special cases

PI = math.pi
SPECIAL_CASES = [
    ("sin", 0.0, 0.0), ("sin", -0.0, -0.0), ("sin", np.inf, np.nan), ("sin", -np.inf, np.nan),
    ("sin", np.nan, np.nan), ("sin", 5e-324, 5e-324), ("sin", -1e-310, -1e-310),
    ("cos", 0.0, 1.0), ("cos", -0.0, 1.0), ("cos", np.inf, np.nan), ("cos", np.nan, np.nan),
    ("cos", 5e-324, 1.0),
    ("tan", 0.0, 0.0), ("tan", -0.0, -0.0), ("tan", np.inf, np.nan), ("tan", -np.inf, np.nan),
    ("tan", np.nan, np.nan), ("tan", -5e-324, -5e-324),
    ("asin", 0.0, 0.0), ("asin", -0.0, -0.0), ("asin", 1.0, PI / 2), ("asin", -1.0, -PI / 2),
    ("asin", 1.0000000000000002, np.nan), ("asin", -2.0, np.nan), ("asin", np.inf, np.nan),
    ("asin", np.nan, np.nan), ("asin", -5e-324, -5e-324),
    ("acos", 1.0, 0.0), ("acos", -1.0, PI), ("acos", 0.0, PI / 2), ("acos", -0.0, PI / 2),
    ("acos", 1.0000000000000002, np.nan), ("acos", -np.inf, np.nan), ("acos", np.nan, np.nan),
    ("atan", 0.0, 0.0), ("atan", -0.0, -0.0), ("atan", np.inf, PI / 2), ("atan", -np.inf, -PI / 2),
    ("atan", np.nan, np.nan), ("atan", 1.0, PI / 4), ("atan", -1e300, -PI / 2),
    ("atan", 5e-324, 5e-324),
]  # fmt: skip

ATAN2_CASES = [
    (0.0, 0.0, 0.0), (-0.0, 0.0, -0.0), (0.0, -0.0, PI), (-0.0, -0.0, -PI),
    (0.0, -1.0, PI), (-0.0, -1.0, -PI), (0.0, 1.0, 0.0), (-0.0, 1.0, -0.0),
    (1.0, 0.0, PI / 2), (1.0, -0.0, PI / 2), (-1.0, 0.0, -PI / 2), (-1.0, -0.0, -PI / 2),
    (1.0, -np.inf, PI), (-1.0, -np.inf, -PI), (1.0, np.inf, 0.0), (-1.0, np.inf, -0.0),
    (np.inf, 1.0, PI / 2), (-np.inf, -1.0, -PI / 2), (np.inf, -np.inf, 3 * PI / 4),
    (-np.inf, -np.inf, -3 * PI / 4), (np.inf, np.inf, PI / 4), (-np.inf, np.inf, -PI / 4),
    (np.nan, 1.0, np.nan), (1.0, np.nan, np.nan), (np.nan, np.nan, np.nan), (np.nan, np.inf, np.nan),
    (0.0, np.nan, np.nan), (1.0, 1.0, PI / 4), (1.0, -1.0, 3 * PI / 4), (-1.0, -1.0, -3 * PI / 4),
    (1e-320, 1e300, 0.0), (-1e-320, -1e300, -PI), (1e300, 1e-320, PI / 2), (5e-324, 5e-324, PI / 4),
    (1e-320, 1.0, 1e-320), (1e-320, -1.0, PI), (1e308, 1e308, PI / 4), (-1e308, -1e308, -3 * PI / 4),
    (1.7976931348623157e308, 0.0, PI / 2), (-1.7976931348623157e308, -0.0, -PI / 2),
    (0.0, 1.7976931348623157e308, 0.0), (-0.0, -1.7976931348623157e308, -PI),
    (1.7976931348623157e308, np.inf, 0.0), (np.inf, 1e-310, PI / 2), (np.nan, 1e300, np.nan),
    (1e-310, 0.0, PI / 2), (0.0, -1e-310, PI), (5e-324, -1.7976931348623157e308, PI),
]  # fmt: skip

CANONICAL_NAN = np.array(np.nan).view(np.int64)


def _check_case(got: float, want: float, what: str) -> None:
    if math.isnan(want):
        assert math.isnan(got), what
        assert np.array(got).view(np.int64) == CANONICAL_NAN, f"{what}: NaN not canonical"
    else:
        assert got == want and math.copysign(1, got) == math.copysign(1, want), f"{what} = {got!r}"


@pytest.mark.parametrize(("name", "x", "want"), SPECIAL_CASES)
def test_special_cases(name: str, x: float, want: float) -> None:
    _check_case(getattr(T, f"{name}_scalar")(x), want, f"{name}({x!r})")
    _check_case(float(getattr(T, f"{name}_array")(x)), want, f"{name}_array({x!r})")
    _check_case(_row(name, np.array([x]))[0], want, f"{name}_row({x!r})")


@pytest.mark.parametrize(("y", "x", "want"), ATAN2_CASES)
def test_atan2_special_cases(y: float, x: float, want: float) -> None:
    _check_case(T.atan2_scalar(y, x), want, f"atan2({y!r}, {x!r})")
    _check_case(float(T.atan2_array(y, x)), want, f"atan2_array({y!r}, {x!r})")
    W = np.array([[y], [x], [0.0]])
    row_table.run("atan2_vv", W, 2, 0, 1, b=1)
    _check_case(W[2, 0], want, f"atan2_row_vv({y!r}, {x!r})")


def _neg(v: np.ndarray) -> np.ndarray:
    return np.where(np.isnan(v), v, -v)  # NaN results stay the canonical NaN


def test_symmetries_exact() -> None:
    """Odd functions are exactly odd, cos is exactly even, acos(-x) = pi - acos(x) closely."""
    x = _arguments("sin", 3000, seed=6)
    x = x[np.isfinite(x)]
    for name in ("sin", "tan"):
        f = getattr(T, f"{name}_array")
        np.testing.assert_array_equal(_bits(f(-x)), _bits(_neg(f(x))))
    np.testing.assert_array_equal(_bits(T.cos_array(-x)), _bits(T.cos_array(x)))
    u = _arguments("asin", 3000, seed=7)
    for name in ("asin", "atan"):
        f = getattr(T, f"{name}_array")
        np.testing.assert_array_equal(_bits(f(-u)), _bits(_neg(f(u))))
    y, xx = _atan2_arguments(2000, seed=8)
    np.testing.assert_array_equal(_bits(T.atan2_array(-y, xx)), _bits(_neg(T.atan2_array(y, xx))))


def test_agrees_with_libm_closely() -> None:
    """Cross-check against the C library (0.5-ulp class): at most 1 ulp apart on plain ranges."""
    rng = np.random.default_rng(9)
    x = rng.uniform(-50, 50, 20000)
    u = rng.uniform(-1, 1, 20000)
    pairs = [
        ("sin", x, math.sin), ("cos", x, math.cos), ("tan", x, math.tan),
        ("asin", u, math.asin), ("acos", u, math.acos), ("atan", x, math.atan),
    ]  # fmt: skip
    for name, args, ref in pairs:
        got = getattr(T, f"{name}_array")(args)
        want = np.array([ref(v) for v in args])
        ulps = np.abs(got - want) / np.spacing(np.abs(want))
        assert ulps.max() <= 1.0, name
        assert np.mean(got == want) > 0.95, name
    want = np.array([math.atan2(a, b) for a, b in zip(x, u, strict=True)])
    assert (np.abs(T.atan2_array(x, u) - want) / np.spacing(np.abs(want))).max() <= 1.0


# ----------------------------------------------------------------------------- use from numba


@njit(cache=True, error_model="numpy")
def _interpreter_like(W, n):
    # rows of a register file, one in place, mixed with plain arithmetic (a subset: every
    # row compiles again inside its caller, which costs seconds)
    T.sin_row(W, 1, 0, n)
    T.acos_row(W, 2, 1, n)
    for k in range(n):
        W[3, k] = W[1, k] * W[1, k] + W[2, k]
    T.atan_row(W, 3, 3, n)
    T.atan2_row_sv(W, 4, 2.0, 0, n)
    return T.tan_scalar(W[0, 0])


def test_rows_run_inside_a_jitted_interpreter() -> None:
    rng = np.random.default_rng(10)
    n = 200
    W = np.zeros((5, n + 7))  # rows longer than n: the tail stays untouched
    W[0, :n] = rng.uniform(-1.5, 1.5, n)
    W[0, 3] = 1e9  # one slow lane
    r = _interpreter_like(W, n)
    x = W[0, :n]
    s = T.sin_array(x)
    np.testing.assert_array_equal(_bits(W[1, :n]), _bits(s))
    c = T.acos_array(s)
    np.testing.assert_array_equal(_bits(W[2, :n]), _bits(c))
    np.testing.assert_array_equal(_bits(W[3, :n]), _bits(T.atan_array(s * s + c)))
    np.testing.assert_array_equal(_bits(W[4, :n]), _bits(T.atan2_array(2.0, x)))
    assert np.all(W[1:, n:] == 0.0)
    assert r == T.tan_scalar(x[0])
    # acos(sin u) = pi/2 - u on [-pi/2, pi/2]
    ok = np.abs(x) < 1.5
    assert np.max(np.abs(W[2, :n][ok] - (np.pi / 2 - x[ok]))) < 1e-15


def test_results_do_not_depend_on_vectorisation(tmp_path) -> None:
    """The same bits with LLVM's vectorisers off (no FMA, no reassociation anywhere)."""
    rng = np.random.default_rng(11)
    x = rng.normal(0, 1, 3000) * 10.0 ** rng.integers(-3, 12, 3000)
    x = np.concatenate([x, [np.inf, np.nan, -0.0, 1e300, 0.75, -1.0]])
    np.save(tmp_path / "x.npy", x)
    code = textwrap.dedent(
        f"""
        import numpy as np
        from surfgen.generator.elementary import trig as T
        x = np.load({str(tmp_path / "x.npy")!r})
        W = np.zeros((3, x.size)); W[0] = x; W[1] = T.sin_array(x) * 1.5
        T.sin_row(W, 2, 0, x.size); np.save({str(tmp_path / "s.npy")!r}, W[2])
        T.acos_row(W, 2, 1, x.size); np.save({str(tmp_path / "a.npy")!r}, W[2])
        """
    )
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    env.update(NUMBA_LOOP_VECTORIZE="0", NUMBA_SLP_VECTORIZE="0")
    subprocess.run([sys.executable, "-c", code], env=env, check=True)
    np.testing.assert_array_equal(_bits(np.load(tmp_path / "s.npy")), _bits(_row("sin", x)))
    np.testing.assert_array_equal(
        _bits(np.load(tmp_path / "a.npy")), _bits(_row("acos", T.sin_array(x) * 1.5))
    )


# ----------------------------------------------------------------------------- tables


def test_two_over_pi_digits() -> None:
    with mp.workdps(500):
        v = 2 / mp.pi
        for i, d in enumerate(TT._F):
            v *= 2**24
            assert int(mp.floor(v)) == int(d), f"digit {i}"
            v -= mp.floor(v)


def test_cody_waite_parts() -> None:
    with mp.workdps(100):
        total = sum(mp.mpf(c) for c in (TT._C1, TT._C2, TT._C3, TT._C4))
        assert abs(total - mp.pi / 2) < mp.mpf(2) ** -140
    for c in (TT._C1, TT._C2, TT._C3):
        m, _ = math.frexp(c)
        assert (m * 2**29) == int(m * 2**29)  # 29 bits: n * c exact for |n| < 2**24
    assert TT.TRIG_FAST_LIMIT * TT._FOUR_OVER_PI < 2**24


@pytest.mark.parametrize(
    ("coeffs", "g", "zmax"),
    [
        ("_S", lambda y: (mp.sin(y) - y) / y**3, mp.pi / 4),
        ("_K", lambda y: (mp.cos(y) - 1 + y * y / 2) / y**4, mp.pi / 4),
        ("_T", lambda y: (mp.tan(y) - y) / y**3, mp.pi / 8),
        ("_A", lambda y: (mp.asin(y) - y) / y**3, mp.mpf("0.5")),
        ("_U", lambda y: (mp.atan(y) - y) / y**3, mp.mpf(7) / 16),
    ],
)
def test_polynomial_fit_errors(coeffs: str, g, zmax) -> None:
    """Each kernel polynomial is within 2**-52 (relative) of its function on its range."""
    c = []
    while hasattr(TT, f"{coeffs}{len(c)}"):
        c.append(mp.mpf(getattr(TT, f"{coeffs}{len(c)}")))
    with mp.workdps(80):
        for i in range(1, 201):
            y = zmax * i / 200
            z = y * y
            p = mp.mpf(0)
            for a in reversed(c):
                p = p * z + a
            assert abs(p / g(y) - 1) < mp.mpf(2) ** -52


def test_tan_row_vectorises_without_fused_multiply_add() -> None:
    """tan, the costliest row of the interpreter's profile: its loop runs on packed doubles,
    and LLVM contracts no multiply-add (the numpy twin rounds every product)."""
    import re

    from surfgen.generator import NO_VECTORIZE

    fresh = njit(error_model="numpy")(T.tan_row.py_func)  # cached functions show no code
    W = np.zeros((2, 16))
    fresh(W, 1, 0, 16)
    asm = "\n".join(fresh.inspect_asm().values())
    packed = re.search(r"\bv(mul|div)pd\s+[^\n]*[yz]mm", asm)
    assert bool(packed) != NO_VECTORIZE, "vectorised iff SURFGEN_NO_VECTORIZE is unset"
    assert not re.search(r"\bv?f(n)?m(add|sub)\d", asm), "FMA in tan_row"


def test_the_rows_gather_their_slow_lanes_with_int64_values_not_literals(monkeypatch) -> None:
    """The rows pass their gathers int64 values (a scalar operand's row too): a literal
    argument compiled ``_gather2`` once per combination of literals (6 signatures, 1.5 s of a
    cold warm-up). A fresh (uncached) caller types the calls, as the interpreter's rows do,
    into fresh gathers (other tests' callers may have typed the module's with literals)."""
    import numba
    from numba import types

    from surfgen.generator.elementary import trig
    from surfgen.generator.jit.options import KERNEL

    for name in ("_gather1", "_gather2"):
        fresh = numba.njit(**{**KERNEL, "cache": False})(getattr(trig, name).py_func)
        monkeypatch.setattr(trig, name, fresh)

    @numba.njit(cache=False)
    def rows(W, d, a, b, n, s):  # noqa: N803 - the rows' own names
        trig.sin_row(W, d, a, n)
        trig.atan2_row_vv(W, d, a, b, n)
        trig.atan2_row_vs(W, d, a, s, n)
        trig.atan2_row_sv(W, d, s, b, n)

    W = np.zeros((3, 6))  # noqa: N806
    W[0] = [1e300, -0.0, np.inf, np.nan, 1.0, 3.0]  # slow lanes in every row
    W[1] = [0.0, -0.0, -np.inf, 2.0, np.nan, 1e-310]
    rows(W, 2, 0, 1, 6, 0.0)
    for gather in (trig._gather1, trig._gather2):
        assert gather.signatures
        literal = [s for s in gather.signatures if any(isinstance(t, types.Literal) for t in s)]
        assert not literal, literal
