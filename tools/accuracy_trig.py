"""Accuracy (against mpmath) and speed of surfgen's own sin, cos, tan, asin, acos, atan, atan2.

For each function: ``--n`` arguments (default 10**6) mixing random scales and the hard ranges
(nearest doubles to k*pi/2 and k*pi/4 with their neighbours for k up to 2**1000, huge arguments
up to the largest double, the worst case of Muller's table, near +-1 for asin/acos, tiny and
subnormal inputs, the interval switches of atan, extreme ratios and signs for atan2). The
exact values come from mpmath at 40 digits (a Pool of 2 processes; it takes minutes: run it
under ``nice``). The results are those of the numba rows (the numpy twins give the same bits:
checked here on a sample and in the tests).

Speed, in one run and on the same arguments: ``NAME_row`` over rows of 1024 points, a numba
loop calling ``math.NAME`` (the C library), and numpy's ufunc. Prints a markdown table::

    nice -n 10 .venv/bin/python -m tools.accuracy_trig            # 10**6 each
    .venv/bin/python -m tools.accuracy_trig --n 20000 --quick      # a smoke run
"""

from __future__ import annotations

import argparse
import math
import time
from multiprocessing import Pool

import mpmath as mp
import numpy as np
from numba import njit

from benchmarks.harness import machine_line
from surfgen.generator.elementary import trig as T

UNARY = ["sin", "cos", "tan", "asin", "acos", "atan"]
NUMPY = {
    "sin": np.sin,
    "cos": np.cos,
    "tan": np.tan,
    "asin": np.arcsin,
    "acos": np.arccos,
    "atan": np.arctan,
}


# ----------------------------------------------------------------------------- arguments


