"""The resolution bound: at grids 32, 64 and 128 every family's finest period spans at least
``period_cells`` cells of the run's grid, measured here independently of the draw's own check
(exactly for linear arguments; on a finer grid for the others), and infill struts are resolved."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage

from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.parser import parse
from surfgen.generator.model.draw import only_b
from surfgen.generator.model.equation13 import Equation13, PowerFunction, PowerTerm, Transform
from surfgen.generator.model.families.gridbound import (
    cells_per_period,
    fit_factor,
    period_of,
    pole_planes,
    scale_arguments,
)
from surfgen.generator.model.sampler import SamplerConfig, draw_equation

GRIDS = (32, 64, 128)


def config(family: str, grid: int) -> SamplerConfig:
    """The family's own draws (not stretched: the bound is the family's; a stretch keeps the
    samples of every period, tests/generator/model/test_stretch.py)."""
    return replace(SamplerConfig(), family=family, aspect_prob=0.0).with_grid(grid)


def linear_cells(draw, cfg: SamplerConfig) -> float:
    """The finest period in cells of a draw whose H arguments are linear: exact, from the
    coefficients (a constant term shifts, it does not speed up)."""
    cell = cfg.cell(draw.box.hi[0])
    worst = math.inf
    for term in draw.equation.terms:
        for f in term:
            if not f.mus[0]:
                continue
            arg = f.powers[2]
            speed = math.sqrt(
                sum(sum(t.a for t in arg.terms if (t.b, t.c, t.d)[k] == 1) ** 2 for k in range(3))
            )
            if speed:
                worst = min(worst, period_of(f.h) / (speed * cell))
    return worst


@pytest.mark.parametrize("grid", GRIDS)
@pytest.mark.parametrize("family", ["lattice", "twist"])
def test_linear_families_resolve_every_period(family: str, grid: int) -> None:
    cfg = config(family, grid)
    for i in range(25):
        draw = draw_equation(13, i, cfg)
        assert linear_cells(draw, cfg) >= cfg.period_cells * 0.99, (family, grid, i)


@pytest.mark.parametrize("grid", GRIDS)
def test_twist_lobes_around_the_axis_are_resolved(grid: int) -> None:
    cfg = config("twist", grid)
    for i in range(25):
        draw = draw_equation(5, i, cfg)
        st = draw.structure
        valley = 1 / math.sqrt(1 + st["lobe_depth"])
        arc = 2 * math.pi * valley / st["lobes"]
        assert st["lobes"] == 2 or arc >= cfg.period_cells * cfg.cell(draw.box.hi[0]) * 0.9


def test_a_coarser_grid_draws_fewer_lobes_and_periods() -> None:
    coarse = [draw_equation(3, i, config("twist", 16)).structure for i in range(30)]
    fine = [draw_equation(3, i, config("twist", 128)).structure for i in range(30)]
    assert sum(s["lobes"] for s in coarse) < sum(s["lobes"] for s in fine)
    lat = [draw_equation(3, i, config("lattice", 16)).structure["periods"] for i in range(30)]
    lat_fine = [draw_equation(3, i, config("lattice", 128)).structure["periods"] for i in range(30)]
    assert sum(lat) < sum(lat_fine)


def thinnest_cells(draw, grid: int) -> float:
    """The thinner of the infill's struts and pores inside its envelope on the run's own grid
    (``grid`` samples per axis): twice the 10th percentile of the distance transform's ridge."""
    clips = 2 * draw.structure["clips"]
    lattice = Equation13(draw.equation.terms[:-clips], draw.d).to_tree()
    clip = Equation13(draw.equation.terms[-clips:], 0.0).to_tree()
    g = Grid(draw.box, (grid,) * 3)
    v = evaluate(lattice, g, threads=1).values
    inside = evaluate(clip, g, threads=1).values == 0
    inner = ndimage.binary_erosion(inside, iterations=3)  # away from the envelope's cut
    out = math.inf
    for phase in (v < 0, v >= 0):
        dist = ndimage.distance_transform_edt(phase)
        ridge = phase & (dist >= ndimage.maximum_filter(dist, size=3)) & inner
        if ridge.any():
            out = min(out, 2 * float(np.quantile(dist[ridge], 0.1)))
    return out


@pytest.mark.parametrize("grid", (32, 64))
def test_infill_struts_and_pores_span_three_cells(grid: int) -> None:
    cfg = config("infill", grid)
    for i in range(8):
        draw = draw_equation(21, i, cfg)
        assert draw.structure["strut_cells"] >= 3.0 - 1e-9
        # measured on the run's grid, in the middle of the envelope: a sampled ridge is within
        # a cell of the true one, so allow one cell
        assert thinnest_cells(draw, grid) >= 2.0, (grid, i, draw.structure)


