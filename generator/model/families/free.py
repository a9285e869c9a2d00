"""The ``free`` family: the first sampler's draw of eq. (13), unchanged (tests pin its models).

A sum of ``sum_terms`` products of ``factors`` random factors (:func:`draw_factor`), a box of
half-size in ``box_half`` and d at a quantile in ``d_quantile`` of the values; its keys are the
shared ``[sampler]`` keys (:class:`~surfgen.generator.model.draw.DrawSettings`), so it has no
table of its own.
"""

from __future__ import annotations

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


def draw_free(seed: int, index: int, cfg: DrawSettings, settings: None = None) -> Draw:
    """Shape ``index`` of the run ``seed`` in the ``free`` family."""
    rng = rng_for(seed, index)
    n_sum = int(choose(rng, cfg.sum_terms, cfg.sum_terms_weights))
    terms = []
    for _ in range(n_sum):
        n_fac = int(choose(rng, cfg.factors, cfg.factors_weights))
        terms.append(tuple(draw_factor(rng, cfg) for _ in range(n_fac)))
    half = round_to(rng.uniform(*cfg.box_half), 1)
    q = float(rng.uniform(*cfg.d_quantile))
    return Draw(Equation13(tuple(terms), 0.0), Box.cube(half), q, "free")


FAMILY = Family(
    "free",
    draw_free,
    "the first sampler's draw: random sums of products of eq. (13) factors",
    mix_weight=0.12,
)
