"""The series row (``row_operations.series_row``: the sum of eqs. (2)-(4) in saw1, tri1, stair1)
against the scalar loop it replaced, measured in one run.

    python -m benchmarks.series_row [--repeats 20] [--json PATH]

The baseline is the loop of the revision before: ``W[d, k] = _series(W[a, k], r, p)`` per
value, an early exit and a search that LLVM cannot vectorise. The row now runs a branch-free
loop (three candidate segments around ``x * (1/r)`` and a select) and patches NaN, inf and huge
values the slow way. Both are timed in turn on rows of 1024 values (the interpreter's tile),
best of ``--repeats`` x 500 calls, for a few periods and sizes of the sum; the two must give
the same bits.
"""

from __future__ import annotations

import sys

import numpy as np
from numba import njit

from benchmarks import harness
from surfgen.generator.eval import row_operations

N = 1024
CASES = [(0.5, 6, 4.0), (0.37, 12, 6.0), (1.0, 1, 3.0), (2.5, 40, 120.0)]  # r, p, |x| range


@njit(error_model="numpy", nogil=True)
def _scalar_row(W, d, a, n, consts, base):
    """The row before: one call of the scalar ``_series`` per value."""
    r = consts[base]
    p = int(consts[base + 1])
    for k in range(n):
        W[d, k] = row_operations.series(W[a, k], r, p)


def _calls(row, W, d: int, consts: np.ndarray, calls: int = 500):
    """``row`` into ``W[d]`` ``calls`` times, as one timed candidate."""

    def repeat() -> None:
        for _ in range(calls):
            row(W, d, 0, N, consts, 0)

    return repeat


def main(argv: list[str] | None = None) -> int:
    ap = harness.parser(__doc__, repeats=20)
    args = ap.parse_args(argv)
    run = harness.Run("series_row", args)
    rng = np.random.default_rng(7)
    ratios = []
    for r, p, span in CASES:
        W = np.zeros((3, N))
        W[0] = rng.uniform(-span, span, N)
        consts = np.array([r, float(p), 0.0])
        _scalar_row(W, 1, 0, N, consts, 0)
        row_operations.series_row(W, 2, 0, N, consts, 0)
        same = np.array_equal(W[1].view(np.int64), W[2].view(np.int64))
        timings = harness.take_turns(
            {
                "before": _calls(_scalar_row, W, 1, consts),
                "now": _calls(row_operations.series_row, W, 2, consts),
            },
            args.repeats,
        )
        best = {key: t.best / 500 for key, t in timings.items()}
        ratio = harness.ratio(best["before"], best["now"])
        ratios.append(ratio)
        run.record(**{f"r={r}, p={p}": {"seconds_per_row": best, "same_bits": same}})
        run.say(
            f"r = {r}, p = {p}, |x| < {span}: {best['now'] / N * 1e9:.2f} ns per value now,"
            f" {best['before'] / N * 1e9:.2f} before: {ratio:.2f}x"
            f"{'' if same else '  BITS DIFFER'}"
        )
    run.say(f"median {np.median(ratios):.2f}x")
    run.save()
    return 0


if __name__ == "__main__":
    sys.exit(main())
