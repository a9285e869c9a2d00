"""The seeded stochastic sampler of equation (13).

Shape ``index`` of a run with ``seed`` draws from
``np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index,)))`` only, so any shape
can be regenerated alone, in any order, on any worker: :func:`draw_equation` is a pure function
of ``(seed, index, config)``.

Every distribution lives in :class:`SamplerConfig` (the ``[sampler]`` table of the TOML config;
``surfgen config show`` prints the defaults with their meaning).

Choosing d: a random ``d`` almost always leaves the box empty. We evaluate the sum of products on
a coarse grid and take ``d`` at a drawn quantile of its finite values, rounded to 6 significant
digits (so the printed formula is short and the key is stable to the last bit of a libm).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass
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
from surfgen.generator.model.settings import (
    require_fractions,
    require_range,
    settings_from_mapping,
    settings_to_dict,
)

SAMPLER_VERSION = 5  # 2: families (sculpture, lattice, free) and their mix; 3: ornaments redrawn when they crumble (sculpture_max_pieces); 4: ornament checks on the unit's transposed copies and a 24^3 grid, sculpture_min_departure 0.2, walls classified by bisection (wall_fraction); 5: half the ornaments pole-free (sculpture_pole_free_prob 0.5), group weights towards none and mirror
FAMILIES = ("sculpture", "lattice", "free")
FAMILY_CHOICES = (*FAMILIES, "mix")
SCULPTURE_ENVELOPES = ("superellipsoid", "product", "cubic")
# Symmetry groups of a sculpture's ornament: how many axis permutations it is summed over, and
# whether it uses |x|, |y|, |z| (the mirrors).
SCULPTURE_GROUPS = ("none", "mirror", "cyclic", "cyclic_mirror", "full", "full_mirror")
LATTICE_PATTERNS = ("schwarz", "gyroid", "product", "diamond", "neovius", "iwp")
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


@dataclass(frozen=True)
class SamplerConfig:
    """The distributions of a random eq. (13) instance (see ``surfgen config show``)."""

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
    # -- families (generator/families.py): which distribution over eq. (13) instances
    family: str = "mix"  # sculpture, lattice, free (the draw above), or mix
    mix: tuple[str, ...] = ("sculpture", "lattice", "free")
    mix_weights: tuple[float, ...] = (0.8, 0.08, 0.12)
    sculpture_envelopes: tuple[str, ...] = SCULPTURE_ENVELOPES
    sculpture_envelope_weights: tuple[float, ...] = (0.45, 0.25, 0.3)
    sculpture_exponent: tuple[float, float] = (1.6, 4.0)  # superellipsoid |x|^p+|y|^p+|z|^p
    sculpture_stretch_prob: float = 0.15  # one axis of the envelope stretched (breaks symmetry)
    sculpture_groups: tuple[str, ...] = SCULPTURE_GROUPS
    sculpture_group_weights: tuple[float, ...] = (0.2, 0.25, 0.2, 0.15, 0.1, 0.1)
    sculpture_powers: tuple[int, ...] = (1, 2, 3)  # outer power k of the ornament sum
    sculpture_power_weights: tuple[float, ...] = (0.6, 0.25, 0.15)
    sculpture_depth: tuple[float, float] = (0.1, 0.4)  # carving depth / envelope radius
    sculpture_margin: tuple[float, float] = (0.15, 0.3)  # box beyond envelope + depth
    sculpture_frequency: tuple[float, float] = (1.0, 4.0)  # scales the ornament's H arguments
    sculpture_constituent_prob: float = 0.3  # the ornament's H or G is a constituent function
    sculpture_omit_element_prob: float = 0.55
    sculpture_bounded_prob: float = 0.7  # an ornament's tan, cot, sec or csc becomes sin or cos
    sculpture_pole_free_prob: float = 0.5  # an ornament without D, E, F, P6, P8 and poles of H
    sculpture_min_feature: float = 0.25  # ornament feature size / box half-size (0: any)
    sculpture_max_stray: float = 0.02  # share of the carved surface far from the envelope
    sculpture_min_departure: float = 0.2  # carved surface's departure from the envelope
    sculpture_max_pieces: int = 6  # pieces of the carved surface on the feature grid
    sculpture_ornament_tries: int = 6  # ornaments drawn until one carves cleanly
    sculpture_feature_grid: int = 24  # samples per axis of the grid the ornament checks use
    lattice_patterns: tuple[str, ...] = LATTICE_PATTERNS
    lattice_pattern_weights: tuple[float, ...] = (0.15, 0.2, 0.15, 0.2, 0.15, 0.15)
    lattice_periods: tuple[float, float] = (1.0, 2.5)  # periods across the box
    lattice_anisotropy_prob: float = 0.5  # each axis's period scaled by its own factor
    lattice_anisotropy: tuple[float, float] = (0.6, 1.6)  # that factor's range
    lattice_constituent_prob: float = 0.3  # a constituent function instead of sin/cos
    lattice_d_quantile: tuple[float, float] = (0.25, 0.6)

    def __post_init__(self) -> None:
        self._check_families()
        pairs = (
            ("sum_terms", "sum_terms_weights"),
            ("factors", "factors_weights"),
            ("lambda_choices", "lambda_weights"),
            ("mu_choices", "mu_weights"),
            ("mix", "mix_weights"),
            ("sculpture_envelopes", "sculpture_envelope_weights"),
            ("sculpture_groups", "sculpture_group_weights"),
            ("sculpture_powers", "sculpture_power_weights"),
            ("lattice_patterns", "lattice_pattern_weights"),
        )
        for a, b in pairs:
            if len(getattr(self, a)) != len(getattr(self, b)) or not getattr(self, a):
                raise SpecError(
                    f"config [sampler]: {a} and {b} must be non-empty lists of the same length"
                )
            if any(w < 0 for w in getattr(self, b)) or sum(getattr(self, b)) <= 0:
                raise SpecError(f"config [sampler]: {b} must be non-negative and not all zero")
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
            "sculpture_stretch_prob",
            "sculpture_constituent_prob",
            "sculpture_omit_element_prob",
            "sculpture_bounded_prob",
            "sculpture_pole_free_prob",
            "lattice_constituent_prob",
            "lattice_anisotropy_prob",
        )
        require_fractions(self, probabilities, "sampler", "a probability")
        require_fractions(self, ("sculpture_max_stray",), "sampler", "a share")
        ranges = (
            "exponent_real",
            "constituent_r",
            "box_half",
            "d_quantile",
            "constituent_p",
            "sculpture_exponent",
            "sculpture_depth",
            "sculpture_margin",
            "sculpture_frequency",
            "lattice_periods",
            "lattice_d_quantile",
            "lattice_anisotropy",
        )
        for name in ranges:
            if len(getattr(self, name)) != 2:
                raise SpecError(f"config [sampler]: {name} must be [low, high]")
            lo, hi = getattr(self, name)
            if not lo <= hi:
                raise SpecError(f"config [sampler]: {name} must be [low, high] with low <= high")
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
        if not 4 <= self.d_grid <= 128:
            raise SpecError("config [sampler]: d_grid must be from 4 to 128")
        if not 8 <= self.sculpture_feature_grid <= 128:
            raise SpecError("config [sampler]: sculpture_feature_grid must be from 8 to 128")
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
            ("sculpture_min_feature", 0, 10),
            ("sculpture_min_departure", 0, 10),
            ("sculpture_ornament_tries", 1, 50),
            ("sculpture_max_pieces", 1, 100000),
            ("lattice_anisotropy", 0.1, 10),
        ):
            require_range(self, name, low, high, "sampler")
        if not self.sculpture_exponent[0] >= 1:
            raise SpecError("config [sampler]: sculpture_exponent must be >= 1 (convex envelopes)")
        if not (self.sculpture_depth[0] > 0 and self.sculpture_margin[0] >= 0):
            raise SpecError("config [sampler]: sculpture_depth must be > 0, sculpture_margin >= 0")
        if not (self.lattice_periods[0] > 0 and self.sculpture_frequency[0] > 0):
            raise SpecError("config [sampler]: lattice_periods, sculpture_frequency must be > 0")
        if not 0 <= self.lattice_d_quantile[0] <= self.lattice_d_quantile[1] <= 1:
            raise SpecError("config [sampler]: lattice_d_quantile must lie in [0, 1]")
        if any(int(k) != k or not 1 <= k <= 3 for k in self.sculpture_powers):
            raise SpecError("config [sampler]: sculpture_powers must be whole numbers 1..3")

    def _check_families(self) -> None:
        """One-line errors naming what is allowed for the family names."""
        if not isinstance(self.family, str) or self.family not in FAMILY_CHOICES:
            raise SpecError(
                f"config [sampler]: family must be one of {', '.join(FAMILY_CHOICES)}, "
                f"got {self.family!r}"
            )
        for name, allowed in (
            ("mix", FAMILIES),
            ("sculpture_envelopes", SCULPTURE_ENVELOPES),
            ("sculpture_groups", SCULPTURE_GROUPS),
            ("lattice_patterns", LATTICE_PATTERNS),
        ):
            values = getattr(self, name)
            bad = [v for v in values if v not in allowed]
            if bad:
                raise SpecError(
                    f"config [sampler]: {name} has unknown {bad[0]!r} "
                    f"(allowed: {', '.join(allowed)})"
                )
            if len(set(values)) != len(values):
                raise SpecError(f"config [sampler]: {name} lists a name twice")
        for name in (
            "mix_weights",
            "sculpture_envelope_weights",
            "sculpture_group_weights",
            "sculpture_power_weights",
            "lattice_pattern_weights",
        ):
            for w in getattr(self, name):
                if isinstance(w, bool) or not isinstance(w, int | float) or not math.isfinite(w):
                    raise SpecError(f"config [sampler]: {name} must be numbers, got {w!r}")

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any]) -> SamplerConfig:
        return settings_from_mapping(cls, data, "sampler")

    def to_dict(self) -> dict[str, Any]:
        return settings_to_dict(self)


def rng_for(seed: int, index: int) -> np.random.Generator:
    """The random stream of shape ``index`` of the run with ``seed``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index,)))


