"""The ``sculpture`` family (the paper's equations A and B, and MathMod's curated surfaces).

An **envelope**, a bounded sum term whose A is a power function with a constant term — a
superellipsoid ``|x|^p + |y|^p + |z|^p - 1`` (optionally stretched along one axis), a product of
two of them (the two factors of one sum term, as equation B's
``(x²+y²+z²-5)(|x|^0.13|y|^0.13|z|^0.13-5)``), a superellipsoid closed by a cubic term as in
equation C, or a **gem**: a superellipsoid cut by an octahedron or a cube through
``max(a, b) = (a + b + |a - b|)/2`` (:func:`~.bodies.power_max`) — plus an **ornament**: one factor of the free draw, summed over a symmetry group
(the 3 cyclic or all 6 axis permutations, each copy one more sum term; ``mirror`` groups use
``|x|, |y|, |z|``; :mod:`.symmetry`), optionally under an outer power k (``(O_1 + O_2 + O_3)^k``
expanded into the sum of its products of k factors, the multinomial coefficients folded into
the constant factor in front). The ornament's strength is drawn relative to its own spread near
the envelope's surface, so it carves to a drawn depth (a fraction of the envelope's size)
without erasing it; d is the ornament's median there, so the carved surface stays on the
envelope on average; the box fits the envelope with a margin, so the shape stands free.
Ornaments that carve badly are redrawn (:mod:`.carving` measures them). Its keys: the
``[sampler.sculpture]`` table (:class:`SculptureSettings`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from surfgen.generator.errors import SpecError
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.expr import Expr, add_all, mul_all
from surfgen.generator.model.draw import (
    ONE,
    Draw,
    DrawSettings,
    Family,
    choose,
    constant,
    draw_factor,
    only_a,
    rng_for,
    round_significant,
)
from surfgen.generator.model.equation13 import (
    CONSTITUENT_TRANSFORMS,
    Equation13,
    Factor,
    PowerFunction,
    PowerTerm,
    Transform,
)
from surfgen.generator.model.families.bodies import power_max
from surfgen.generator.model.families.gridbound import fit_factor, pole_planes, scale_arguments
from surfgen.generator.model.families.symmetry import (
    GROUP_PERMUTATIONS,
    ornament_terms,
    permute_factor,
)
from surfgen.generator.model.settings import (
    require_fractions,
    require_low_high,
    require_names,
    require_numbers,
    require_range,
    require_weighted_pairs,
)

SCULPTURE_ENVELOPES = ("superellipsoid", "product", "cubic", "gem")
# Symmetry groups of a sculpture's ornament: how many axis permutations it is summed over, and
# whether it uses |x|, |y|, |z| (the mirrors).
SCULPTURE_GROUPS = tuple(GROUP_PERMUTATIONS)
EXTENT_GRID = 33  # samples per axis of the search box used to measure an envelope's extent
EXTENT_BOX = 2.5
TABLE = "sampler.sculpture"
JUMPS = ("saw1", "saw2", "stair1", "stair2", "rect1", "rect2", "rect3")


@dataclass(frozen=True)
class SculptureSettings:
    """The ``[sampler.sculpture]`` table (``surfgen config show``)."""

    envelopes: tuple[str, ...] = SCULPTURE_ENVELOPES
    envelope_weights: tuple[float, ...] = (0.3, 0.2, 0.25, 0.25)
    exponent: tuple[float, float] = (1.6, 4.0)  # superellipsoid |x|^p+|y|^p+|z|^p
    stretch_prob: float = 0.15  # one axis of the envelope stretched (breaks symmetry)
    groups: tuple[str, ...] = SCULPTURE_GROUPS
    group_weights: tuple[float, ...] = (0.2, 0.25, 0.2, 0.15, 0.1, 0.1)
    powers: tuple[int, ...] = (1, 2, 3)  # outer power k of the ornament sum
    power_weights: tuple[float, ...] = (0.6, 0.25, 0.15)
    depth: tuple[float, float] = (0.15, 0.45)  # carving depth / envelope radius
    margin: tuple[float, float] = (0.15, 0.3)  # box beyond envelope + depth
    frequency: tuple[float, float] = (1.0, 4.0)  # scales the ornament's H arguments
    constituent_prob: float = 0.3  # the ornament's H or G is a constituent function
    omit_element_prob: float = 0.55
    bounded_prob: float = 0.7  # an ornament's tan, cot, sec or csc becomes sin or cos
    jump_prob: float = 0.35  # an ornament's saw, staircase or pulse is kept (else: a triangle)
    pole_free_prob: float = 0.5  # an ornament without D, E, F, P6, P8 and poles of H
    min_feature: float = 0.25  # ornament feature size / box half-size (0: any)
    max_stray: float = 0.02  # share of the carved surface far from the envelope
    min_departure: float = 0.2  # carved surface's departure from the envelope
    max_pieces: int = 6  # pieces of the carved surface on the feature grid
    ornament_tries: int = 6  # ornaments drawn until one carves cleanly
    feature_grid: int = 24  # samples per axis of the grid the ornament checks use

    def __post_init__(self) -> None:
        require_names(self, "envelopes", SCULPTURE_ENVELOPES, TABLE)
        require_names(self, "groups", SCULPTURE_GROUPS, TABLE)
        require_numbers(self, ("envelope_weights", "group_weights", "power_weights"), TABLE)
        require_weighted_pairs(
            self,
            (
                ("envelopes", "envelope_weights"),
                ("groups", "group_weights"),
                ("powers", "power_weights"),
            ),
            TABLE,
        )
        probabilities = (
            "stretch_prob",
            "constituent_prob",
            "omit_element_prob",
            "bounded_prob",
            "jump_prob",
            "pole_free_prob",
        )
        require_fractions(self, probabilities, TABLE, "a probability")
        require_fractions(self, ("max_stray",), TABLE, "a share")
        require_low_high(self, ("exponent", "depth", "margin", "frequency"), TABLE)
        if not 8 <= self.feature_grid <= 128:
            raise SpecError(f"config [{TABLE}]: feature_grid must be from 8 to 128")
        for name, low, high in (
            ("min_feature", 0, 10),
            ("min_departure", 0, 10),
            ("ornament_tries", 1, 50),
            ("max_pieces", 1, 100000),
        ):
            require_range(self, name, low, high, TABLE)
        if not self.exponent[0] >= 1:
            raise SpecError(f"config [{TABLE}]: exponent must be >= 1 (convex envelopes)")
        if not (self.depth[0] > 0 and self.margin[0] >= 0):
            raise SpecError(f"config [{TABLE}]: depth must be > 0, margin >= 0")
        if not self.frequency[0] > 0:
            raise SpecError(f"config [{TABLE}]: frequency must be > 0")
        if any(int(k) != k or not 1 <= k <= 3 for k in self.powers):
            raise SpecError(f"config [{TABLE}]: powers must be whole numbers 1..3")


def superellipsoid(p: float, radii: tuple[float, float, float]) -> PowerFunction:
    """``Σ |x_k|^p / r_k^p - 1``: negative inside, a convex body for p >= 1."""
    terms = [
        PowerTerm(round_significant(1.0 / r**p, 4), *(p if j == k else 0.0 for j in range(3)))
        for k, r in enumerate(radii)
    ]
    return PowerFunction((*terms, PowerTerm(-1.0)), absolute=True)


def _sum_tree(terms: list[tuple[Factor, ...]]) -> Expr:
    return add_all([mul_all([f.to_tree() for f in prod]) for prod in terms])


def _eval(tree: Expr, box: Box, n: int) -> np.ndarray:
    return evaluate(tree, Grid(box, (n,) * 3), threads=1).values


def _draw_envelope(
    rng: np.random.Generator, s: SculptureSettings, permutes: bool
) -> tuple[list[tuple[Factor, ...]], dict[str, Any]]:
    """The envelope's sum terms and their description."""
    kind = str(choose(rng, s.envelopes, s.envelope_weights))
    p = round(float(rng.uniform(*s.exponent)), 1)
    radii = [1.0, 1.0, 1.0]
    if rng.random() < s.stretch_prob:
        radii[int(rng.integers(0, 3))] = round(float(rng.uniform(0.6, 1.5)), 2)
    info: dict[str, Any] = {"kind": kind, "exponent": p, "radii": list(radii)}
    first = superellipsoid(p, tuple(radii))
    if kind == "superellipsoid":
        return [(only_a(first),)], info
    if kind == "product":
        # A second body that pokes out of the first: a boxier one inside, or a rounder (or
        # diamond) one outside along the axes; inside is where exactly one of them is.
        if p < 2.6:
            p2, r2 = round(min(p * 2.2, 8.0), 1), round(float(rng.uniform(0.72, 0.9)), 2)
        else:
            p2, r2 = round(max(p / 2.2, 1.0), 1), round(float(rng.uniform(1.08, 1.3)), 2)
        info.update(second_exponent=p2, second_radius=r2)
        return [(only_a(first), only_a(superellipsoid(p2, (r2,) * 3)))], info
    if kind == "gem":
        # max(S, C): the superellipsoid cut by an octahedron |x|+|y|+|z| < w or a cube
        # (|x|^10 + ... < r^10): flat facets and creases, full symmetry kept
        if rng.random() < 0.5:
            w = round(float(rng.uniform(1.05, 1.5)), 2)
            cut = PowerFunction(
                (
                    *(
                        PowerTerm(1.0, *(1.0 if j == k else 0.0 for j in range(3)))
                        for k in range(3)
                    ),
                    PowerTerm(-w),
                ),
                absolute=True,
            )
            info.update(cut="octahedron", cut_size=w)
        else:
            r = round(float(rng.uniform(0.7, 0.92)), 2)
            cut = superellipsoid(10.0, (r, r, r))
            info.update(cut="cube", cut_size=r)
        return [tuple(t) for t in power_max(first, cut)], info
    # cubic: a superellipsoid steep enough (p > 3) to stay closed, plus c x^3 (summed over
    # the axes when the ornament is permuted, to keep that symmetry), as in equation C.
    p = round(max(p, 3.5) + 1.0, 1)
    first = superellipsoid(p, tuple(radii))
    c = round(float(rng.uniform(0.25, 0.7)) * (1 if rng.random() < 0.5 else -1), 2)
    axes = range(3) if permutes else (0,)
    cubic = PowerFunction(
        tuple(PowerTerm(c, *(3.0 if j == k else 0.0 for j in range(3))) for k in axes)
    )
    info.update(exponent=p, cubic=c, cubic_axes=len(axes))
    return [(only_a(first),), (only_a(cubic),)], info


