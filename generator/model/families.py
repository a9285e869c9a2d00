"""Families: named, configurable distributions over equation (13) instances.

Every family draws a plain :class:`~surfgen.generator.model.equation13.Equation13` — a sum of products
of factors ``A/D * B/E * C/F`` minus d — so every shape stays an instance of the paper's model;
what a family changes is *which* instances are likely (``[sampler] family``, ``mix``):

- ``sculpture`` (the paper's equations A and B, and MathMod's curated surfaces): an **envelope**,
  a bounded sum term whose A is a power function with a constant term — a superellipsoid
  ``|x|^p + |y|^p + |z|^p - 1`` (optionally stretched along one axis), a product of two of them
  (the two factors of one sum term, as equation B's ``(x²+y²+z²-5)(|x|^0.13|y|^0.13|z|^0.13-5)``),
  or a superellipsoid closed by a cubic term as in equation C — plus an **ornament**: one factor
  of the free draw, summed over a symmetry group (the 3 cyclic or all 6 axis permutations, each
  copy one more sum term; ``mirror`` groups use ``|x|, |y|, |z|``), optionally under an outer
  power k (``(O_1 + O_2 + O_3)^k`` expanded into the sum of its products of k factors, the
  multinomial coefficients folded into the constant factor in front). The ornament's strength is
  drawn relative to its own spread near the envelope's surface, so it carves to a drawn depth
  (a fraction of the envelope's size) without erasing it; d is the ornament's median there, so
  the carved surface stays on the envelope on average; the box fits the envelope with a margin,
  so the shape stands free.
- ``lattice``: triply periodic patterns of linear arguments — Schwarz-like ``Σ H(w x_k)``,
  gyroid-like ``Σ_cyclic H1(w x_k) H2(w x_k+1)``, or a product ``Π H(w x_k)`` plus a Schwarz
  part — with H a sine/cosine or a continuous or pulse constituent function (Figure 3's porous
  cubes); cut by the box and capped; d at a quantile near the middle of the values.
- ``free``: :func:`surfgen.generator.model.sampler.draw_free`, the first sampler's draw.

Each family is a pure function of ``(seed, index, config)``: it reads only
:func:`~surfgen.generator.model.sampler.rng_for` ``(seed, index)``, and ``mix`` picks the family from a
second stream of the same index.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections import Counter
from dataclasses import replace
from typing import Any

import numba
import numpy as np
from scipy import ndimage

from surfgen.generator.eval.compiler import Program, compile_tree
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.tape import evaluate_program
from surfgen.generator.formula.expr import Expr, add_all, mul_all
from surfgen.generator.model.equation13 import (
    Equation13,
    Factor,
    PowerFunction,
    PowerTerm,
    Transform,
)
from surfgen.generator.model.sampler import (
    Draw,
    SamplerConfig,
    _choice,
    draw_factor,
    draw_free,
    rng_for,
    round_significant,
)

ONE = PowerFunction.constant(1.0)
_CYCLIC = ((0, 1, 2), (1, 2, 0), (2, 0, 1))
_ALL = tuple(itertools.permutations(range(3)))
GROUP_PERMUTATIONS = {
    "none": ((0, 1, 2),),
    "mirror": ((0, 1, 2),),
    "cyclic": _CYCLIC,
    "cyclic_mirror": _CYCLIC,
    "full": _ALL,
    "full_mirror": _ALL,
}
EXTENT_GRID = 33  # samples per axis of the search box used to measure an envelope's extent
EXTENT_BOX = 2.5
# Continuous and pulse constituents for lattices (saw teeth would draw walls at every jump).
LATTICE_CONSTITUENTS = ("tri2", "tri3", "rect2")


def family_rng(seed: int, index: int) -> np.random.Generator:
    """The stream ``mix`` picks shape ``index``'s family from (separate from the draw's own)."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index, 1)))


def pick_family(seed: int, index: int, cfg: SamplerConfig) -> str:
    """The family of shape ``index``: ``cfg.family``, or a weighted pick from ``cfg.mix``."""
    if cfg.family != "mix":
        return cfg.family
    return str(_choice(family_rng(seed, index), cfg.mix, cfg.mix_weights))


