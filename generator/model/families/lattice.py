"""The ``lattice`` family: triply periodic patterns of linear arguments, cut by the box.

Schwarz-like ``Σ H(w x_k)``, gyroid-like ``Σ_cyclic H1(w x_k) H2(w x_k+1)``, or a product
``Π H(w x_k)`` plus a Schwarz part, and the triply periodic minimal surfaces diamond (Schwarz
D), neovius and iwp (Schoen I-WP) — with H a sine/cosine or a continuous or pulse constituent
function (Figure 3's porous cubes); cut by the box and capped; d at a quantile near the middle
of the values. Its keys: the ``[sampler.lattice]`` table (:class:`LatticeSettings`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from surfgen.generator.errors import SpecError
from surfgen.generator.eval.grid import Box
from surfgen.generator.model.draw import (
    Draw,
    DrawSettings,
    Family,
    choose,
    constant,
    only_b,
    rng_for,
    round_significant,
)
from surfgen.generator.model.equation13 import (
    Equation13,
    Factor,
    PowerFunction,
    PowerTerm,
    Transform,
)
from surfgen.generator.model.families.gridbound import fit_terms
from surfgen.generator.model.settings import (
    require_fractions,
    require_low_high,
    require_names,
    require_numbers,
    require_range,
    require_weighted_pairs,
)

LATTICE_PATTERNS = ("schwarz", "gyroid", "product", "diamond", "neovius", "iwp")
# Continuous and pulse constituents for lattices (saw teeth would draw walls at every jump).
LATTICE_CONSTITUENTS = ("tri2", "tri3", "rect2")
TABLE = "sampler.lattice"


@dataclass(frozen=True)
class LatticeSettings:
    """The ``[sampler.lattice]`` table (``surfgen config show``)."""

    patterns: tuple[str, ...] = LATTICE_PATTERNS
    pattern_weights: tuple[float, ...] = (0.15, 0.2, 0.15, 0.2, 0.15, 0.15)
    periods: tuple[float, float] = (1.0, 2.5)  # periods across the box
    anisotropy_prob: float = 0.5  # each axis's period scaled by its own factor
    anisotropy: tuple[float, float] = (0.6, 1.6)  # that factor's range
    constituent_prob: float = 0.3  # a constituent function instead of sin/cos
    d_quantile: tuple[float, float] = (0.25, 0.6)

    def __post_init__(self) -> None:
        require_names(self, "patterns", LATTICE_PATTERNS, TABLE)
        require_numbers(self, ("pattern_weights",), TABLE)
        require_weighted_pairs(self, (("patterns", "pattern_weights"),), TABLE)
        require_fractions(self, ("constituent_prob", "anisotropy_prob"), TABLE, "a probability")
        require_low_high(self, ("periods", "d_quantile", "anisotropy"), TABLE)
        require_range(self, "anisotropy", 0.1, 10, TABLE)
        if not self.periods[0] > 0:
            raise SpecError(f"config [{TABLE}]: periods must be > 0")
        if not 0 <= self.d_quantile[0] <= self.d_quantile[1] <= 1:
            raise SpecError(f"config [{TABLE}]: d_quantile must lie in [0, 1]")


def _lattice_transform(
    rng: np.random.Generator, s: LatticeSettings, period: float
) -> tuple[Transform, float]:
    """H and the coefficient of its linear argument for the given period."""
    if rng.random() < s.constituent_prob:
        name = str(rng.choice(LATTICE_CONSTITUENTS))
        r = round(period, 3)
        if name == "rect2":
            t = round(float(rng.uniform(0.2, 0.45)) * r, 3)
            return Transform(name, (r, t)), 1.0
        return Transform(name, (r,)), 1.0
    name = "cos" if rng.random() < 0.5 else "sin"
    return Transform(name), round(2 * math.pi / period, 4)


def _linear(w: float, axis: int) -> PowerFunction:
    return PowerFunction((PowerTerm(w, *(1.0 if j == axis else 0.0 for j in range(3))),))


def draw_lattice(seed: int, index: int, cfg: DrawSettings, s: LatticeSettings) -> Draw:
    """Shape ``index`` of the run ``seed`` in the ``lattice`` family (see the module docstring)."""
    rng = rng_for(seed, index)
    pattern = str(choose(rng, s.patterns, s.pattern_weights))
    half = round(float(rng.uniform(*cfg.box_half)), 1)
    periods = float(rng.uniform(*s.periods))
    period = 2 * half / periods
    scales = [1.0, 1.0, 1.0]
    if rng.random() < s.anisotropy_prob:
        scales = [round(float(rng.uniform(*s.anisotropy)), 2) for _ in range(3)]
    if pattern in ("diamond",):  # written in sines and cosines: the pattern needs both
        h1, w1 = Transform("sin"), round(2 * math.pi / period, 4)
        h2, w2 = Transform("cos"), w1
    else:
        h1, w1 = _lattice_transform(rng, s, period)
        h2, w2 = _lattice_transform(rng, s, period)

    terms = lattice_terms(rng, pattern, (h1, w1), (h2, w2), scales)
    box = Box.cube(half)
    terms, alpha, cells = fit_terms(terms, box, cfg.cell(half), cfg.period_cells)
    periods *= alpha
    q = float(rng.uniform(*s.d_quantile))
    structure = {
        "pattern": pattern,
        "periods": round(periods, 3),
        "H": [h1.name] if pattern in ("schwarz", "neovius") else [h1.name, h2.name],
        "group": "cyclic" if scales[0] == scales[1] == scales[2] else "none",
        "axis_scales": scales,
    }
    structure["cells_per_period"] = round(min(cells, 9999.0), 2)
    return Draw(Equation13(tuple(terms), 0.0), box, q, "lattice", structure)


def lattice_terms(
    rng: np.random.Generator,
    pattern: str,
    first: tuple[Transform, float],
    second: tuple[Transform, float],
    scales: list[float],
) -> list[tuple[Factor, ...]]:
    """The sum terms of ``pattern`` (one of :data:`LATTICE_PATTERNS`) with H1 and H2 and the
    coefficients of their linear arguments, each axis's scaled by ``scales`` (``product`` and
    ``neovius`` draw their constant from ``rng``)."""
    h1, w1 = first
    h2, w2 = second

    def wave(h: Transform, w: float, axis: int, times: float = 1.0) -> Factor:
        return only_b(_linear(round_significant(w * scales[axis], 4) * times, axis), h)

    terms: list[tuple[Factor, ...]] = []
    if pattern == "schwarz":
        terms = [(wave(h1, w1, k),) for k in range(3)]
    elif pattern == "gyroid":
        terms = [(wave(h1, w1, k), wave(h2, w2, (k + 1) % 3)) for k in range(3)]
    elif pattern == "product":
        c = round(float(rng.uniform(0.3, 1.2)), 2)
        terms = [tuple(wave(h1, w1, k) for k in range(3))]
        terms += [(constant(c), wave(h2, w2, k)) for k in range(3)]
    elif pattern == "diamond":
        # sin sin sin + sin cos cos + cos sin cos + cos cos sin (Schwarz's D surface)
        for sines in ((0, 1, 2), (0,), (1,), (2,)):
            terms.append(tuple(wave(h1 if k in sines else h2, w1, k) for k in range(3)))
    elif pattern == "neovius":
        # 3 (H x + H y + H z) + c H x H y H z, c about 4 (Neovius's surface)
        c = round(float(rng.uniform(2.5, 5.5)), 2)
        terms = [(constant(3.0), wave(h1, w1, k)) for k in range(3)]
        terms.append((constant(c), *(wave(h1, w1, k) for k in range(3))))
    else:  # iwp: 2 (cos x cos y + cos y cos z + cos z cos x) - (cos 2x + cos 2y + cos 2z)
        # (Schoen's I-WP); with sines the second part is + cos 2x (a shift of half a period),
        # with a constituent H that same H at twice the frequency.
        h2, w2, sign = (
            (h1, w1, -1.0)
            if h1.name not in ("sin", "cos")
            else (Transform("cos"), w1, 1.0 if h1.name == "sin" else -1.0)
        )
        terms = [(constant(2.0), wave(h1, w1, k), wave(h1, w1, (k + 1) % 3)) for k in range(3)]
        terms += [(constant(sign), wave(h2, w2, k, 2.0)) for k in range(3)]
    return terms


FAMILY = Family(
    "lattice",
    draw_lattice,
    "triply periodic patterns (Schwarz, gyroid, diamond, Neovius, I-WP ...) cut by the box",
    LatticeSettings,
    mix_weight=0.1,
    porous=True,
)