def envelope_extent(tree: Expr) -> float | None:
    """The largest |coordinate| of the envelope's inside (one search cell added), or None if
    the inside reaches the search box (not bounded there) or is empty."""
    box = Box.cube(EXTENT_BOX)
    v = _eval(tree, box, EXTENT_GRID)
    inside = np.isfinite(v) & (v < 0)
    if not inside.any():
        return None
    axis = np.linspace(-EXTENT_BOX, EXTENT_BOX, EXTENT_GRID)
    idx = np.nonzero(inside)
    extent = max(float(np.abs(axis[i]).max()) for i in idx)
    cell = 2 * EXTENT_BOX / (EXTENT_GRID - 1)
    return None if extent >= EXTENT_BOX - cell / 2 else extent + cell


def draw_sculpture(seed: int, index: int, cfg: DrawSettings, s: SculptureSettings) -> Draw:
    """The ``sculpture`` family (see the module docstring)."""
    rng = rng_for(seed, index)
    group = str(choose(rng, s.groups, s.group_weights))
    perms = GROUP_PERMUTATIONS[group]
    mirror = group.endswith("mirror")
    k = int(choose(rng, s.powers, s.power_weights))
    if len(perms) > 3:  # (6 copies)^k would print as dozens of products
        k = 1
    env_terms, env_info = _draw_envelope(rng, s, permutes=len(perms) > 1)
    depth = round(float(rng.uniform(*s.depth)), 2)
    margin = float(rng.uniform(*s.margin))
    envelope = _sum_tree(env_terms)
    extent = envelope_extent(envelope)
    half = EXTENT_BOX if extent is None else round(extent * (1 + depth + margin), 2)
    box = Box.cube(half)
    ornament, freq, products, checks, strength_d, tries = coarse_ornament(
        rng,
        cfg,
        s,
        envelope if extent is not None else None,
        box,
        perms,
        mirror,
        k,
        depth * (extent or 0.0),
    )
    structure: dict[str, Any] = {
        "envelope": env_info,
        "ornament": {"factor": Equation13(((ornament,),)).to_dict()["terms"][0][0]},
        "group": group,
        "k": k,
    }
    structure["ornament"].update(frequency=freq, depth=depth)
    if checks is not None:
        feature, stray, departure, pieces, cells, poles = checks
        structure["ornament"].update(
            cells_per_period=round(min(cells, 9999.0), 2),
            pole_planes=poles,
            feature=round(feature, 4),
            stray=round(stray, 4),
            departure=round(min(departure, 99.0), 4),
            pieces=pieces,
            tries=tries,
        )
    if extent is None:  # an envelope that does not close: give it a box, it will be rejected
        return _sculpture_draw(env_terms, products, 0.0, half, None, structure, envelope)
    strength, d = strength_d
    structure["ornament"].update(strength=strength)
    structure["extent"] = round(extent, 4)
    return _sculpture_draw(env_terms, products, strength, half, d, structure, envelope)