def draw_family(seed: int, index: int, cfg: SamplerConfig) -> Draw:
    """Shape ``index`` of the run ``seed`` in the configured family (or mix)."""
    family = pick_family(seed, index, cfg)
    if family == "sculpture":
        return draw_sculpture(seed, index, cfg)
    if family == "lattice":
        return draw_lattice(seed, index, cfg)
    return draw_free(seed, index, cfg)


# ----------------------------------------------------------------------------- building blocks


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
    return only_a(PowerFunction.constant(value))


def permute_power(p: PowerFunction, perm: tuple[int, ...], absolute: bool) -> PowerFunction:
    """``p`` with the variable of axis k moved to axis ``perm[k]`` (x -> perm's axis)."""
    terms = []
    for t in p.terms:
        e = [0.0, 0.0, 0.0]
        for k, v in enumerate((t.b, t.c, t.d)):
            e[perm[k]] = v
        terms.append(PowerTerm(t.a, *e))
    return PowerFunction(tuple(terms), p.absolute or absolute)


def permute_factor(f: Factor, perm: tuple[int, ...], absolute: bool = False) -> Factor:
    """The factor with its variables permuted; ``absolute`` puts every power function in
    ``|x|, |y|, |z|`` (the mirror symmetries)."""
    return replace(f, powers=tuple(permute_power(p, perm, absolute) for p in f.powers))


def _superellipsoid(p: float, radii: tuple[float, float, float]) -> PowerFunction:
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


# ----------------------------------------------------------------------------- sculpture


def _draw_envelope(
    rng: np.random.Generator, cfg: SamplerConfig, permutes: bool
) -> tuple[list[tuple[Factor, ...]], dict[str, Any]]:
    """The envelope's sum terms and their description."""
    kind = str(_choice(rng, cfg.sculpture_envelopes, cfg.sculpture_envelope_weights))
    p = round(float(rng.uniform(*cfg.sculpture_exponent)), 1)
    radii = [1.0, 1.0, 1.0]
    if rng.random() < cfg.sculpture_stretch_prob:
        radii[int(rng.integers(0, 3))] = round(float(rng.uniform(0.6, 1.5)), 2)
    info: dict[str, Any] = {"kind": kind, "exponent": p, "radii": list(radii)}
    first = _superellipsoid(p, tuple(radii))
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
        return [(only_a(first), only_a(_superellipsoid(p2, (r2,) * 3)))], info
    # cubic: a superellipsoid steep enough (p > 3) to stay closed, plus c x^3 (summed over
    # the axes when the ornament is permuted, to keep that symmetry), as in equation C.
    p = round(max(p, 3.5) + 1.0, 1)
    first = _superellipsoid(p, tuple(radii))
    c = round(float(rng.uniform(0.25, 0.7)) * (1 if rng.random() < 0.5 else -1), 2)
    axes = range(3) if permutes else (0,)
    cubic = PowerFunction(
        tuple(PowerTerm(c, *(3.0 if j == k else 0.0 for j in range(3))) for k in axes)
    )
    info.update(exponent=p, cubic=c, cubic_axes=len(axes))
    return [(only_a(first),), (only_a(cubic),)], info


def _envelope_extent(tree: Expr) -> float | None:
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


def _draw_ornament(rng: np.random.Generator, cfg: SamplerConfig) -> tuple[Factor, float]:
    """One factor of the free draw, with more constituent functions and a drawn frequency
    (the coefficients inside H and G scaled), never without a trigonometric/constituent part."""
    f = draw_factor(rng, _ornament_config(cfg))
    if f.h.name in ("tan", "cot", "sec", "csc") and rng.random() < cfg.sculpture_bounded_prob:
        # Poles throw debris far from the envelope: mostly keep H to sin and cos.
        f = replace(f, h=Transform("sin" if rng.random() < 0.5 else "cos"))
    freq = round(float(rng.uniform(*cfg.sculpture_frequency)), 1)
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
    if cfg.sculpture_pole_free_prob > 0 and rng.random() < cfg.sculpture_pole_free_prob:
        f, powers = _pole_free(rng, f, powers, lambdas, mus)
    for k, mu in zip((2, 3, 4, 6), mus, strict=True):
        if mu and lambdas[k] == 0:
            lambdas[k] = 1.0
    return replace(f, powers=powers, mus=tuple(mus), lambdas=tuple(lambdas)), freq


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
    speckle rejections (README, Families). ``lambdas`` and ``mus`` are changed in place; B or C
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
def _ornament_config(cfg: SamplerConfig) -> SamplerConfig:
    """The free draw's settings for ornaments (made once per config: it is checked again)."""
    return replace(
        cfg,
        constituent_prob=cfg.sculpture_constituent_prob,
        omit_element_prob=cfg.sculpture_omit_element_prob,
    )


