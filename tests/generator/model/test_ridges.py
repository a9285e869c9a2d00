"""The ridge of the distance transform is scipy's, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.parser import parse
from surfgen.generator.model.ridges import ridge_distances


def _scipy(phase: np.ndarray, lo: int, hi: int) -> np.ndarray:
    dist = ndimage.distance_transform_edt(phase)
    ridge = phase & (dist >= ndimage.maximum_filter(dist, size=3))
    cube = np.zeros(phase.shape, dtype=bool)
    cube[lo:hi, lo:hi, lo:hi] = True
    return dist[ridge & cube]


def _lattice(formula: str, n: int = 32) -> np.ndarray:
    grid = Grid(Box((0.0,) * 3, ((n - 1) / (n // 2),) * 3), (n,) * 3)
    return evaluate(parse(formula), grid, evaluator="reference").values


GYROID = "sin(6.2832*x)*cos(6.2832*y)+sin(6.2832*y)*cos(6.2832*z)+sin(6.2832*z)*cos(6.2832*x)"
SCHWARZ = "cos(6.2832*x)+cos(6.2832*y)+cos(6.2832*z)"


@pytest.mark.parametrize("formula", [GYROID, SCHWARZ])
@pytest.mark.parametrize("t", [-0.9, 0.0, 0.4])
def test_the_ridges_of_lattice_phases_are_scipy_s(formula: str, t: float) -> None:
    values = _lattice(formula)
    for phase in (values < t, values >= t):
        got = ridge_distances(phase, 8, 24)
        want = _scipy(phase, 8, 24)
        assert got.size and got.tobytes() == want.tobytes()


def test_random_phases_odd_shapes_and_a_cube_past_the_faces() -> None:
    rng = np.random.default_rng(4)
    for shape, share in (((9, 14, 11), 0.93), ((20, 7, 13), 0.6), ((5, 5, 5), 0.995)):
        phase = rng.random(shape) < share
        phase.flat[rng.integers(phase.size)] = False  # a sample outside, at least
        for lo, hi in ((0, 20), (2, 6), (-3, 4)):
            got = ridge_distances(phase, lo, hi)
            want = _scipy(phase, max(lo, 0), hi)
            assert got.tobytes() == want.tobytes()
    # one sample outside a long bar: distances up to the far end, every one exact
    phase = np.ones((40, 3, 2), dtype=bool)
    phase[0, 0, 0] = False
    assert ridge_distances(phase, 0, 40).tobytes() == _scipy(phase, 0, 40).tobytes()