def _choice(rng: np.random.Generator, values, weights) -> Any:
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


def _round(v: float, digits: int = 2) -> float:
    return float(round(v, digits)) + 0.0


def draw_power_function(
    rng: np.random.Generator, cfg: SamplerConfig, nonnegative: bool = False
) -> PowerFunction:
    """A random eq. (8) power function; ``nonnegative`` makes it >= 0 everywhere."""
    n_terms = int(rng.integers(1, cfg.power_terms_max + 1))
    terms = []
    any_real = False
    for _ in range(n_terms):
        a = _round(rng.uniform(-cfg.coefficient_max, cfg.coefficient_max))
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
                exps[int(axis)] = _round(rng.uniform(*cfg.exponent_real))
                any_real = any_real or not exps[int(axis)].is_integer()
        terms.append(PowerTerm(a, *exps))
    # Real exponents of negative numbers are NaN: such power functions use |x|, |y|, |z|.
    absolute = any_real or nonnegative or bool(rng.random() < cfg.absolute_vars_prob)
    return PowerFunction(tuple(terms), absolute)


def draw_transform(
    rng: np.random.Generator, cfg: SamplerConfig, family: tuple[str, ...]
) -> Transform:
    if rng.random() < cfg.constituent_prob:
        name = str(rng.choice(sorted(CONSTITUENT_TRANSFORMS)))
        params = []
        for pname in CONSTITUENT_TRANSFORMS[name]:
            if pname == "r":
                params.append(_round(rng.uniform(*cfg.constituent_r)))
            elif pname == "p":
                params.append(float(rng.integers(cfg.constituent_p[0], cfg.constituent_p[1] + 1)))
            elif pname == "h":
                params.append(_round(rng.uniform(0.2, 2.0)))
            else:  # t: |t| < 1 and t/r, t not whole
                params.append(_round(rng.uniform(0.1, 0.9)))
        if name == "rect2" and float(params[1] / params[0]).is_integer():
            # t = r (both rounded to 0.01) is not a rect2: half of r instead (t/r = 0.5
            # exactly), without another random number, so no other draw changes
            params[1] = params[0] / 2
        return Transform(name, tuple(params))
    return Transform(str(rng.choice(family)))


