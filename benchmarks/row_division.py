"""The interpreter's row divided by a scalar (``generator/elementary/division.py``): its speed
against the plain division loop it replaces, and its bits against numpy's ``/`` on many cases.

    python -m benchmarks.row_division [--cases 1000000000] [--hard 10000000] [--repeats 7]

1. **Speed**: ``W[d] = W[a] / s`` over rows of 1024 (the interpreter's tile), the FMA row
   division against a numba loop of ``/`` compiled with the same options, taking turns, best of
   ``--repeats``; prints ns a value for each and their ratio.
2. **Bits**: ``--cases`` dividends (random over the whole exponent range, and random bit
   patterns) and ``--hard`` quotients built next to a rounding midpoint (as in the tests), each
   against numpy's ``/``; prints how many differ (0 is the only right answer) and how many rows
   took the FMA path.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from numba import njit

from benchmarks import harness
from surfgen.generator.elementary import division as D
from surfgen.generator.jit.options import KERNEL
from tests.support.division_cases import midpoint_row


@njit(**KERNEL)
def _plain(W, d, a, s, n):
    for k in range(n):
        W[d, k] = W[a, k] / s


@njit(**KERNEL)
def _repeat(fast, W, s, n, reps):
    for _ in range(reps):
        if fast:
            D.div_row_by_scalar(W, 1, 0, s, n)
        else:
            _plain(W, 1, 0, s, n)


def speed(run: harness.Run, repeats: int) -> None:
    """The FMA row division against the plain loop, taking turns, best of ``repeats``."""
    n, reps = 1024, 20000
    W = np.random.default_rng(0).standard_normal((2, n)) * 1e3
    for fast in (True, False):
        _repeat(fast, W, 2.7, n, 1)
    timings = harness.take_turns(
        {
            "fma": lambda: _repeat(True, W, 2.7, n, reps),
            "plain": lambda: _repeat(False, W, 2.7, n, reps),
        },
        repeats,
    )
    ns = {k: t.best / reps / n * 1e9 for k, t in timings.items()}
    run.say(
        f"rows of {n}: FMA row division {ns['fma']:.3f} ns a value, plain division "
        f"{ns['plain']:.3f} ns: {harness.ratio(ns['plain'], ns['fma']):.2f}x faster"
        f" (ROW_DIVISION={D.ROW_DIVISION})"
    )
    run.record(ns_per_value=ns)


def random_rows(rng: np.random.Generator):
    """Rows of about 2**20 dividends with one divisor: random over the whole fast range, and
    random bit patterns (kept to the fast range), in turn."""
    n = 1 << 20
    while True:
        x = rng.uniform(-1, 1, n) * np.exp2(rng.integers(-899, 901, n))
        s = float(rng.uniform(-2, 2) * 2.0 ** rng.integers(-99, 100))
        yield x[np.abs(x) >= D.X_MIN], s
        x = rng.integers(0, 1 << 64, n, dtype=np.uint64).view(np.float64)
        s = float(rng.integers(0, 1 << 64, 1, dtype=np.uint64).view(np.float64)[0])
        if not (D.S_MIN <= abs(s) <= D.S_MAX):
            s = float(np.ldexp(abs(s) % 1.0 + 1.0, int(rng.integers(-100, 100))))
        yield x[np.isfinite(x) & (np.abs(x) >= D.X_MIN) & (np.abs(x) <= D.X_MAX)], s


def hard_rows(rng: np.random.Generator):
    """Rows of quotients next to a rounding midpoint, each with its own divisor (the tests'
    ``midpoint_row``: within 2**-46 of an ulp of the midpoint)."""
    while True:
        row = midpoint_row(rng)
        if row is not None:
            yield row


def tally(run: harness.Run, label: str, rows, cases: int) -> None:
    """Divide rows until ``cases`` quotients are done; print how many differ from numpy's."""
    done = wrong = fast = count = 0
    t0 = time.perf_counter()
    for x, s in rows:
        if done >= cases:
            break
        wrong_row, fast_row = _check(x, s)
        wrong += wrong_row
        fast += fast_row
        count += 1
        done += x.size
    run.say(
        f"{done} {label} against numpy's /: {wrong} differ; {fast} of {count} rows took the "
        f"FMA path ({time.perf_counter() - t0:.0f} s)"
    )
    run.record(**{label: {"cases": done, "differ": wrong, "fma_rows": fast, "rows": count}})


def _check(x: np.ndarray, s: float) -> tuple[int, bool]:
    W = np.empty((2, x.size))
    W[0] = x
    took = D.div_row_by_scalar_call(W, 1, 0, s, x.size)
    with np.errstate(all="ignore"):
        want = x / s
    return int((W[1].view(np.uint64) != want.view(np.uint64)).sum()), bool(took)


def main(argv: list[str] | None = None) -> int:
    ap = harness.parser(__doc__, repeats=7)
    ap.add_argument("--cases", type=int, default=1_000_000_000)
    ap.add_argument("--hard", type=int, default=10_000_000, help="quotients next to a midpoint")
    args = ap.parse_args(argv)
    run = harness.Run("row_division", args)
    speed(run, args.repeats)
    tally(run, "random quotients", random_rows(np.random.default_rng(1)), args.cases)
    hard = hard_rows(np.random.default_rng(3))
    tally(run, "quotients next to a rounding midpoint", hard, args.hard)
    run.save()
    return 0


if __name__ == "__main__":
    sys.exit(main())
