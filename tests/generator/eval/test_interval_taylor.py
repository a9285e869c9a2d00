"""The Taylor forms' pairs and kernel (:mod:`surfgen.generator.eval.interval_taylor`): each β's
pairs together with their groups, and two groups weighted per box bounding ``P - r D``."""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from surfgen.generator.eval.interval_taylor import MAX_PAIRS, taylor_bounds, taylor_pairs
from tests.support.interval_checks import random_boxes

P = (np.array([[2, 1, 0], [0, 2, 1], [1, 1, 1], [0, 0, 0]]), np.array([3.0, -2.5, 1e8, -7.0]))
D = (np.array([[2, 0, 0], [0, 2, 0], [0, 0, 0]]), np.array([1.0, 1.0, 0.01]))
_U = 2.0**-53


def test_the_pairs_are_grouped_by_beta_with_their_groups() -> None:
    """Every pair of a β is together (``starts``), its power of the centre is ``α - β`` of a
    monomial of its group, and a shift longer than MAX_PAIRS is refused."""
    exps, coefs = np.vstack([P[0], D[0]]), np.concatenate([P[1], D[1]])
    coef, expo, which, starts, betas = taylor_pairs(exps, coefs, [0] * 4 + [1] * 3)
    assert len(coef) == int(np.prod(exps + 1, axis=1).sum())
    ends = [*starts[1:], len(coef)]
    for b, (s, e) in enumerate(zip(starts, ends, strict=True)):
        for q in range(s, e):
            alpha = expo[q] + betas[b]
            group = P[0] if which[q] == 0 else D[0]
            assert any((alpha == m).all() for m in group)
    big = np.array([[8, 8, 8], [8, 8, 7]])
    assert MAX_PAIRS < 2 * 9**3 and taylor_pairs(big, np.ones(2)) is None


def exact(mono, x) -> Fraction:
    exps, coefs = mono
    x0, x1, x2 = (Fraction(v) for v in x)
    return sum(Fraction(c) * x0 ** e[0] * x1 ** e[1] * x2 ** e[2]
               for e, c in zip(exps.tolist(), coefs.tolist(), strict=True))  # fmt: skip


def test_two_groups_bound_p_minus_r_d() -> None:
    """Weighted 1 and ``-r`` per box, the pairs of P and D bound ``P - r D`` exactly computed
    at random points of the boxes (in exact fractions)."""
    rng = np.random.default_rng(1)
    blo, bhi = random_boxes(rng, [-2.0] * 3, [2.0] * 3, 40)
    exps, coefs = np.vstack([P[0], D[0]]), np.concatenate([P[1], D[1]])
    pairs = taylor_pairs(exps, coefs, [0] * 4 + [1] * 3)
    absolute = (exps, np.abs(coefs), np.array([0] * 4 + [1] * 3))
    r = rng.uniform(-50, 50, len(blo))
    lo, hi = taylor_bounds(pairs, absolute, 2, _U, blo, bhi, 1, np.stack([np.ones(len(r)), -r]))
    for k in range(len(blo)):
        for u in rng.uniform(0, 1, (6, 3)):
            x = blo[k] + u * (bhi[k] - blo[k])
            v = exact(P, x) - Fraction(r[k]) * exact(D, x)
            assert Fraction(lo[k]) <= v <= Fraction(hi[k])