@pytest.mark.parametrize("grid", GRIDS)
@pytest.mark.parametrize("family", ["sculpture", "free"])
def test_ornaments_and_free_draws_are_slowed_to_the_grid(family: str, grid: int) -> None:
    """Re-measured on a finer grid (40^3, whole box for free, the recorded cells for the
    ornaments): most draws are resolved, and all the ones the draw calls resolved are within
    the sampling's tolerance."""
    cfg = config(family, grid)
    resolved = 0
    n = 12
    for i in range(n):
        draw = draw_equation(17, i, cfg)
        if family == "sculpture":
            cells = draw.structure["ornament"]["cells_per_period"]
        else:
            cells = draw.structure["cells_per_period"]
            fine = min(
                (
                    cells_per_period(f, draw.box, 40, cfg.cell(draw.box.hi[0]))
                    for t in draw.equation.terms
                    for f in t
                    if any(f.mus)
                ),
                default=math.inf,  # no H: nothing periodic
            )
            if cells >= cfg.period_cells:
                assert fine >= 0.8 * cfg.period_cells, (i, cells, fine)
        resolved += cells >= cfg.period_cells
    assert resolved >= 0.75 * n


def test_fit_factor_slows_a_wave_to_the_bound() -> None:
    wave = only_b(PowerFunction((PowerTerm(40.0, 1.0),)), Transform("sin"))  # sin(40 x)
    box = Box.cube(1.0)
    cell = 2 / 63
    assert cells_per_period(wave, box, 8, cell) == pytest.approx(2 * math.pi / (40 * cell))
    slowed, alpha, cells = fit_factor(wave, box, 8, cell, 8.0)
    assert 7.9 <= cells < 8.0 / 0.97 and alpha < 1
    assert slowed == scale_arguments(wave, alpha)
    # a pulse counts its shorter level: rect2 with t/r = 0.1 is 0.1 r; a triangle its corners
    assert period_of(Transform("rect2", (1.0, 0.9))) == pytest.approx(0.1)
    assert period_of(Transform("saw2", (0.7,))) == 0.7
    assert period_of(Transform("tri3", (0.7,))) == 0.35
    assert period_of(Transform("tan")) == pytest.approx(math.pi)


@pytest.mark.parametrize(
    ("formula", "planes"),
    [
        ("x^2+y^2+z^2-1", 0),
        ("x^2+y^2+z^2-1+0.01/(y^2*z)", 2),  # y^2 z vanishes on y = 0 and on z = 0
        ("x^2+y^2+z^2-1+0.01/x", 1),
        ("x^2+y^2+z^2-1+0.01*cot(x*y*z)", 3),  # cot(0): every plane through the centre
        ("x^2+y^2+z^2-1+0.01/(x^2+y^2)", 0),  # a pole on a line (the z axis), not a plane
        ("x^2+y^2+z^2-1+0.01/(x^2+(y-z)^2)", 0),  # a line in the plane x = 0: sampled, not counted
        ("x^2+y^2+z^2-1+0.01/(y-0.3)", 0),  # a plane, but not through the centre
        ("x^2+y^2+z^2-1+sqrt(0.5-x^2)", 0),  # non-finite beyond |x| > 0.7: not a thin plane
    ],
)
def test_pole_planes_counts_the_poles_an_odd_grid_would_sample(formula: str, planes: int) -> None:
    box, cell = Box.cube(1.5), 3.0 / 63
    tree = parse(formula)
    assert pole_planes(compile_tree(tree), box, cell) == planes
    # an odd grid samples those planes: non-finite there, finite on the planes beside them
    finite = np.isfinite(evaluate(tree, Grid(box, (65,) * 3)).values)
    found = 0
    for axis in range(3):
        a = np.moveaxis(finite, axis, 0)
        found += np.count_nonzero(~a[32] & a[31] & a[33]) > 65
    assert found == planes


@pytest.mark.parametrize("family", ["sculpture", "free"])
def test_draws_have_no_pole_on_a_plane_through_the_centre(family: str) -> None:
    """Ornaments (and free draws) with a pole on x, y or z = 0 are redrawn: the whole formula,
    re-measured on a finer plane grid, has none, and the draw records none."""
    cfg = config(family, 64)
    for i in range(16):
        draw = draw_equation(7, i, cfg)
        s = draw.structure["ornament"] if family == "sculpture" else draw.structure
        if family == "free" and s["tries"] == cfg.resolve_tries:
            continue  # the last of the tries is kept, whatever it is
        assert s["pole_planes"] == 0, (i, s)
        program = compile_tree(draw.equation.with_d(0.0).to_tree())
        assert pole_planes(program, draw.box, cfg.cell(draw.box.hi[0]), n=40) == 0, i
