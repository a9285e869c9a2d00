"""The families' order statistics (:mod:`surfgen.generator.model.order_stats`) are numpy's,
bit for bit: random samples with ties, signed zeros, infinities and NaN, every size from 1, the
quantiles the families use and random ones."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.generator.model.order_stats import median, quantile, quantiles

QS = (0.0, 0.05, 0.1, 0.5, 0.9, 0.95, 1.0, 0.25, 0.75, 1 / 3, 0.999, 1e-9)


def same(a, b) -> bool:
    """Equal bits (NaN equal to NaN)."""
    a, b = np.float64(a), np.float64(b)
    return a.tobytes() == b.tobytes() or (np.isnan(a) and np.isnan(b))


def samples(rng: np.random.Generator):
    for n in [*range(1, 40), 100, 1001, 13824]:
        yield rng.normal(size=n)
        yield rng.integers(-3, 4, size=n).astype(np.float64)  # ties, zeros
        mixed = rng.normal(scale=1e3, size=n)
        mixed[rng.random(n) < 0.1] = np.inf
        mixed[rng.random(n) < 0.1] = -np.inf
        mixed[rng.random(n) < 0.1] = -0.0
        yield mixed
        with_nan = rng.normal(size=n)
        with_nan[rng.integers(n)] = np.nan
        yield with_nan


def test_quantiles_and_medians_are_numpys_bit_for_bit():
    rng = np.random.default_rng(3)
    checked = 0
    for a in samples(rng):
        qs = (*QS, *rng.random(4))
        with np.errstate(invalid="ignore"):  # inf - inf: NaN, with numpy's warning either way
            got = quantiles(a, qs)
            want = np.quantile(a, qs)
            assert same(quantile(a, 0.95), np.quantile(a, 0.95))
            assert same(median(a), np.median(a))
        assert all(same(g, w) for g, w in zip(got, want, strict=True)), (a, qs)
        checked += 1
    assert checked > 150


def test_a_grid_of_values_is_taken_whole_and_other_dtypes_go_to_numpy():
    rng = np.random.default_rng(5)
    grid = rng.normal(size=(6, 7, 8))
    assert same(quantile(grid, 0.3), np.quantile(grid, 0.3))
    assert same(median(grid), np.median(grid))
    small = grid.astype(np.float32)
    assert same(quantile(small, 0.3), np.quantile(small, 0.3))
    assert same(median(small), np.median(small))
    assert isinstance(quantiles(grid, (0.1, 0.9))[0], np.float64)


def test_an_empty_sample_fails_as_numpys():
    with pytest.raises(IndexError):
        np.quantile(np.zeros(0), 0.5)
    with pytest.raises(IndexError):
        quantile(np.zeros(0), 0.5)
