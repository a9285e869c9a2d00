"""The interpreter's row divided by a scalar (``generator/elementary/division.py``): its speed
against the plain division loop it replaces, and its bits against numpy's ``/`` on many cases.

    python benchmarks/bench_division.py [--cases 1000000000] [--hard 10000000] [--repeats 7]

1. **Speed**: ``W[d] = W[a] / s`` over rows of 1024 (the interpreter's tile), the FMA row
   division against a numba loop of ``/`` compiled with the same options, taking turns, best of
   ``--repeats``; prints ns a value for each and their ratio.
2. **Bits**: ``--cases`` dividends (random over the whole exponent range, and random bit
   patterns) and ``--hard`` quotients built next to a rounding midpoint (as in the tests), each
   against numpy's ``/``; prints how many differ (0 is the only right answer) and how many rows
   took the FMA path.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from numba import njit

from surfgen.generator.elementary import division as D


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
    """Random dividends over the whole fast range, and random bit patterns, in rows of 2**20."""
    rng = np.random.default_rng(1)
    n = 1 << 20
    done = wrong = fast = rows = 0
    t0 = time.perf_counter()
    while done < cases:
        if rows % 2 == 0:
            x = rng.uniform(-1, 1, n) * np.exp2(rng.integers(-899, 901, n))
            x = x[np.abs(x) >= D.X_MIN]
            s = float(rng.uniform(-2, 2) * 2.0 ** rng.integers(-99, 100))
        else:
            x = rng.integers(0, 1 << 64, n, dtype=np.uint64).view(np.float64)
            s = float(rng.integers(0, 1 << 64, 1, dtype=np.uint64).view(np.float64)[0])
            if not (D.S_MIN <= abs(s) <= D.S_MAX):
                s = float(np.ldexp(abs(s) % 1.0 + 1.0, int(rng.integers(-100, 100))))
            x = x[np.isfinite(x) & (np.abs(x) >= D.X_MIN) & (np.abs(x) <= D.X_MAX)]
        wrong_row, fast_row = _check(x, s)
        wrong += wrong_row
        fast += fast_row
        rows += 1
        done += x.size
    print(
        f"{done} random quotients against numpy's /: {wrong} differ; {fast} of {rows} rows of "
        f"about {n} took the FMA path ({time.perf_counter() - t0:.0f} s)"
    )


def hard(cases: int) -> None:
    """Quotients next to a rounding midpoint: for a random odd 53-bit divisor S and each odd
    t in [-63, 63], the 53-bit X with X * 2**54 = S*M + t, M odd (a midpoint of 53-bit
    quotients), so that X/S lies within |t|/S of an ulp (below 2**-46) of that midpoint; one
    row per divisor, both scaled by random powers of two and signs."""
    rng = np.random.default_rng(3)
    done = wrong = fast = rows = 0
    t0 = time.perf_counter()
    while done < cases:
        S = int(rng.integers(1 << 52, 1 << 53)) | 1
        inv = pow(S, -1, 1 << 54)
        xs = []
        for t in range(-63, 64, 2):
            M = (-t * inv) % (1 << 54)
            if M >= (1 << 53):
                X = (S * M + t) >> 54
                if (1 << 52) <= X < (1 << 53):
                    xs.append(float(X))
        if not xs:
            continue
        sign = float(rng.choice([-1.0, 1.0]))
        x = np.ldexp(np.array(xs), int(rng.integers(-840, 840))) * sign
        s = float(np.ldexp(float(S), int(rng.integers(-150, 40))))
        wrong_row, fast_row = _check(x, s)
        wrong += wrong_row
        fast += fast_row
        rows += 1
        done += x.size
    print(
        f"{done} quotients next to a rounding midpoint: {wrong} differ; {fast} of {rows} rows "
        f"took the FMA path ({time.perf_counter() - t0:.0f} s)"
    )


def _check(x: np.ndarray, s: float) -> tuple[int, bool]:
    W = np.empty((2, x.size))
    W[0] = x
    took = D.div_row_by_scalar_call(W, 1, 0, s, x.size)
    with np.errstate(all="ignore"):
        want = x / s
    return int((W[1].view(np.uint64) != want.view(np.uint64)).sum()), bool(took)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=1_000_000_000)
    ap.add_argument("--hard", type=int, default=10_000_000, help="quotients next to a midpoint")
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    speed(args.repeats)
    bits(args.cases)
    hard(args.hard)
    return 0


if __name__ == "__main__":
    sys.exit(main())