def coarse_ornament(
    rng: np.random.Generator,
    cfg: DrawSettings,
    s: SculptureSettings,
    envelope: Expr | None,
    box: Box,
    perms: tuple[tuple[int, ...], ...],
    mirror: bool,
    k: int,
    depth: float,
) -> tuple[
    Factor,
    float,
    list,
    tuple[float, float, float, int, float, int] | None,
    tuple[float, float | None],
    int,
]:
    """Draw ornaments until one carves cleanly: features at least ``min_feature`` of the box,
    at most ``max_stray`` of its surface far from the envelope, a departure from the envelope
    of at least ``min_departure``, periods the grid resolves and no pole on a plane through the
    centre (:func:`~.gridbound.pole_planes`), and a carved body in at most ``max_pieces``
    pieces (at most ``ornament_tries``; else the best drawn).
    Finer ornaments carve noise, ornaments that outgrow the envelope away from its surface
    throw debris, and ornaments that break the body into crumbs make speckle: the filters
    reject all three after evaluating and meshing the full grid, or the eye calls them rough
    balls (docs/guide/sampling.md, Families). Returns the ornament, its frequency, the expanded products, its
    checks ``(feature, stray, departure, pieces, cells per period, pole planes)`` (None
    without an envelope), its strength
    and d (:func:`~.carving.strength_on` the ``d_grid``: the checks judge the surface the draw
    will be) and the number of ornaments drawn. The unit is sampled by
    :func:`~.carving.unit_samples`."""
    # Deferred on purpose: numba kernels and scipy, loaded by the first sculpture drawn, so that
    # reading the registry (``--help``, ``config show``, ``catalogue list``) loads neither.
    import surfgen.generator.model.families.carving as carving
    from surfgen.generator.model.slope import gradient_norm

    n = s.feature_grid
    e = None if envelope is None else _eval(envelope, box, n)
    # the envelope's samples and slope on both grids: the same for every ornament tried
    ge = None if e is None else gradient_norm(e, (box.hi[0] - box.lo[0]) / (n - 1))
    step_d = (box.hi[0] - box.lo[0]) / (cfg.d_grid - 1)
    e_d = None if e is None else _eval(envelope, box, cfg.d_grid)
    ge_d = None if e_d is None else gradient_norm(e_d, step_d)
    best, best_score = None, -math.inf
    band = None
    if e is not None and ge is not None:  # where the carved surface can be: the bound's samples
        step = (box.hi[0] - box.lo[0]) / (n - 1)
        with np.errstate(invalid="ignore"):
            band = np.isfinite(e) & np.isfinite(ge) & (np.abs(e) <= (depth + 2 * step) * ge)
    for tries in range(1, s.ornament_tries + 1):
        ornament, freq = draw_ornament(rng, cfg, s)
        if e is None:
            products = ornament_terms(ornament, perms, mirror, k)
            return ornament, freq, products, None, (0.0, None), tries
        ornament, freq, cells = _resolved_ornament(ornament, freq, mirror, box, n, cfg, band)
        program = carving.ornament_program(ornament, mirror)
        poles = pole_planes(program, box, cfg.cell(box.hi[0]), n) if cfg.period_cells > 0 else 0
        if poles and best is not None:
            continue  # slit on the odd grids whatever it carves: never preferred (score below)
        resolved = cells >= cfg.period_cells * 0.999 and not poles
        o = carving.unit_samples(ornament, perms, mirror, k, box, n, program)
        feature = carving.feature_size(e, o, box, ge)
        o_d = carving.unit_samples(ornament, perms, mirror, k, box, cfg.d_grid, program)
        strength_d = carving.strength_on(e_d, o_d, step_d, depth, ge_d)
        stray, departure, f = carving.carved(e, o, box, depth, ge, strength_d)
        shaped = (
            feature >= s.min_feature
            and stray <= s.max_stray
            and departure >= s.min_departure
            and resolved
        )
        score = (
            min(feature / max(s.min_feature, 1e-9), 1.0)
            + min(departure / max(s.min_departure, 1e-9), 1.0)
            - stray
            - (not resolved)
            if not poles
            else -math.inf
        )
        if not shaped and best is not None and score <= best_score:
            continue  # neither clean nor the best, whatever its pieces: no need to count them
        n_pieces = 0 if f is None else carving.pieces(f)
        score -= n_pieces > s.max_pieces
        if best is None or score > best_score:
            checks = (feature, stray, departure, n_pieces, cells, poles)
            best, best_score = (ornament, freq, checks, strength_d), score
        if shaped and n_pieces <= s.max_pieces:
            break
    assert best is not None
    ornament, freq, checks, strength_d = best
    products = ornament_terms(ornament, perms, mirror, k)
    return ornament, freq, products, checks, strength_d, tries


