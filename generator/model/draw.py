"""What every family builds on: the random stream of a shape, a drawn instance, the shared
``[sampler]`` keys, the factor draw of equation (13), and what a family is.

Shape ``index`` of a run with ``seed`` draws from
``np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index,)))`` only
(:func:`rng_for`), so any shape can be regenerated alone, in any order, on any worker.

The families (:mod:`surfgen.generator.model.families`) and the sampler
(:mod:`surfgen.generator.model.sampler`) both import this module; it imports neither.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from surfgen.generator.errors import SpecError
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.expr import Expr
from surfgen.generator.model.equation13 import (
    CONSTITUENT_TRANSFORMS,
    DIRECT_TRIG,
    INVERSE_TRIG,
    Equation13,
    Factor,
    PowerFunction,
    PowerTerm,
    Transform,
)
from surfgen.generator.model.order_stats import quantile
from surfgen.generator.model.settings import (
    require_fractions,
    require_low_high,
    require_range,
    require_weighted_pairs,
)

# Transforms whose values stay in [-1, 1], and inverse functions defined on all of R.
BOUNDED_TRANSFORMS = (
    "sin",
    "cos",
    "saw1",
    "saw2",
    "tri1",
    "tri2",
    "tri3",
    "rect1",
    "rect2",
    "rect3",
)
UNBOUNDED_INVERSE = ("atan", "acot")
NOT_SAMPLER_KEYS = ("grid",)  # fields that are not keys of [sampler] (metadata config_key False)


@dataclass(frozen=True)
class DrawSettings:
    """The shared keys of the ``[sampler]`` table: the free draw of eq. (13), which the other
    families build on (a sculpture's ornament is one of its factors), its box and its d."""

    sum_terms: tuple[int, ...] = (1, 2, 3)  # choices for the number of i terms...
    sum_terms_weights: tuple[float, ...] = (0.6, 0.3, 0.1)  # ...and their weights
    factors: tuple[int, ...] = (1, 2)  # choices for the number of m factors per term
    factors_weights: tuple[float, ...] = (0.85, 0.15)
    power_terms_max: int = 3  # terms per power function: 1..max
    coefficient_max: float = 1.5  # |a| <= this, 2 decimals
    integer_exponent_prob: float = 0.6  # b, c, d: whole 1..integer_exponent_max, else real
    integer_exponent_max: int = 2
    exponent_real: tuple[float, float] = (0.2, 2.0)
    variables_per_term_max: int = 2
    absolute_vars_prob: float = 0.35  # |x|, |y|, |z| in a power function with whole exponents
    trivial_denominator_prob: float = 0.5  # P2, P6, P8 = 1
    lambda_choices: tuple[float, ...] = (1.0, 2.0, 3.0, 0.5, 1.5)
    lambda_weights: tuple[float, ...] = (0.6, 0.2, 0.0, 0.1, 0.1)
    mu_choices: tuple[int, ...] = (1, 2, 3)  # mu1, mu3
    mu_weights: tuple[float, ...] = (0.7, 0.3, 0.0)
    omit_element_prob: float = 0.6  # each of A, D (lambda=0), B, E, C, F (mu=0) left out
    constituent_prob: float = 0.2  # H or G is a constituent function instead of trigonometric
    constituent_r: tuple[float, float] = (0.5, 3.0)
    constituent_p: tuple[int, int] = (2, 8)
    abs_prob: float = 0.3  # each of A..F in |.|
    box_half: tuple[float, float] = (0.8, 2.0)
    d_quantile: tuple[float, float] = (0.05, 0.45)
    d_grid: int = 20  # coarse grid used to choose d
    # The resolution bound (docs/guide/sampling.md, Priors the grid resolves): every period of
    # an H (a sine's 2 pi, a constituent's r, a pulse's shorter level twice) spans at least this
    # many cells of the run's grid where the shape is; 0 turns the bound off.
    period_cells: float = 6.0
    resolve_tries: int = 8  # free draws redrawn (from the same stream) until one is resolved
    # Proportions (surfgen.generator.model.stretch): a share of the shapes of every family
    # stretched along the axes by factors log-uniform in aspect, their axis swaps kept.
    aspect_prob: float = 0.8
    aspect: tuple[float, float] = (0.45, 2.2)
    # The run's grid ([run] grid or --grid; not a [sampler] key): the Config copies it here so
    # the draw, a pure function of (seed, index, config), sees the cell size it must resolve.
    grid: int = field(default=64, metadata={"config_key": False})

    def cell(self, half: float) -> float:
        """The run's cell size in a box ``[-half, half]^3``: ``2 half / (grid - 1)``."""
        return 2.0 * half / (self.grid - 1)

    def __post_init__(self) -> None:
        table = "sampler"
        require_weighted_pairs(
            self,
            (
                ("sum_terms", "sum_terms_weights"),
                ("factors", "factors_weights"),
                ("lambda_choices", "lambda_weights"),
                ("mu_choices", "mu_weights"),
            ),
            table,
        )
        for name in ("sum_terms", "factors"):
            if any(int(v) != v or v < 1 for v in getattr(self, name)):
                raise SpecError(f"config [sampler]: {name} must be whole numbers >= 1")
        probabilities = (
            "integer_exponent_prob",
            "absolute_vars_prob",
            "trivial_denominator_prob",
            "omit_element_prob",
            "constituent_prob",
            "abs_prob",
            "aspect_prob",
        )
        require_fractions(self, probabilities, table, "a probability")
        ranges = (
            "exponent_real",
            "constituent_r",
            "box_half",
            "d_quantile",
            "constituent_p",
            "aspect",
        )
        require_low_high(self, ranges, table)
        if not 0.1 <= self.aspect[0] <= self.aspect[1] <= 10:
            raise SpecError(
                "config [sampler]: aspect must lie within [0.1, 10], got "
                f"[{self.aspect[0]}, {self.aspect[1]}]"
            )
        if not self.box_half[0] > 0:
            raise SpecError("config [sampler]: box_half must be > 0")
        if not 0 <= self.d_quantile[0] <= self.d_quantile[1] <= 1:
            raise SpecError("config [sampler]: d_quantile must lie in [0, 1]")
        if self.power_terms_max < 1 or not 1 <= self.variables_per_term_max <= 3:
            raise SpecError(
                "config [sampler]: power_terms_max >= 1 and variables_per_term_max in 1..3"
            )
        if self.integer_exponent_max < 1:
            raise SpecError("config [sampler]: integer_exponent_max must be >= 1")
        if not 0 <= self.period_cells <= 64:
            raise SpecError(
                f"config [sampler]: period_cells must be from 0 to 64, got {self.period_cells}"
            )
        if not 1 <= self.resolve_tries <= 100:
            raise SpecError(
                f"config [sampler]: resolve_tries must be from 1 to 100, got {self.resolve_tries}"
            )
        if isinstance(self.grid, bool) or not isinstance(self.grid, int) or self.grid < 4:
            raise SpecError(f"config [run]: grid must be a whole number >= 4, got {self.grid!r}")
        if not 4 <= self.d_grid <= 128:
            raise SpecError("config [sampler]: d_grid must be from 4 to 128")
        # Upper bounds: a formula grows with these, and a huge one only makes every shape crash.
        for name, low, high in (
            ("sum_terms", 1, 10),
            ("factors", 1, 10),
            ("power_terms_max", 1, 10),
            ("integer_exponent_max", 1, 10),
            ("constituent_p", 1, 64),
            ("coefficient_max", 0, 1e6),
            ("exponent_real", -100, 100),
            ("constituent_r", 1e-6, 1e6),
            ("box_half", 1e-6, 1e6),
        ):
            require_range(self, name, low, high, table)


@dataclass(frozen=True)
class Draw:
    """One random instance before d is chosen: the model, its box and the d quantile.

    ``family`` names the distribution it came from and ``structure`` says how it was built
    (JSON-ready; stored with the model). A family that chooses d itself sets ``d_quantile`` to
    None and gives ``d`` (None: no d makes a surface). ``envelope`` is the sculpture's envelope
    (without its ornament), used to measure how far the shape departs from it.
    """

    equation: Equation13
    box: Box
    d_quantile: float | None
    family: str = "free"
    structure: Mapping[str, Any] | None = None
    d: float | None = None
    envelope: Expr | None = None

    def model_dict(self, equation: Equation13 | None = None) -> dict[str, Any]:
        """The model JSON: eq. (13) (``terms``, ``d``) plus ``family`` and ``structure``."""
        out = (equation or self.equation).to_dict()
        out["family"] = self.family
        if self.structure is not None:
            out["structure"] = dict(self.structure)
        return out


# The draw of one family: ``draw(seed, index, shared, settings) -> Draw``, a pure function of
# its arguments; ``settings`` is the family's own table (None for a family without one).
DrawFunction = Callable[[int, int, DrawSettings, Any], Draw]


@dataclass(frozen=True)
class Family:
    """A registry entry (:mod:`surfgen.generator.model.families`): a named distribution over
    eq. (13) instances.

    ``settings`` is the frozen dataclass its ``[sampler.<name>]`` table is read into (None: the
    family has no keys of its own); ``mix_weight`` its weight in the default ``mix`` (0: not in
    it); ``description`` one line for ``--help`` and the docs; ``one_body``: its shapes are
    drawn as one connected body, so the filters reject one broken into pieces (``fragmented``:
    ``[filters] min_body_fraction``); ``porous``: its shapes may fall into many pieces (struts
    cut by the box or an envelope), so the filters allow it more than ``[filters] max_pieces``
    (a body, or a few, in more pieces has flying debris: ``fragmented``); ``outline``: a
    lump of it is told by its silhouette (every view a convex outline: ``plain``,
    :mod:`surfgen.generator.mesh.outline`) — False for a family whose look is the relief inside a
    convex outline (``twist``: its grooves); ``aspect_limit``: the largest ratio of two of the
    factors its shapes are stretched by (:mod:`surfgen.generator.model.stretch`; None: as
    drawn) — a twisted column squashed flat is a lens.
    """

    name: str
    draw: DrawFunction
    description: str
    settings: type | None = None
    mix_weight: float = 0.0
    one_body: bool = False
    porous: bool = False
    outline: bool = True
    aspect_limit: float | None = None

    @property
    def table(self) -> str | None:
        """The family's config table, e.g. ``sampler.sculpture`` (None without settings)."""
        return None if self.settings is None else f"sampler.{self.name}"


def rng_for(seed: int, index: int) -> np.random.Generator:
    """The random stream of shape ``index`` of the run with ``seed``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index,)))


def choose(rng: np.random.Generator, values, weights) -> Any:
    """``values[rng.choice(len(values), p=weights / sum)]``: the same index from the same one
    uniform draw as numpy's ``Generator.choice`` (the normalised cumulative sum searched from
    the right, tested), without its per-call checks and conversions (12 calls per factor)."""
    return values[int(_cdf(tuple(weights)).searchsorted(rng.random(), side="right"))]


@functools.lru_cache(maxsize=64)
def _cdf(weights: tuple[float, ...]) -> np.ndarray:
    w = np.asarray(weights, dtype=np.float64)
    cdf = (w / w.sum()).cumsum()
    cdf /= cdf[-1]
    return cdf


def coarse_values(
    draw: Draw, cfg: DrawSettings, evaluator: str = "fast", threads: int | None = None
) -> tuple[np.ndarray, float | None]:
    """The body's values on the coarse grid of ``d_grid`` points per axis over the draw's box,
    and ``d``: at the draw's quantile of the finite values, rounded to 6 significant digits
    (None when they hold fewer than two distinct values: no d makes a surface), or the d the
    family chose (``d_quantile`` None)."""
    grid = Grid(draw.box, (cfg.d_grid,) * 3)
    values = evaluate(draw.equation.body(), grid, evaluator=evaluator, threads=threads).values
    if draw.d_quantile is None:
        return values, draw.d
    finite = values[np.isfinite(values)]
    if finite.size < 8 or finite.min() == finite.max():
        return values, None
    return values, round_significant(float(quantile(finite, draw.d_quantile)), 6)


def round_to(v: float, digits: int = 2) -> float:
    """``v`` rounded to ``digits`` decimals, never ``-0.0``."""
    return float(round(v, digits)) + 0.0


def round_significant(v: float, digits: int) -> float:
    """``v`` rounded to ``digits`` significant digits (0 for 0 and non-finite values)."""
    if v == 0 or not math.isfinite(v):
        return 0.0
    return float(f"{v:.{digits - 1}e}") + 0.0


def draw_power_function(
    rng: np.random.Generator, cfg: DrawSettings, nonnegative: bool = False
) -> PowerFunction:
    """A random eq. (8) power function; ``nonnegative`` makes it >= 0 everywhere."""
    n_terms = int(rng.integers(1, cfg.power_terms_max + 1))
    terms = []
    any_real = False
    for _ in range(n_terms):
        a = round_to(rng.uniform(-cfg.coefficient_max, cfg.coefficient_max))
        if a == 0:
            a = 1.0
        if nonnegative:
            a = abs(a)
        exps = [0.0, 0.0, 0.0]
        k = int(rng.integers(1, cfg.variables_per_term_max + 1))
        for axis in rng.choice(3, size=k, replace=False):
            if rng.random() < cfg.integer_exponent_prob:
                exps[int(axis)] = float(rng.integers(1, cfg.integer_exponent_max + 1))
            else:
                exps[int(axis)] = round_to(rng.uniform(*cfg.exponent_real))
                any_real = any_real or not exps[int(axis)].is_integer()
        terms.append(PowerTerm(a, *exps))
    # Real exponents of negative numbers are NaN: such power functions use |x|, |y|, |z|.
    absolute = any_real or nonnegative or bool(rng.random() < cfg.absolute_vars_prob)
    return PowerFunction(tuple(terms), absolute)


def draw_transform(
    rng: np.random.Generator, cfg: DrawSettings, family: tuple[str, ...]
) -> Transform:
    """H or G: a constituent function (``constituent_prob``) or one of ``family``."""
    if rng.random() < cfg.constituent_prob:
        name = str(rng.choice(sorted(CONSTITUENT_TRANSFORMS)))
        params = []
        for pname in CONSTITUENT_TRANSFORMS[name]:
            if pname == "r":
                params.append(round_to(rng.uniform(*cfg.constituent_r)))
            elif pname == "p":
                params.append(float(rng.integers(cfg.constituent_p[0], cfg.constituent_p[1] + 1)))
            elif pname == "h":
                params.append(round_to(rng.uniform(0.2, 2.0)))
            else:  # t: |t| < 1 and t/r, t not whole
                params.append(round_to(rng.uniform(0.1, 0.9)))
        if name == "rect2" and float(params[1] / params[0]).is_integer():
            # t = r (both rounded to 0.01) is not a rect2: half of r instead (t/r = 0.5
            # exactly), without another random number, so no other draw changes
            params[1] = params[0] / 2
        return Transform(name, tuple(params))
    return Transform(str(rng.choice(family)))


def draw_factor(rng: np.random.Generator, cfg: DrawSettings) -> Factor:
    """A random factor ``A/D * B/E * C/F`` of eq. (13)."""
    lambdas = [float(choose(rng, cfg.lambda_choices, cfg.lambda_weights)) for _ in range(8)]
    powers = []
    for k in range(8):
        if k in (1, 5, 7) and rng.random() < cfg.trivial_denominator_prob:
            powers.append(PowerFunction.constant(1.0))
            continue
        powers.append(draw_power_function(rng, cfg, nonnegative=not lambdas[k].is_integer()))
    mus = [float(choose(rng, cfg.mu_choices, cfg.mu_weights)) for _ in range(4)]
    h = draw_transform(rng, cfg, DIRECT_TRIG)
    # asin/acos are NaN outside [-1, 1]: after an H that leaves [-1, 1] (tan, cot, sec, csc,
    # a staircase) G is drawn from the inverse functions defined everywhere.
    bounded = h.name in BOUNDED_TRANSFORMS
    g = draw_transform(rng, cfg, INVERSE_TRIG if bounded else UNBOUNDED_INVERSE)
    # Leave some elements out (exponent 0 makes them exactly 1), but never all of them.
    omit = rng.random(6) < cfg.omit_element_prob
    if omit.all():
        omit[int(rng.integers(0, 6))] = False
    for flag, (kind, k) in zip(
        omit, (("l", 0), ("m", 0), ("m", 2), ("l", 1), ("m", 1), ("m", 3)), strict=True
    ):
        if flag:
            (lambdas if kind == "l" else mus)[k] = 0.0
    return Factor(
        powers=tuple(powers),
        lambdas=tuple(lambdas),
        mus=tuple(mus),
        h=h,
        g=g,
        absolute=tuple(bool(v) for v in rng.random(6) < cfg.abs_prob),
    )


# ----------------------------------------------------------------------------- building blocks

ONE = PowerFunction.constant(1.0)


def only_a(p: PowerFunction) -> Factor:
    """A factor that is its A = P alone (every other element left out)."""
    return Factor(
        powers=(p,) + (ONE,) * 7,
        lambdas=(1.0,) + (0.0,) * 7,
        mus=(0.0,) * 4,
        h=Transform("sin"),
        g=Transform("asin"),
    )


def only_b(p: PowerFunction, h: Transform) -> Factor:
    """A factor that is its B = H(P) alone."""
    return Factor(
        powers=(ONE, ONE, p) + (ONE,) * 5,
        lambdas=(0.0, 0.0, 1.0) + (0.0,) * 5,
        mus=(1.0, 0.0, 0.0, 0.0),
        h=h,
        g=Transform("asin"),
    )


def constant(value: float) -> Factor:
    """A factor that is the constant ``value``."""
    return only_a(PowerFunction.constant(value))