def draw_factor(rng: np.random.Generator, cfg: SamplerConfig) -> Factor:
    lambdas = [float(_choice(rng, cfg.lambda_choices, cfg.lambda_weights)) for _ in range(8)]
    powers = []
    for k in range(8):
        if k in (1, 5, 7) and rng.random() < cfg.trivial_denominator_prob:
            powers.append(PowerFunction.constant(1.0))
            continue
        powers.append(draw_power_function(rng, cfg, nonnegative=not lambdas[k].is_integer()))
    mus = [float(_choice(rng, cfg.mu_choices, cfg.mu_weights)) for _ in range(4)]
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


def draw_equation(seed: int, index: int, cfg: SamplerConfig) -> Draw:
    """Shape ``index`` of the run ``seed``: a pure function of its arguments.

    ``cfg.family`` picks the distribution; ``mix`` picks one family per index from a stream of
    its own, so a ``free`` shape of the mix is the very shape ``family = "free"`` draws there.
    """
    if cfg.family == "free":
        return draw_free(seed, index, cfg)
    from surfgen.generator.model.families import draw_family  # families build on this module

    return draw_family(seed, index, cfg)


def draw_free(seed: int, index: int, cfg: SamplerConfig) -> Draw:
    """The ``free`` family: the first sampler's draw, unchanged (tests pin its models)."""
    rng = rng_for(seed, index)
    n_sum = int(_choice(rng, cfg.sum_terms, cfg.sum_terms_weights))
    terms = []
    for _ in range(n_sum):
        n_fac = int(_choice(rng, cfg.factors, cfg.factors_weights))
        terms.append(tuple(draw_factor(rng, cfg) for _ in range(n_fac)))
    half = _round(rng.uniform(*cfg.box_half), 1)
    q = float(rng.uniform(*cfg.d_quantile))
    return Draw(Equation13(tuple(terms), 0.0), Box.cube(half), q, "free")


def choose_d(
    draw: Draw, cfg: SamplerConfig, evaluator: str = "fast", threads: int | None = None
) -> float | None:
    """``d`` at the draw's quantile of the body's finite values on a coarse grid.

    Returns ``None`` when the body has fewer than two distinct finite values there
    (no ``d`` can make a surface). A family that chose d itself (``d_quantile`` None) gives it.
    """
    if draw.d_quantile is None:
        return draw.d
    grid = Grid(draw.box, (cfg.d_grid,) * 3)
    values = evaluate(draw.equation.body(), grid, evaluator=evaluator, threads=threads).values
    finite = values[np.isfinite(values)]
    if finite.size < 8 or finite.min() == finite.max():
        return None
    d = float(np.quantile(finite, draw.d_quantile))
    return round_significant(d, 6)


def round_significant(v: float, digits: int) -> float:
    if v == 0 or not math.isfinite(v):
        return 0.0
    return float(f"{v:.{digits - 1}e}") + 0.0