def _resolved_ornament(
    ornament: Factor,
    freq: float,
    mirror: bool,
    box: Box,
    n: int,
    cfg: DrawSettings,
    band: np.ndarray | None,
) -> tuple[Factor, float, float]:
    """The ornament slowed down until its finest period spans ``[sampler] period_cells`` cells
    of the run's grid near the envelope's surface (:func:`~.gridbound.fit_factor`, on the
    mirrored copy when the group mirrors): the ornament, its frequency, its cells per period."""
    if cfg.period_cells <= 0:
        return ornament, freq, math.inf
    probe = permute_factor(ornament, (0, 1, 2), mirror)
    _, alpha, cells = fit_factor(probe, box, n, cfg.cell(box.hi[0]), cfg.period_cells, band)
    if alpha != 1.0:
        ornament = scale_arguments(ornament, alpha)
        freq = round_significant(freq * alpha, 3)
    return ornament, freq, cells


def _sculpture_draw(env_terms, products, strength, half, d, structure, envelope) -> Draw:
    terms = list(env_terms)
    for coef, prod in products:
        c = round_significant(strength * coef, 3) or 1.0
        terms.append((constant(c), *prod))
    equation = Equation13(tuple(terms), 0.0)
    return Draw(equation, Box.cube(half), None, "sculpture", structure, d, envelope)