def _signs(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.choice([-1.0, 1.0], n)


def _near_multiples(rng: np.random.Generator, n: int, quarter: bool) -> np.ndarray:
    """Nearest doubles to k*pi/2 (k*pi/4) and their neighbours, k up to 2**1000."""
    m = n // 4
    small = min(2000, m // 4)
    ks = np.concatenate(
        [
            np.arange(1, small + 1),
            rng.integers(1, 2**24, m // 2),
            (2.0 ** rng.uniform(24, 1000, m - m // 2 - small)),
        ]
    )
    step = mp.pi / 4 if quarter else mp.pi / 2
    with mp.workdps(60):
        base = np.array([float(step * mp.mpf(int(k))) for k in ks])
    base = base[np.isfinite(base)]
    out = [base, np.nextafter(base, np.inf), np.nextafter(base, 0.0)]
    out.append(np.nextafter(out[1], np.inf))
    v = np.concatenate(out)
    return v * _signs(rng, v.size)


def arguments(name: str, n: int, seed: int = 0) -> np.ndarray:
    """``n`` arguments for a unary function: random scales plus its hard ranges."""
    rng = np.random.default_rng(seed)
    if name in ("sin", "cos", "tan"):
        hard = _near_multiples(rng, n // 4, quarter=name == "tan")
        worst = np.array([6381956970095103.0 * 2.0**797, 5319372648326954.0 * 2.0**-1])
        k = n - hard.size - worst.size
        parts = [
            rng.uniform(-10.0, 10.0, k * 3 // 10),
            _signs(rng, k // 4) * 10 ** rng.uniform(-320, math.log10(2.0**23), k // 4),
            _signs(rng, k // 4) * 10 ** rng.uniform(6.9, 308.25, k // 4),
            rng.uniform(-(2.0**23), 2.0**23, k // 10),
            hard,
            worst,
        ]
    elif name in ("asin", "acos"):
        k = n // 10
        parts = [
            rng.uniform(-1.0, 1.0, 4 * k),
            _signs(rng, 3 * k) * (1.0 - 2.0 ** -rng.uniform(1, 53, 3 * k)),
            _signs(rng, k) * 10 ** rng.uniform(-323, 0, k),
            _signs(rng, k) * (0.5 + rng.uniform(-1e-3, 1e-3, k)),
            _signs(rng, k // 2) * (1.0 - np.arange(1, k // 2 + 1) * 2.0**-53),
            _signs(rng, k // 2) * rng.uniform(1.0, 4.0, k // 2),  # domain error -> NaN
        ]
    else:  # atan
        k = n // 10
        switches = rng.choice([7 / 16, 11 / 16, 19 / 16, 39 / 16, 1.0], 2 * k)
        parts = [
            rng.uniform(-4.0, 4.0, 3 * k),
            _signs(rng, 4 * k) * 10 ** rng.uniform(-323, 308.25, 4 * k),
            _signs(rng, 2 * k) * switches * (1 + rng.normal(0, 1e-6, 2 * k)),
            rng.uniform(-100.0, 100.0, k),
        ]
    x = np.concatenate([np.asarray(p, dtype=np.float64) for p in parts])
    return x[:n] if x.size >= n else np.concatenate([x, rng.uniform(-1, 1, n - x.size)])


def atan2_arguments(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``n`` pairs (y, x): random scales, extreme ratios and magnitudes, the switches, signs."""
    rng = np.random.default_rng(seed)
    k = n // 10
    y = [rng.normal(0, 1, 4 * k) * 10.0 ** rng.integers(-8, 9, 4 * k)]
    x = [rng.normal(0, 1, 4 * k) * 10.0 ** rng.integers(-8, 9, 4 * k)]
    y.append(_signs(rng, 2 * k) * 10 ** rng.uniform(-323, 308.25, 2 * k))
    x.append(_signs(rng, 2 * k) * 10 ** rng.uniform(-323, 308.25, 2 * k))
    r = rng.choice([7 / 16, 11 / 16, 19 / 16, 39 / 16, 1.0], 3 * k) * (
        1 + rng.normal(0, 1e-6, 3 * k)
    )
    bx = _signs(rng, 3 * k) * 10 ** rng.uniform(-3, 3, 3 * k)
    y.append(_signs(rng, 3 * k) * r * np.abs(bx))
    x.append(bx)
    m = n - 9 * k
    y.append(_signs(rng, m) * 10 ** rng.uniform(-30, 0, m))  # tiny angle, x < 0: near pi
    x.append(-(10 ** rng.uniform(0, 3, m)))
    return np.concatenate(y), np.concatenate(x)


# ----------------------------------------------------------------------------- exact values


def _exact_chunk(job: tuple[str, np.ndarray, np.ndarray | None]) -> tuple[np.ndarray, np.ndarray]:
    """(hi, lo) double-double of the exact values (NaN where the function is undefined)."""
    name, x, x2 = job
    mp.mp.dps = 40
    f = {"sin": mp.sin, "cos": mp.cos, "tan": mp.tan, "asin": mp.asin, "acos": mp.acos}.get(
        name, mp.atan
    )
    hi = np.empty(x.size)
    lo = np.empty(x.size)
    for i in range(x.size):
        v = float(x[i])
        if x2 is not None:
            w = float(x2[i])
            if not (math.isfinite(v) and math.isfinite(w)) or v == 0 or w == 0:
                e = None  # signed zeros and infinities: the special-case tests cover them
            else:
                e = mp.atan2(mp.mpf(v), mp.mpf(w))
        elif not math.isfinite(v) or (name in ("asin", "acos") and abs(v) > 1):
            e = None
        else:
            e = f(mp.mpf(v))
        if e is None:
            hi[i] = lo[i] = np.nan
        else:
            h = float(e)
            hi[i] = h
            lo[i] = float(e - h) if math.isfinite(h) else 0.0
    return hi, lo


def exact_values(name: str, x: np.ndarray, x2: np.ndarray | None, pool: Pool) -> tuple:
    step = 20000
    jobs = [
        (name, x[i : i + step], None if x2 is None else x2[i : i + step])
        for i in range(0, x.size, step)
    ]
    parts = pool.map(_exact_chunk, jobs)
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def ulp_errors(got: np.ndarray, hi: np.ndarray, lo: np.ndarray) -> np.ndarray:
    """|got - exact| in ulps of the exact value (exact = hi + lo); defined lanes only."""
    ok = ~np.isnan(hi)
    g, h, lo = got[ok], hi[ok], lo[ok]
    m, e = np.frexp(h)
    # the exact value just below a power of two lives in the binade below
    e = e - ((np.abs(m) == 0.5) & (np.sign(lo) == -np.sign(h))).astype(int)
    ulp = np.ldexp(1.0, np.maximum(e - 53, -1074))
    with np.errstate(invalid="ignore"):
        err = np.abs((g - h) - lo) / ulp
    err = np.where(g == h, np.abs(lo) / ulp, err)  # also infinities
    return err


# ----------------------------------------------------------------------------- speed


@njit(cache=True, error_model="numpy")
def _libm_row(W, d, a, n, which):
    for k in range(n):
        u = W[a, k]
        if which == 0:
            W[d, k] = math.sin(u)
        elif which == 1:
            W[d, k] = math.cos(u)
        elif which == 2:
            W[d, k] = math.tan(u)
        elif which == 3:
            W[d, k] = math.asin(u)
        elif which == 4:
            W[d, k] = math.acos(u)
        else:
            W[d, k] = math.atan(u)


@njit(cache=True, error_model="numpy")
def _libm_atan2_row(W, d, a, b, n):
    for k in range(n):
        W[d, k] = math.atan2(W[a, k], W[b, k])


def _rates(calls: list, points: int, seconds: float = 0.01, rounds: int = 60) -> list[float]:
    """Million evaluations per second of each call: best of ``rounds`` short interleaved timings
    (interleaving keeps the ratios fair on a machine whose load changes)."""
    reps = []
    for call in calls:
        for _ in range(3):
            call()
        r = 1
        while True:
            t = time.perf_counter()
            for _ in range(r):
                call()
            if time.perf_counter() - t > seconds / 4:
                break
            r *= 4
        reps.append(r)
    best = [math.inf] * len(calls)
    for _ in range(rounds):
        for i, call in enumerate(calls):
            t = time.perf_counter()
            for _ in range(reps[i]):
                call()
            best[i] = min(best[i], (time.perf_counter() - t) / reps[i])
    return [points / b / 1e6 for b in best]


def speeds(name: str) -> tuple[float, float, float]:
    """(NAME_row, math.NAME loop in numba, numpy ufunc) in M evaluations/s, rows of 1024."""
    n = 1024
    rng = np.random.default_rng(1)
    W = np.zeros((3, n))
    if name == "atan2":
        W[0], W[1] = rng.normal(0, 1, n), rng.normal(0, 1, n)
        return tuple(
            _rates(
                [
                    lambda: T.atan2_row_vv(W, 2, 0, 1, n),
                    lambda: _libm_atan2_row(W, 2, 0, 1, n),
                    lambda: np.arctan2(W[0], W[1], out=W[2]),
                ],
                n,
            )
        )
    W[0] = rng.uniform(-1, 1, n) if name in ("asin", "acos") else rng.uniform(-10, 10, n)
    row = getattr(T, f"{name}_row")
    which = UNARY.index(name)
    return tuple(
        _rates(
            [
                lambda: row(W, 1, 0, n),
                lambda: _libm_row(W, 1, 0, n, which),
                lambda: NUMPY[name](W[0], out=W[1]),
            ],
            n,
        )
    )


# ----------------------------------------------------------------------------- main


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=10**6, help="arguments per function")
    ap.add_argument("--functions", default="sin,cos,tan,asin,acos,atan,atan2")
    ap.add_argument("--speed-only", action="store_true", help="skip the accuracy measurement")
    args = ap.parse_args()
    if args.speed_only:
        print(f"{machine_line()}; rows of 1024 points, one thread")
        print(
            "| function | `NAME_row` (M/s) | `math.NAME` loop in numba (M/s) | numpy ufunc (M/s) |"
        )
        print("|---|---|---|---|")
        for name in args.functions.split(","):
            fast, libm, npy = speeds(name)
            print(f"| {name} | {fast:.0f} | {libm:.0f} | {npy:.0f} |")
        return
    names = args.functions.split(",")
    rows = []
    with Pool(2) as pool:
        for name in names:
            t0 = time.time()
            if name == "atan2":
                y, x = atan2_arguments(args.n)
                W = np.zeros((3, y.size))
                W[0], W[1] = y, x
                T.atan2_row_vv(W, 2, 0, 1, y.size)
                got = W[2].copy()
                sample = slice(None, None, max(1, y.size // 20000))
                assert np.array_equal(
                    got[sample].view(np.int64), T.atan2_array(y[sample], x[sample]).view(np.int64)
                )
                hi, lo = exact_values(name, y, x, pool)
                count = y.size
            else:
                x = arguments(name, args.n)
                W = np.zeros((2, x.size))
                W[0] = x
                getattr(T, f"{name}_row")(W, 1, 0, x.size)
                got = W[1].copy()
                sample = slice(None, None, max(1, x.size // 20000))
                want = getattr(T, f"{name}_array")(x[sample])
                assert np.array_equal(got[sample].view(np.int64), want.view(np.int64))
                hi, lo = exact_values(name, x, None, pool)
                count = x.size
            nan_ok = np.array_equal(np.isnan(got), np.isnan(hi) & ~_special(name, W))
            err = ulp_errors(got, hi, lo)
            fast, libm, npy = speeds(name)
            rows.append((name, count, err.max(), np.mean(err > 0.5), fast, libm, npy, nan_ok))
            print(
                f"{name}: {count} args, max {err.max():.3f} ulp, NaN positions ok: {nan_ok} "
                f"({time.time() - t0:.0f} s)",
                flush=True,
            )
    print()
    print(f"{machine_line()}; rows of 1024 points, one thread")
    print()
    print(
        "| function | arguments | max ulp | share > 0.5 ulp | `NAME_row` (M/s) "
        "| `math.NAME` loop in numba (M/s) | numpy ufunc (M/s) |"
    )
    print("|---|---|---|---|---|---|---|")
    for name, count, mx, share, fast, libm, npy, _ in rows:
        print(
            f"| {name} | {count:,} | {mx:.3f} | {100 * share:.2f} % | {fast:.0f} | {libm:.0f} "
            f"| {npy:.0f} |"
        )


def _special(name: str, W: np.ndarray) -> np.ndarray:
    """Lanes whose exact value is left out (NaN in ``hi``) but whose result is a number."""
    if name == "atan2":
        y, x = W[0], W[1]
        return (
            ~np.isnan(y) & ~np.isnan(x) & (~np.isfinite(y) | ~np.isfinite(x) | (y == 0) | (x == 0))
        )
    x = W[0]
    return np.isinf(x) & (name == "atan")


if __name__ == "__main__":
    main()
