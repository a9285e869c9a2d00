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


def _struts_by_scipy(unit, q: float, q_rim: float, reach: float) -> tuple[float, float, float]:
    """The infill's strut share as scipy measured it (the code before the numba transform)."""
    from surfgen.generator.model.families.infill import CELL_SAMPLES, _tree
    from surfgen.generator.model.order_stats import quantile

    m = CELL_SAMPLES
    n = 2 * m
    grid = Grid(Box((0.0,) * 3, ((n - 1) / m,) * 3), (n,) * 3)
    values = evaluate(_tree(unit), grid, threads=1).values
    t_c = float(quantile(values, q))
    t_r = float(quantile(values, q_rim))
    middle = np.zeros(values.shape, dtype=bool)
    middle[m // 2 : m // 2 + m, m // 2 : m // 2 + m, m // 2 : m // 2 + m] = True
    thinnest = np.inf
    for t in {t_c, t_c + (t_r - t_c) * reach}:
        for phase in (values < t, values >= t):
            if not phase.any():
                return t_c, t_r, 0.0
            dist = ndimage.distance_transform_edt(phase)
            ridge = phase & (dist >= ndimage.maximum_filter(dist, size=3)) & middle
            if not ridge.any():
                return t_c, t_r, 0.0
            thinnest = min(thinnest, 2.0 * float(quantile(dist[ridge], 0.1)) / m)
    return t_c, t_r, thinnest


@pytest.mark.parametrize("pattern", ["gyroid", "schwarz", "iwp"])
def test_the_infill_struts_are_scipy_s_even_past_the_values(pattern: str) -> None:
    """strut_share gives scipy's numbers, including a rim level past every value (a reach far
    beyond the rim: no sample outside the phase, where scipy's transform still gives numbers)."""
    from surfgen.generator.model.families.infill import _transforms, strut_share
    from surfgen.generator.model.families.lattice import lattice_terms

    unit = lattice_terms(np.random.default_rng(3), pattern, *_transforms(pattern), [1.0] * 3)
    for q, q_rim, reach in ((0.5, 0.5, 1.0), (0.3, 0.6, 1.4), (0.5, 0.95, 60.0)):
        assert strut_share(unit, q, q_rim, reach) == _struts_by_scipy(unit, q, q_rim, reach)


def test_a_phase_with_nothing_outside_it_keeps_scipy_s_numbers() -> None:
    from surfgen.generator.model.families.infill import phase_widths

    whole = np.ones((32, 32, 32), dtype=bool)
    assert phase_widths(whole, 16).tobytes() == _scipy(whole, 8, 24).tobytes()
    assert np.isfinite(phase_widths(whole, 16)).all()
    holed = whole.copy()
    holed[3, 30, 7] = False
    assert phase_widths(holed, 16).tobytes() == _scipy(holed, 8, 24).tobytes()