def draw_ornament(
    rng: np.random.Generator, cfg: DrawSettings, s: SculptureSettings
) -> tuple[Factor, float]:
    """One factor of the free draw, with more constituent functions and a drawn frequency
    (the coefficients inside H and G scaled), never without a trigonometric/constituent part."""
    f = draw_factor(rng, _ornament_config(cfg, s))
    if f.h.name in ("tan", "cot", "sec", "csc") and rng.random() < s.bounded_prob:
        # Poles throw debris far from the envelope: mostly keep H to sin and cos.
        f = replace(f, h=Transform("sin" if rng.random() < 0.5 else "cos"))
    for part in ("h", "g"):
        # Jumps cut the envelope into terraces with ragged rims (a wall is a cell wide on any
        # grid): mostly keep to corners, a triangle of the same base.
        t = getattr(f, part)
        if t.name in JUMPS and rng.random() >= s.jump_prob:
            f = replace(f, **{part: Transform("tri2", (_base(t),))})
    freq = round(float(rng.uniform(*s.frequency)), 1)
    mus = list(f.mus)
    if not any(mus):
        mus[int(rng.integers(0, 4))] = 1.0
    # P3, P4, P5, P7 are the arguments of H (P6, P8 only divide P5, P7).
    powers = tuple(
        PowerFunction(
            tuple(PowerTerm(_scale(t.a, freq), t.b, t.c, t.d) for t in p.terms), p.absolute
        )
        if k in (2, 3, 4, 6)
        else p
        for k, p in enumerate(f.powers)
    )
    lambdas = list(f.lambdas)
    if s.pole_free_prob > 0 and rng.random() < s.pole_free_prob:
        f, powers = _pole_free(rng, f, powers, lambdas, mus)
    for k, mu in zip((2, 3, 4, 6), mus, strict=True):
        if mu and lambdas[k] == 0:
            lambdas[k] = 1.0
    return replace(f, powers=powers, mus=tuple(mus), lambdas=tuple(lambdas)), freq


