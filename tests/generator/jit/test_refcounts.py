"""The reading of numba's reference counting in loops (:mod:`tests.support.refcounts`) that the
kernels' tests use: it finds the counting a reassigned array leaves in a loop, and none where
the loop only indexes its arrays."""

from __future__ import annotations

import numpy as np

from tests.support.refcounts import kernel_ir, loop_refcounts, loops, refcounts_in_loops


def _growing(n):
    a = np.empty(2)
    for i in range(n):
        if i == a.size:  # grown as it fills, as the Lewiner pass's arrays were, cell by cell
            b = np.empty(2 * a.size)
            for k in range(i):
                b[k] = a[k]
            a = b
        a[i] = np.sin(i)
    return a[n - 1]


def _sized(n):
    a = np.empty(max(n, 1))  # the same values in an array sized before the loop
    for i in range(n):
        a[i] = np.sin(i)
    return a[n - 1]


def test_counting_left_in_a_loop_is_found():
    body = kernel_ir(_growing, 10)
    assert refcounts_in_loops(body) > 0
    assert loop_refcounts(body, "sin") > 0  # the loop around the call of sin


def test_a_loop_that_only_indexes_counts_nothing():
    body = kernel_ir(_sized, 10)
    _, found = loops(body)
    assert found  # the loop is seen
    assert refcounts_in_loops(body) == 0
    assert loop_refcounts(body, "sin") == 0