def _scale(a: float, freq: float) -> float:
    return round_significant(a * freq, 4)


def _ornament_combos(copies: int, k: int) -> list[tuple[float, tuple[int, ...]]]:
    """``(Σ_c O_c)^k`` expanded: (multinomial coefficient, copy indices) per product."""
    out = []
    for combo in itertools.combinations_with_replacement(range(copies), k):
        counts = Counter(combo)
        coef = math.factorial(k)
        for c in counts.values():
            coef //= math.factorial(c)
        out.append((float(coef), combo))
    return out


def _ornament_terms(
    ornament: Factor, perms: tuple[tuple[int, ...], ...], mirror: bool, k: int
) -> list[tuple[float, tuple[Factor, ...]]]:
    """``(Σ_perms O∘perm)^k`` expanded: (multinomial coefficient, factors) per product."""
    copies = [permute_factor(ornament, p, mirror) for p in perms]
    return [
        (coef, tuple(copies[i] for i in combo)) for coef, combo in _ornament_combos(len(copies), k)
    ]


def _inverse(perm: tuple[int, ...]) -> tuple[int, ...]:
    out = [0] * len(perm)
    for k, v in enumerate(perm):
        out[v] = k
    return tuple(out)


def _ornament_program(ornament: Factor, mirror: bool) -> Program:
    """The ornament's unit copy (with ``|x|, |y|, |z|`` when ``mirror``) compiled once: a try
    samples it on the feature grid and on the d grid."""
    return compile_tree(permute_factor(ornament, (0, 1, 2), mirror).to_tree())


def _unit_samples(
    ornament: Factor,
    perms: tuple[tuple[int, ...], ...],
    mirror: bool,
    k: int,
    box: Box,
    n: int,
    program: Program | None = None,
) -> np.ndarray:
    """The ornament's unit ``(Σ_perms O∘perm)^k`` sampled on the cube ``box`` (``n`` per axis),
    for the checks: the ornament (with ``|x|, |y|, |z|`` when ``mirror``) is evaluated once, and
    its permuted copies are the same samples with the axes transposed (the cube's three axes
    are the same coordinates), then multiplied and summed in numpy as
    :func:`_ornament_terms` writes them. A copy's samples may differ from the evaluation of its
    own formula in the last bits, where the formula adds its terms in another order."""
    if len(set(box.lo)) != 1 or len(set(box.hi)) != 1:
        raise ValueError(f"the ornament's copies are transposed samples: {box} must be a cube")
    if program is None:
        program = _ornament_program(ornament, mirror)
    base = evaluate_program(program, Grid(box, (n,) * 3), threads=1).values
    # O∘perm(x) = O(x[perm[0]], x[perm[1]], x[perm[2]]): sample i of the copy is sample
    # (i[perm[0]], ...) of O, which is O's array with its axes put in the inverse order.
    copies = [np.transpose(base, _inverse(p)) for p in perms]
    total = None
    with np.errstate(invalid="ignore", over="ignore"):
        for coef, combo in _ornament_combos(len(perms), k):
            product = copies[combo[0]]
            for i in combo[1:]:
                product = product * copies[i]
            product = product * coef
            total = product if total is None else total + product
    assert total is not None
    return np.ascontiguousarray(total)