def _base(t: Transform) -> float:
    """A constituent's period: its r, or 2 for rect1 and 1 for rect3."""
    names = CONSTITUENT_TRANSFORMS[t.name]
    return t.params[names.index("r")] if "r" in names else (2.0 if t.name == "rect1" else 1.0)


def _pole_free(
    rng: np.random.Generator,
    f: Factor,
    powers: tuple[PowerFunction, ...],
    lambdas: list[float],
    mus: list[float],
) -> tuple[Factor, tuple[PowerFunction, ...]]:
    """The ornament with nothing that divides: D, E and F left out, P6 and P8 (which divide
    the arguments of C's and F's H) the constant 1, and an H with poles (tan, cot, sec, csc)
    made sin or cos. Where a divisor vanishes, F passes through infinity or its argument
    oscillates without bound: dust, voids and walls finer than any check grid, most of the
    speckle rejections (docs/guide/sampling.md, Families). ``lambdas`` and ``mus`` are changed in place; B or C
    is kept (an ornament always has a trigonometric or constituent part)."""
    lambdas[1] = 0.0  # D = P2^l2
    mus[1] = mus[3] = 0.0  # E = H(P4)^mu2, F = G(H(P7/P8))^mu4
    if not (mus[0] or mus[2]):
        mus[0 if rng.random() < 0.5 else 2] = 1.0
    powers = tuple(ONE if k in (5, 7) else p for k, p in enumerate(powers))
    if f.h.name in ("tan", "cot", "sec", "csc"):
        f = replace(f, h=Transform("sin" if rng.random() < 0.5 else "cos"))
    return f, powers


@functools.lru_cache(maxsize=8)
def _ornament_config(cfg: DrawSettings, s: SculptureSettings) -> DrawSettings:
    """The free draw's settings for ornaments (made once per config: it is checked again)."""
    return replace(
        cfg,
        constituent_prob=s.constituent_prob,
        omit_element_prob=s.omit_element_prob,
    )


def _scale(a: float, freq: float) -> float:
    return round_significant(a * freq, 4)


FAMILY = Family(
    "sculpture",
    draw_sculpture,
    "an envelope carved by an ornament summed over a symmetry group",
    SculptureSettings,
    mix_weight=0.49,
    one_body=True,
)
