"""The interpreter's row divided by a scalar (``generator/elementary/division.py``): its speed
against the plain division loop it replaces, and its bits against numpy's ``/`` on many cases.

    python benchmarks/bench_division.py [--cases 1000000000] [--repeats 7]

1. **Speed**: ``W[d] = W[a] / s`` over rows of 1024 (the interpreter's tile), the FMA row
   division against a numba loop of ``/`` compiled with the same options, taking turns, best of
   ``--repeats``; prints ns a value for each and their ratio.
2. **Bits**: ``--cases`` dividends (random over the whole exponent range, random bit patterns,
   and quotients built next to a rounding midpoint, as in the tests) against numpy's ``/``;
   prints how many differ (0 is the only right answer).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit

from surfgen.generator.elementary import division as D

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "generator"))
from test_division import _near_midpoints  # noqa: E402


@njit(**D.JIT)
def _plain(W, d, a, s, n):
    for k in range(n):
        W[d, k] = W[a, k] / s


@njit(**D.JIT)
def _repeat(fast, W, s, n, reps):
    for _ in range(reps):
        if fast:
            D.div_row_by_scalar(W, 1, 0, s, n)
        else:
            _plain(W, 1, 0, s, n)


def speed(repeats: int) -> None:
    n, reps = 1024, 20000
    W = np.random.default_rng(0).standard_normal((2, n)) * 1e3
    best = {True: np.inf, False: np.inf}
    for fast in (True, False):
        _repeat(fast, W, 2.7, n, 1)
    for _ in range(repeats):
        for fast in (True, False):
            t = time.perf_counter()
            _repeat(fast, W, 2.7, n, reps)
            best[fast] = min(best[fast], time.perf_counter() - t)
    ns = {k: v / reps / n * 1e9 for k, v in best.items()}
    print(
        f"rows of {n}: FMA row division {ns[True]:.3f} ns a value, plain division "
        f"{ns[False]:.3f} ns: {ns[False] / ns[True]:.2f}x faster (ROW_DIVISION={D.ROW_DIVISION})"
    )


def bits(cases: int) -> None:
    rng = np.random.default_rng(1)
    n = 1 << 20
    done = wrong = fast = rows = 0
    X, S = _near_midpoints(20000, seed=2)
    t0 = time.perf_counter()
    while done < cases:
        kind = (done // n) % 3
        if kind == 0:
            x = rng.uniform(-1, 1, n) * np.exp2(rng.integers(-899, 901, n))
            x = x[np.abs(x) >= D.X_MIN]
            s = float(rng.uniform(-2, 2) * 2.0 ** rng.integers(-99, 100))
        elif kind == 1:
            x = rng.integers(0, 1 << 64, n, dtype=np.uint64).view(np.float64)
            s = float(rng.integers(0, 1 << 64, 1, dtype=np.uint64).view(np.float64)[0])
            if not (D.S_MIN <= abs(s) <= D.S_MAX):
                s = float(np.ldexp(abs(s) % 1.0 + 1.0, int(rng.integers(-100, 100))))
            x = x[np.isfinite(x) & (np.abs(x) >= D.X_MIN) & (np.abs(x) <= D.X_MAX)]
        else:
            i = rng.integers(0, X.size, n)
            x = np.ldexp(X[i], rng.integers(-800, 800, n)) * rng.choice([-1.0, 1.0], n)
            s = float(np.ldexp(S[rng.integers(0, S.size)], int(rng.integers(-140, 40))))
        W = np.empty((2, x.size))
        W[0] = x
        fast += D.div_row_by_scalar_call(W, 1, 0, s, x.size)
        rows += 1
        with np.errstate(all="ignore"):
            want = x / s
        wrong += int((W[1].view(np.uint64) != want.view(np.uint64)).sum())
        done += x.size
    print(
        f"{done} quotients against numpy's /: {wrong} differ; {fast} of {rows} rows of "
        f"about {n} took the FMA path ({time.perf_counter() - t0:.0f} s)"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=1_000_000_000)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    speed(args.repeats)
    bits(args.cases)
    return 0


if __name__ == "__main__":
    sys.exit(main())