def draw_sculpture(seed: int, index: int, cfg: SamplerConfig) -> Draw:
    """The ``sculpture`` family (see the module docstring)."""
    rng = rng_for(seed, index)
    group = str(_choice(rng, cfg.sculpture_groups, cfg.sculpture_group_weights))
    perms = GROUP_PERMUTATIONS[group]
    mirror = group.endswith("mirror")
    k = int(_choice(rng, cfg.sculpture_powers, cfg.sculpture_power_weights))
    if len(perms) > 3:  # (6 copies)^k would print as dozens of products
        k = 1
    env_terms, env_info = _draw_envelope(rng, cfg, permutes=len(perms) > 1)
    depth = round(float(rng.uniform(*cfg.sculpture_depth)), 2)
    margin = float(rng.uniform(*cfg.sculpture_margin))
    envelope = _sum_tree(env_terms)
    extent = _envelope_extent(envelope)
    half = EXTENT_BOX if extent is None else round(extent * (1 + depth + margin), 2)
    box = Box.cube(half)
    ornament, freq, products, checks, strength_d, tries = _coarse_ornament(
        rng,
        cfg,
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
        feature, stray, departure, pieces = checks
        structure["ornament"].update(
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


def _coarse_ornament(
    rng: np.random.Generator,
    cfg: SamplerConfig,
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
    tuple[float, float, float, int] | None,
    tuple[float, float | None],
    int,
]:
    """Draw ornaments until one carves cleanly: features at least ``sculpture_min_feature`` of
    the box, at most ``sculpture_max_stray`` of its surface far from the envelope, a departure
    from the envelope of at least ``sculpture_min_departure``, and a carved body in at most
    ``sculpture_max_pieces`` pieces (at most ``sculpture_ornament_tries``; else the best drawn).
    Finer ornaments carve noise, ornaments that outgrow the envelope away from its surface
    throw debris, and ornaments that break the body into crumbs make speckle: the filters
    reject all three after evaluating and meshing the full grid, or the eye calls them rough
    balls (README, Families). Returns the ornament, its frequency, the expanded products, its
    checks ``(feature, stray, departure, pieces)`` (None without an envelope), its strength
    and d (:func:`_strength_on` the ``d_grid``: the checks judge the surface the draw will be)
    and the number of ornaments drawn. The unit is sampled by :func:`_unit_samples`."""
    n = cfg.sculpture_feature_grid
    e = None if envelope is None else _eval(envelope, box, n)
    # the envelope's samples and slope on both grids: the same for every ornament tried
    ge = None if e is None else _slope(e, (box.hi[0] - box.lo[0]) / (n - 1))
    step_d = (box.hi[0] - box.lo[0]) / (cfg.d_grid - 1)
    e_d = None if e is None else _eval(envelope, box, cfg.d_grid)
    ge_d = None if e_d is None else _slope(e_d, step_d)
    best, best_score = None, -math.inf
    for tries in range(1, cfg.sculpture_ornament_tries + 1):
        ornament, freq = _draw_ornament(rng, cfg)
        if e is None:
            products = _ornament_terms(ornament, perms, mirror, k)
            return ornament, freq, products, None, (0.0, None), tries
        program = _ornament_program(ornament, mirror)
        o = _unit_samples(ornament, perms, mirror, k, box, n, program)
        feature = _feature_size(e, o, box, ge)
        o_d = _unit_samples(ornament, perms, mirror, k, box, cfg.d_grid, program)
        strength_d = _strength_on(e_d, o_d, step_d, depth, ge_d)
        stray, departure, f = _carved(e, o, box, depth, ge, strength_d)
        shaped = (
            feature >= cfg.sculpture_min_feature
            and stray <= cfg.sculpture_max_stray
            and departure >= cfg.sculpture_min_departure
        )
        score = (
            min(feature / max(cfg.sculpture_min_feature, 1e-9), 1.0)
            + min(departure / max(cfg.sculpture_min_departure, 1e-9), 1.0)
            - stray
        )
        if not shaped and best is not None and score <= best_score:
            continue  # neither clean nor the best, whatever its pieces: no need to count them
        n_pieces = 0 if f is None else pieces(f)
        score -= n_pieces > cfg.sculpture_max_pieces
        if best is None or score > best_score:
            checks = (feature, stray, departure, n_pieces)
            best, best_score = (ornament, freq, checks, strength_d), score
        if shaped and n_pieces <= cfg.sculpture_max_pieces:
            break
    assert best is not None
    ornament, freq, checks, strength_d = best
    products = _ornament_terms(ornament, perms, mirror, k)
    return ornament, freq, products, checks, strength_d, tries


def _stray_share(e: np.ndarray, o: np.ndarray, box: Box, depth: float) -> float:
    """The share of the carved surface's crossings (on the feature grid, strength and d as
    :func:`_strength_on` sets them) that lie farther from the envelope's surface than twice the
    carving depth plus two cells: debris thrown away from the body. 1 when it cannot tell."""
    return _carved(e, o, box, depth)[0]


def _carved(
    e: np.ndarray,
    o: np.ndarray,
    box: Box,
    depth: float,
    ge: np.ndarray | None = None,
    strength_d: tuple[float, float | None] | None = None,
) -> tuple[float, float, np.ndarray | None]:
    """The carved surface ``e + s o - d = 0`` on the feature grid (s and d as
    :func:`_strength_on` sets them): its stray share (see :func:`_stray_share`; 1 when it
    cannot tell), its :func:`envelope_departure` (0 when it cannot tell), which the ``plain``
    filter judges on the full grid, and its samples ``e + s o - d`` (None when it cannot tell;
    :func:`pieces` counts its pieces). ``strength_d``: s and d if already chosen (else
    :func:`_strength_on` these samples)."""
    n = e.shape[0]
    step = (box.hi[0] - box.lo[0]) / (n - 1)
    ge = _slope(e, step) if ge is None else ge
    s, d = _strength_on(e, o, step, depth, ge) if strength_d is None else strength_d
    if d is None:
        return 1.0, 0.0, None
    with np.errstate(invalid="ignore", over="ignore"):
        f = e + s * o - d
        distance = np.abs(e) / np.where(ge > 0, ge, np.inf)
    inside = f < 0
    crossing = np.zeros_like(inside)
    for axis in range(3):
        change = np.diff(inside, axis=axis)
        lo = [slice(None)] * 3
        lo[axis] = slice(0, -1)
        crossing[tuple(lo)] |= change
    count = np.count_nonzero(crossing)
    if count == 0:
        return 1.0, 0.0, None
    far = crossing & ~(distance <= 2 * depth + 2 * step)
    departure = envelope_departure(f, e)
    stray = np.count_nonzero(far) / count
    return stray, departure if math.isfinite(departure) else 0.0, f


_CUBE = np.ones((3, 3, 3), dtype=bool)


def pieces(values: np.ndarray, level: float = 0.0) -> int:
    """How many pieces the closed surface ``values = level`` has at least, from the samples
    alone: (components of the solid) + (components of the rest, the outside of the box
    included) - 1, both connected through the 26 neighbours of a sample.

    A capped marching-cubes surface separates the solid's regions from the rest's, each of its
    components exactly two of them, and the regions with the surfaces between them form a tree
    (every closed surface in space splits it in two): surfaces = regions - 1. Marching cubes
    joins samples only within a cell, where all are 26-neighbours, so it has at least as many
    regions of each kind as this count: the count never exceeds the mesh's components. The
    solid is the mesher's (finite samples below the level)."""
    with np.errstate(invalid="ignore"):
        solid = np.isfinite(values) & (values < level)
    if not solid.any() or solid.all():
        return 0
    n_solid = ndimage.label(solid, structure=_CUBE)[1]
    n_rest = ndimage.label(np.pad(~solid, 1, constant_values=True), structure=_CUBE)[1]
    return int(n_solid + n_rest - 1)


def envelope_departure(values: np.ndarray, envelope: np.ndarray, level: float = 0.0) -> float:
    """How far the surface ``values = level`` departs from its envelope ``envelope = 0``, both
    sampled on the same grid: the spread (5th to 95th percentile) of the envelope's normal
    offset ``E / |grad E|`` over the surface, divided by the envelope's radius (that of a ball of
    its volume). A shape that is its envelope, or its envelope grown or shrunk evenly, gives
    about 0; a few scratches leave the percentiles alone; deep carving gives 0.2 and more.

    The surface points are where the grid's edges cross the level, interpolated linearly (the
    marching-cubes vertices), so the measure does not see the grid's staircase. Returns
    ``inf`` when the envelope is empty on the grid or the surface has too few points.

    ``|grad E|`` is ``numpy.gradient``'s (central differences inside, one-sided at the faces, in
    grid steps), computed only at the ends of the crossing edges (:func:`_crossing_offsets`:
    the same operations, so the same bits, without the three whole-grid gradient arrays).
    """
    f = np.ascontiguousarray(values, dtype=np.float64)
    env = np.ascontiguousarray(envelope, dtype=np.float64)
    if f.ndim != 3 or f.shape != env.shape or min(f.shape) < 2:
        raise ValueError(f"values and envelope must be one 3-D grid, got {f.shape}, {env.shape}")
    n_env, off = _crossing_offsets(f, float(level), env)
    if n_env == 0:
        return float("inf")
    off = off[np.isfinite(off)]
    if off.size < 8:
        return float("inf")
    radius = (3.0 * n_env / (4.0 * np.pi)) ** (1.0 / 3.0)  # in grid steps, like the offsets
    lo, hi = np.quantile(off, (0.05, 0.95))
    return float((hi - lo) / radius)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _gradient_norm(e: np.ndarray, i: int, j: int, k: int) -> float:
    """``sqrt(gx² + gy² + gz²)`` of ``numpy.gradient(e)`` (unit spacing, edge order 1) at one
    point, with numpy's operations: ``(e[i+1] - e[i-1]) / 2`` inside, a one-sided difference on
    the faces, the squares summed in axis order."""
    n0, n1, n2 = e.shape
    if i == 0:
        g0 = e[1, j, k] - e[0, j, k]
    elif i == n0 - 1:
        g0 = e[i, j, k] - e[i - 1, j, k]
    else:
        g0 = (e[i + 1, j, k] - e[i - 1, j, k]) / 2.0
    if j == 0:
        g1 = e[i, 1, k] - e[i, 0, k]
    elif j == n1 - 1:
        g1 = e[i, j, k] - e[i, j - 1, k]
    else:
        g1 = (e[i, j + 1, k] - e[i, j - 1, k]) / 2.0
    if k == 0:
        g2 = e[i, j, 1] - e[i, j, 0]
    elif k == n2 - 1:
        g2 = e[i, j, k] - e[i, j, k - 1]
    else:
        g2 = (e[i, j, k + 1] - e[i, j, k - 1]) / 2.0
    return math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _crossing_offsets(v: np.ndarray, level: float, e: np.ndarray) -> tuple[int, np.ndarray]:
    """The envelope's cell count (finite and < 0) and, for every grid edge whose ends are
    finite and on either side of ``level``, ``E / |grad E|`` interpolated linearly to the
    crossing (axis by axis, in C order: the order does not change the percentiles)."""
    n0, n1, n2 = v.shape
    n_env = 0
    for i in range(n0):
        for j in range(n1):
            for k in range(n2):
                x = e[i, j, k]
                if np.isfinite(x) and x < 0:
                    n_env += 1
    out = np.empty(3 * v.size, np.float64)
    m = 0
    for axis in range(3):
        for i in range(n0 - (axis == 0)):
            for j in range(n1 - (axis == 1)):
                for k in range(n2 - (axis == 2)):
                    i1 = i + (axis == 0)
                    j1 = j + (axis == 1)
                    k1 = k + (axis == 2)
                    f0 = v[i, j, k] - level
                    f1 = v[i1, j1, k1] - level
                    if not (np.isfinite(f0) and np.isfinite(f1)) or (f0 < 0) == (f1 < 0):
                        continue
                    t = f0 / (f0 - f1)
                    e0 = e[i, j, k]
                    g0 = _gradient_norm(e, i, j, k)
                    ee = e0 + t * (e[i1, j1, k1] - e0)
                    g = g0 + t * (_gradient_norm(e, i1, j1, k1) - g0)
                    out[m] = ee / g
                    m += 1
    return n_env, out[:m]


def _slope(a: np.ndarray, step: float) -> np.ndarray:
    """``|grad a|`` by central differences (non-finite where ``a`` overflows)."""
    with np.errstate(invalid="ignore", over="ignore"):
        return np.sqrt(sum(g**2 for g in np.gradient(a, step)))


def _feature_size(e: np.ndarray, o: np.ndarray, box: Box, ge: np.ndarray | None = None) -> float:
    """How large the ornament ``o``'s features are where the envelope ``e`` has its surface:
    the 10-90 % spread of ``o`` over the median of ``|grad o|`` there, over the box's half-size
    (about 0.36 wavelengths of a sine; a grid too coarse to see the features gives about one
    cell). 0 when it cannot be measured (a constant, non-finite ornament)."""
    n = e.shape[0]
    step = (box.hi[0] - box.lo[0]) / (n - 1)
    ge = _slope(e, step) if ge is None else ge
    go = _slope(o, step)
    ok = np.isfinite(e) & np.isfinite(o) & np.isfinite(ge) & np.isfinite(go) & (ge > 0)
    band = ok & (np.abs(e) < 1.5 * step * np.where(ok, ge, 0.0))
    if np.count_nonzero(band) < 16:
        return 0.0
    lo, hi = np.quantile(o[band], (0.1, 0.9))
    slope = float(np.median(go[band]))
    if not (slope > 0 and math.isfinite(float(hi - lo))):
        return 0.0
    return float(hi - lo) / slope / float(box.hi[0])


def _sculpture_draw(env_terms, products, strength, half, d, structure, envelope) -> Draw:
    terms = list(env_terms)
    for coef, prod in products:
        c = round_significant(strength * coef, 3) or 1.0
        terms.append((constant(c), *prod))
    equation = Equation13(tuple(terms), 0.0)
    return Draw(equation, Box.cube(half), None, "sculpture", structure, d, envelope)


def _strength_on(
    e: np.ndarray, o: np.ndarray, step: float, depth: float, grad: np.ndarray | None = None
) -> tuple[float, float | None]:
    """The ornament's strength s that moves the envelope's surface by about ``depth`` where
    the ornament is at its 10th or 90th percentile near that surface, and d = s * its median
    there, from the sampled envelope ``e`` and ornament ``o`` (grid step ``step``; ``grad``:
    ``e``'s :func:`_slope` if already known). d is None when the ornament is constant or
    non-finite near the surface."""
    grad = _slope(e, step) if grad is None else grad
    ok = np.isfinite(e) & np.isfinite(o) & np.isfinite(grad) & (grad > 0)
    band = ok & (np.abs(e) < 1.5 * step * np.where(ok, grad, 0.0))
    if np.count_nonzero(band) < 16:
        return 1.0, None
    lo, med, hi = np.quantile(o[band], (0.1, 0.5, 0.9))
    spread = float(hi - lo)
    if not spread > 0 or not math.isfinite(spread):
        return 1.0, None
    slope = float(np.median(grad[band]))
    s = round_significant(depth * slope / spread, 3)
    if s == 0:
        return 1.0, None
    return s, round_significant(s * float(med), 6)


# ----------------------------------------------------------------------------- lattice


def _lattice_transform(
    rng: np.random.Generator, cfg: SamplerConfig, period: float
) -> tuple[Transform, float]:
    """H and the coefficient of its linear argument for the given period."""
    if rng.random() < cfg.lattice_constituent_prob:
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


def draw_lattice(seed: int, index: int, cfg: SamplerConfig) -> Draw:
    """The ``lattice`` family (see the module docstring)."""
    rng = rng_for(seed, index)
    pattern = str(_choice(rng, cfg.lattice_patterns, cfg.lattice_pattern_weights))
    half = round(float(rng.uniform(*cfg.box_half)), 1)
    periods = float(rng.uniform(*cfg.lattice_periods))
    period = 2 * half / periods
    scales = [1.0, 1.0, 1.0]
    if rng.random() < cfg.lattice_anisotropy_prob:
        scales = [round(float(rng.uniform(*cfg.lattice_anisotropy)), 2) for _ in range(3)]
    if pattern in ("diamond",):  # written in sines and cosines: the pattern needs both
        h1, w1 = Transform("sin"), round(2 * math.pi / period, 4)
        h2, w2 = Transform("cos"), w1
    else:
        h1, w1 = _lattice_transform(rng, cfg, period)
        h2, w2 = _lattice_transform(rng, cfg, period)

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
    q = float(rng.uniform(*cfg.lattice_d_quantile))
    structure = {
        "pattern": pattern,
        "periods": round(periods, 3),
        "H": [h1.name] if pattern in ("schwarz", "neovius") else [h1.name, h2.name],
        "group": "cyclic" if scales[0] == scales[1] == scales[2] else "none",
        "axis_scales": scales,
    }
    return Draw(Equation13(tuple(terms), 0.0), Box.cube(half), q, "lattice", structure)
