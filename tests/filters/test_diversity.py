"""The Vendi score: known values, and the descriptor kernel it is computed with."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.filters.descriptor import descriptor
from surfgen.filters.diversity import BANDWIDTH, descriptor_vendi, similarity, vendi_score
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import extract_mesh


@pytest.mark.parametrize("n", [1, 2, 7, 50])
def test_identical_items_count_once_and_orthogonal_ones_each(n: int) -> None:
    assert vendi_score(np.ones((n, n))) == pytest.approx(1.0)
    assert vendi_score(np.eye(n)) == pytest.approx(n)


def test_two_groups_and_partial_similarity() -> None:
    # two groups of identical items: 2 distinct items whatever the group sizes are equal
    k = np.kron(np.eye(2), np.ones((5, 5)))
    assert vendi_score(k) == pytest.approx(2.0)
    # two items of similarity s: eigenvalues (1 +- s) / 2
    s = 0.6
    lam = np.array([(1 + s) / 2, (1 - s) / 2])
    want = float(np.exp(-(lam * np.log(lam)).sum()))
    assert vendi_score(np.array([[1, s], [s, 1]])) == pytest.approx(want)
    assert 1.0 < want < 2.0


def test_bad_kernels_are_refused() -> None:
    assert vendi_score(np.zeros((0, 0))) == 0.0
    with pytest.raises(ValueError, match="square"):
        vendi_score(np.ones((2, 3)))
    with pytest.raises(ValueError, match="diagonal"):
        vendi_score(2 * np.eye(3))


def _describe(formula: str, half: float) -> np.ndarray:
    grid = Grid(Box.cube(half), (24,) * 3)
    return descriptor(extract_mesh(evaluate_reference(parse(formula), grid), cap=True))


def test_the_descriptor_kernel_is_a_similarity() -> None:
    rows = np.array(
        [
            _describe("x^2+y^2+z^2-1", 1.5),
            _describe("x^2+y^2+z^2-1", 1.4),  # the same sphere, meshed a little differently
            _describe("(sqrt(x^2+y^2)-1)^2+z^2-0.16", 1.6),
            _describe("sin(2*x)*cos(2*y)+sin(2*y)*cos(2*z)+sin(2*z)*cos(2*x)", 3.0),
        ]
    )
    k = similarity(rows)
    assert np.array_equal(k, k.T) and np.allclose(np.diag(k), 1.0)
    assert np.linalg.eigvalsh(k).min() > -1e-9  # positive semi-definite
    assert k[0, 1] > 0.5 > k[0, 2] and k[0, 3] < k[0, 1]
    score = descriptor_vendi(rows)
    assert 2.0 < score < 4.0  # two spheres count as about one
    assert descriptor_vendi(rows[[0, 0, 0]]) == pytest.approx(1.0)
    # a wider kernel finds everything more alike
    assert descriptor_vendi(rows, 4 * BANDWIDTH) < score
    with pytest.raises(ValueError, match="bandwidth"):
        similarity(rows, 0.0)
    with pytest.raises(ValueError, match="values"):
        similarity(rows[:, :10])
