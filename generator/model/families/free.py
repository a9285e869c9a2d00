"""The ``free`` family: the first sampler's draw of eq. (13), bounded by the run's grid.

A sum of ``sum_terms`` products of ``factors`` random factors (:func:`draw_factor`), a box of
half-size in ``box_half`` and d at a quantile in ``d_quantile`` of the values; its keys are the
shared ``[sampler]`` keys (:class:`~surfgen.generator.model.draw.DrawSettings`), so it has no
table of its own. A draw whose finest period spans fewer than ``[sampler] period_cells`` cells of
the run's grid, or whose sum has a pole on a plane through the box's centre, is drawn again from
the same stream (:mod:`.gridbound`); with ``period_cells = 0``
the family is the first sampler's draw, unchanged (tests pin its models).
"""

from __future__ import annotations

import math

import numpy as np

from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.grid import Box
from surfgen.generator.model.draw import (
    Draw,
    DrawSettings,
    Family,
    choose,
    draw_factor,
    rng_for,
    round_to,
)
from surfgen.generator.model.equation13 import Equation13
from surfgen.generator.model.families.gridbound import cells_per_period, pole_planes

CHECK_GRID = 24  # samples per axis of the box the bound's arguments are sampled on


def draw_free(seed: int, index: int, cfg: DrawSettings, settings: None = None) -> Draw:
    """Shape ``index`` of the run ``seed`` in the ``free`` family: drawn again from the same
    stream (at most ``resolve_tries`` times in all) while a factor's finest period spans fewer
    than ``period_cells`` cells of the run's grid somewhere in the box, or the sum has a pole on
    a plane through the box's centre (:func:`~.gridbound.pole_planes`; the last draw is kept)."""
    rng = rng_for(seed, index)
    attempt = 0
    while attempt < cfg.resolve_tries:
        attempt += 1
        terms, half, q = _draw_once(rng, cfg)
        if cfg.period_cells <= 0:
            return Draw(Equation13(tuple(terms), 0.0), Box.cube(half), q, "free")
        box = Box.cube(half)
        cell = cfg.cell(half)
        cells = min(
            (cells_per_period(f, box, CHECK_GRID, cell) for t in terms for f in t if any(f.mus)),
            default=math.inf,
        )
        program = compile_tree(Equation13(tuple(terms), 0.0).to_tree())
        poles = pole_planes(program, box, cell, CHECK_GRID)
        if cells >= cfg.period_cells and not poles:
            break
    structure = {
        "tries": attempt,
        "cells_per_period": round(min(cells, 9999.0), 2),
        "pole_planes": poles,
    }
    return Draw(Equation13(tuple(terms), 0.0), Box.cube(half), q, "free", structure)


def _draw_once(rng: np.random.Generator, cfg: DrawSettings) -> tuple[list, float, float]:
    """The first sampler's draw: sum terms, box half-size, d quantile."""
    n_sum = int(choose(rng, cfg.sum_terms, cfg.sum_terms_weights))
    terms = []
    for _ in range(n_sum):
        n_fac = int(choose(rng, cfg.factors, cfg.factors_weights))
        terms.append(tuple(draw_factor(rng, cfg) for _ in range(n_fac)))
    half = round_to(rng.uniform(*cfg.box_half), 1)
    q = float(rng.uniform(*cfg.d_quantile))
    return terms, half, q


FAMILY = Family(
    "free",
    draw_free,
    "the first sampler's draw: random sums of products of eq. (13) factors",
    mix_weight=0.05,
)
