"""The bounds' compiled planning (:mod:`surfgen.generator.eval.interval_plan`): a range's
minimum and maximum from the sparse tables, NaN and signed zeros included (the levels' items
are tested with :func:`~surfgen.generator.eval.intervals.plan_levels`, in test_intervals.py)."""

from __future__ import annotations

import numpy as np

from surfgen.generator.eval.interval_plan import range_reduce_into, range_tables


def test_range_reductions_are_the_minimum_and_maximum_over_the_range() -> None:
    rng = np.random.default_rng(4)
    for n in (1, 2, 3, 5, 16, 17, 100):
        rows = rng.normal(size=(3, n))
        rows[1, ::4] = np.nan  # NaN wins, as in numpy's minimum and maximum
        first = rng.integers(0, n + 1, 200)
        last = rng.integers(0, n + 1, 200)
        low, high = np.empty((3, 203)), np.empty((3, 203))
        range_reduce_into(range_tables(rows, False), first, last, False, np.inf, low, 3)
        range_reduce_into(range_tables(rows, True), first, last, True, -np.inf, high, 3)
        for i, (a, b) in enumerate(zip(first, last, strict=True)):
            want_lo = rows[:, a:b].min(axis=1) if b > a else np.full(3, np.inf)
            want_hi = rows[:, a:b].max(axis=1) if b > a else np.full(3, -np.inf)
            assert np.array_equal(low[:, 3 + i], want_lo, equal_nan=True)
            assert np.array_equal(high[:, 3 + i], want_hi, equal_nan=True)
        flags = (rng.random((2, n)) < 0.2).astype(np.uint8)
        got = np.zeros((2, 200), dtype=np.uint8)
        range_reduce_into(range_tables(flags, True), first, last, True, 0, got, 0)
        for i, (a, b) in enumerate(zip(first, last, strict=True)):
            assert np.array_equal(got[:, i], flags[:, a:b].max(axis=1) if b > a else [0, 0])


def test_a_signed_zero_s_minimum_is_the_same_whatever_the_order_of_the_windows() -> None:
    """+0 and -0 are equal: the minimum of a range holding both is the first of the two
    windows' (numpy's vector and scalar loops pick differently), so the bounds do not depend
    on which loop a CPU runs."""
    rows = np.array([[-0.0, 0.0, -0.0, 0.0]])
    low = np.empty((1, 3))
    first, last = np.array([0, 1, 0]), np.array([4, 3, 3])
    range_reduce_into(range_tables(rows, False), first, last, False, 0.0, low, 0)
    assert np.array_equal(np.signbit(low[0]), [True, False, True])
