"""The ``infill`` family: an envelope filled with a triply periodic lattice (the gyroid-filled
sculpture of 3D printing), all inside equation (13).

``F = L - t + c max(E, 0)``: L a lattice of :mod:`.lattice` (gyroid, diamond, Schwarz P,
Neovius, I-WP, in sines and cosines), t its level (d), E an envelope — a superellipsoid
(optionally stretched), a torus or the product of two superellipsoids (equation B) — and
``max(E, 0) = (E + |E|)/2`` (:func:`~.bodies.positive_part`): inside the envelope F is the
lattice, outside it F grows by c per unit of E, with c set so that it clears the lattice's
whole range within half a cell of the run's grid. The solid is the lattice's ``L < t`` cut by the
envelope and closed on it; the box fits the envelope with a margin, so the shape stands free.

The period is drawn as a number of periods across the envelope, then bounded by the run's
cell size: on one period of the pattern at its level, the thinner of the struts (``L < t``) and
the pores (``L > t``) is measured (twice the 10th percentile of the distance transform's ridge,
:func:`strut_share`), and the period is made long enough that it spans
``[sampler.infill] strut_cells`` cells. Its keys: the ``[sampler.infill]`` table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from surfgen.generator.eval.evaluate import evaluate, evaluate_points
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.expr import Expr, add_all, mul_all
from surfgen.generator.model.draw import (
    Draw,
    DrawSettings,
    Family,
    choose,
    only_a,
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
from surfgen.generator.model.families.bodies import positive_part, torus
from surfgen.generator.model.families.gridbound import scale_arguments
from surfgen.generator.model.families.lattice import lattice_terms
from surfgen.generator.model.families.sculpture import envelope_extent, superellipsoid
from surfgen.generator.model.order_stats import median, quantile
from surfgen.generator.model.settings import (
    require_fractions,
    require_low_high,
    require_names,
    require_numbers,
    require_range,
    require_weighted_pairs,
)

INFILL_ENVELOPES = ("superellipsoid", "torus", "product")
INFILL_PATTERNS = ("gyroid", "diamond", "schwarz", "neovius", "iwp")
TABLE = "sampler.infill"
CELL_SAMPLES = 16  # samples per period of the pattern where struts are measured


@dataclass(frozen=True)
class InfillSettings:
    """The ``[sampler.infill]`` table (``surfgen config show``)."""

    envelopes: tuple[str, ...] = INFILL_ENVELOPES
    envelope_weights: tuple[float, ...] = (0.4, 0.3, 0.3)
    exponent: tuple[float, float] = (1.8, 4.0)  # superellipsoid |x|^p+|y|^p+|z|^p
    stretch_prob: float = 0.6  # the envelope stretched along one or two axes by 0.55-1.6
    patterns: tuple[str, ...] = INFILL_PATTERNS
    pattern_weights: tuple[float, ...] = (0.3, 0.25, 0.15, 0.15, 0.15)
    periods: tuple[float, float] = (1.8, 3.5)  # periods across the envelope's width
    strut_cells: float = 3.0  # the thinner of struts and pores spans at least this many cells
    level: tuple[float, float] = (0.25, 0.65)  # t at this quantile of L: the solid's share
    margin: tuple[float, float] = (0.08, 0.2)  # box half = envelope extent * (1 + margin)
    phase_prob: float = 0.6  # the lattice shifted by one drawn share of a period along x, y, z
    grade_prob: float = 0.4  # graded: the level goes from the centre's to a rim's (both in level)
    cut_prob: float = 0.6  # cut again: a half-space, a slab, a cube or an octahedron
    hollow_prob: float = 0.35  # a perforated shell: the envelope's inside hollowed out ...
    shell: tuple[float, float] = (0.25, 0.45)  # ... but a shell this share of its inradius thick

    def __post_init__(self) -> None:
        require_names(self, "envelopes", INFILL_ENVELOPES, TABLE)
        require_names(self, "patterns", INFILL_PATTERNS, TABLE)
        require_numbers(self, ("envelope_weights", "pattern_weights"), TABLE)
        require_weighted_pairs(
            self, (("envelopes", "envelope_weights"), ("patterns", "pattern_weights")), TABLE
        )
        probabilities = ("stretch_prob", "phase_prob", "grade_prob", "cut_prob", "hollow_prob")
        require_fractions(self, probabilities, TABLE, "a probability")
        require_low_high(self, ("exponent", "periods", "level", "margin", "shell"), TABLE)
        require_range(self, "shell", 0.05, 0.9, TABLE)
        require_range(self, "exponent", 1.0, 10.0, TABLE)
        require_range(self, "periods", 0.5, 50.0, TABLE)
        require_range(self, "level", 0.05, 0.95, TABLE)
        require_range(self, "margin", 0.0, 2.0, TABLE)
        require_range(self, "strut_cells", 0.0, 32.0, TABLE)


def _draw_envelope(
    rng: np.random.Generator, s: InfillSettings
) -> tuple[tuple[Factor, ...], dict[str, Any]]:
    """The envelope as one product of factors (each an A alone) and its description."""
    kind = str(choose(rng, s.envelopes, s.envelope_weights))
    p = round(float(rng.uniform(*s.exponent)), 1)
    radii = [1.0, 1.0, 1.0]
    if rng.random() < s.stretch_prob:
        for k in rng.choice(3, size=int(rng.integers(1, 3)), replace=False):
            radii[int(k)] = round(float(rng.uniform(0.55, 1.6)), 2)
    info: dict[str, Any] = {"kind": kind}
    if kind == "torus":
        ring = round(float(rng.uniform(0.8, 1.1)), 2)
        tube = round(ring * float(rng.uniform(0.35, 0.6)), 2)
        axis = [0.0, 0.0, 0.0]
        axis[int(rng.integers(0, 3))] = 1.0
        info.update(ring=ring, tube=tube, axis=axis)
        return (only_a(torus((0, 0, 0), axis, ring, tube).to_power_function()),), info
    info.update(exponent=p, radii=radii)
    first = only_a(superellipsoid(p, tuple(radii)))
    if kind == "superellipsoid":
        return (first,), info
    # product: a boxier body inside a rounder one (or the reverse): inside where one of them is
    p2 = round(min(p * 2.2, 8.0), 1) if p < 2.6 else round(max(p / 2.2, 1.0), 1)
    r2 = round(float(rng.uniform(0.72, 0.9) if p < 2.6 else rng.uniform(1.08, 1.3)), 2)
    info.update(second_exponent=p2, second_radius=r2)
    return (first, only_a(superellipsoid(p2, (r2,) * 3))), info


def strut_share(
    pattern_terms: list[tuple[Factor, ...]],
    q: float,
    q_rim: float | None = None,
    reach: float = 1.0,
) -> tuple[float, float, float]:
    """The levels of the lattice of period 1 at the ``q`` (centre) and ``q_rim`` (rim, default:
    the same) quantiles of its values, and the thinner of its struts (``L < t``) and pores
    (``L > t``) as a share of the period, at the centre's level and at ``t_c + (t_r - t_c)
    reach`` (the farthest a graded level goes inside the envelope): on two periods sampled
    :data:`CELL_SAMPLES` times per period, twice the 10th percentile of the distance
    transform's ridge (its local maxima) in the middle period. Returns ``(t_c, t_r, share)``."""
    m = CELL_SAMPLES
    n = 2 * m
    grid = Grid(Box((0.0,) * 3, ((n - 1) / m,) * 3), (n,) * 3)
    values = evaluate(_tree(pattern_terms), grid, threads=1).values
    t_c = float(quantile(values, q))
    t_r = t_c if q_rim is None else float(quantile(values, q_rim))
    thinnest = math.inf
    for t in {t_c, t_c + (t_r - t_c) * reach}:
        for phase in (values < t, values >= t):
            if not phase.any():
                return t_c, t_r, 0.0
            widths = phase_widths(phase, m)
            if not widths.size:
                return t_c, t_r, 0.0
            thinnest = min(thinnest, 2.0 * float(quantile(widths, 0.1)) / m)
    return t_c, t_r, thinnest


def phase_widths(phase: np.ndarray, m: int) -> np.ndarray:
    """The distance transform of ``phase`` (two periods of ``m`` samples a side) on its ridge
    in the middle period (:func:`~surfgen.generator.model.ridges.ridge_distances`); a phase
    with no sample outside it (a rim level past every value) has no transform, and gets what
    scipy's ``distance_transform_edt`` gives it, as it always did."""
    # Deferred on purpose, as the sculpture's carving: reading the registry (``--help``,
    # ``config show``) loads no scipy or numba.
    from scipy import ndimage

    from surfgen.generator.model.ridges import ridge_distances

    if not phase.all():
        return ridge_distances(phase, m // 2, m // 2 + m)
    dist = ndimage.distance_transform_edt(phase)
    ridge = phase & (dist >= ndimage.maximum_filter(dist, size=3))
    middle = (slice(m // 2, m // 2 + m),) * 3
    return dist[middle][ridge[middle]]


def _tree(terms: list[tuple[Factor, ...]]) -> Expr:
    return add_all([mul_all([f.to_tree() for f in prod]) for prod in terms])


def draw_infill(seed: int, index: int, cfg: DrawSettings, s: InfillSettings) -> Draw:
    """The ``infill`` family (see the module docstring)."""
    rng = rng_for(seed, index)
    envelope, env_info = _draw_envelope(rng, s)
    pattern = str(choose(rng, s.patterns, s.pattern_weights))
    periods = float(rng.uniform(*s.periods))
    q = float(rng.uniform(*s.level))
    hollow = bool(rng.random() < s.hollow_prob) and len(envelope) == 1
    if hollow:  # a shell is pierced by the pores, not made of a lace of struts
        q = max(q, 1.0 - q)
    margin = float(rng.uniform(*s.margin))
    phase = round(float(rng.uniform(0.1, 0.9)), 2) if rng.random() < s.phase_prob else 0.0
    env_tree = mul_all([f.to_tree() for f in envelope])
    extent = envelope_extent(env_tree) or 2.5
    half = round(extent * (1 + margin), 2)
    cell = cfg.cell(half)
    period = 2 * extent / periods
    graded = bool(rng.random() < s.grade_prob)
    q_rim = float(rng.uniform(*s.level)) if graded else q
    if hollow:
        q_rim = max(q_rim, 1.0 - q_rim)
    unit = lattice_terms(rng, pattern, *_transforms(pattern), [1.0, 1.0, 1.0])  # period 1
    slope, reach = _surface_slope(env_tree, half, extent)
    t_unit, t_rim, share = strut_share(unit, q, q_rim, reach)
    if share > 0 and s.strut_cells > 0 and period < s.strut_cells * cell / share:
        # the bound: rounded up, so rounding does not thin the struts below it
        period = _round_up(s.strut_cells * cell / share, 3)
    else:
        period = round_significant(period, 3)
    lattice = [
        tuple(
            _shifted(scale_arguments(f, 1.0 / period), phase * period) if any(f.mus) else f
            for f in t
        )
        for t in unit
    ]
    lo, hi = _range(unit)
    # outside, F = L - t + c E: E grows by about |grad E| per unit length; c clears L's range
    # within half a cell
    c = round_significant(2.0 * (hi - lo) / max(slope * cell, 1e-9), 3)
    grade = []
    if graded:  # the level from t_c at the centre to t_r at r = extent: - (t_r - t_c) r^2/extent^2
        k = round_significant(-(t_rim - t_unit) / extent**2, 4)
        grade = [(only_a(PowerFunction(tuple(PowerTerm(k, *_axis(j, 2.0)) for j in range(3)))),)]
    cut, cut_info = _cut(rng, s, extent, (hi - lo) / cell, env_info["kind"] if hollow else None)
    hollow_terms, shell = [], None
    if hollow:
        hollow_terms, shell = _hollow(rng, s, envelope, env_info, env_tree, c, s.strut_cells * cell)
    terms = [*lattice, *grade, *positive_part(envelope, c), *cut, *hollow_terms]
    structure = {
        "envelope": env_info,
        "pattern": pattern,
        "period": period,
        "periods": round(2 * extent / period, 3),
        "level_quantile": round(q, 3),
        "rim_quantile": round(q_rim, 3) if graded else None,
        "phase": phase,
        "strut_cells": round(share * period / cell, 2),
        "clip": c,
        "cut": cut_info,
        "clips": 1 + len(cut) // 2 + len(hollow_terms) // 2,
        "shell": shell,
        "extent": round(extent, 4),
        "group": "cyclic" if env_info.get("radii") == [1.0, 1.0, 1.0] else "none",
    }
    d = round_significant(t_unit, 6)
    return Draw(Equation13(tuple(terms), 0.0), Box.cube(half), None, "infill", structure, d)


def _round_up(v: float, digits: int) -> float:
    """``v`` rounded up to ``digits`` significant digits."""
    unit = 10.0 ** (math.floor(math.log10(v)) - digits + 1)
    return round_significant(math.ceil(v / unit - 1e-9) * unit, digits)


def _transforms(pattern: str) -> tuple[tuple[Transform, float], tuple[Transform, float]]:
    """H1 and H2 with the coefficient of a period 1: the gyroid in ``sin x cos y``, the
    diamond in sines and cosines, the others in cosines (centred on the envelope)."""
    w = round_significant(2 * math.pi, 6)
    h1 = Transform("sin") if pattern in ("gyroid", "diamond") else Transform("cos")
    return (h1, w), (Transform("cos"), w)


def _cut(
    rng: np.random.Generator,
    s: InfillSettings,
    extent: float,
    steepness: float,
    hollow: str | None = None,
) -> tuple[list[tuple[Factor, ...]], dict[str, Any] | None]:
    """With ``cut_prob``, more clips (each another ``c max(P, 0)``; a sum of them clips to the
    intersection of their bodies): a half-space ``x_k > -h`` (a dome, a bowl) or a slab
    ``x_k^2 < w^2`` (a disc) along a drawn axis, or — keeping the permutations — a cube (a slab
    along each axis) or an octahedron ``|x| + |y| + |z| < w``: faceted silhouettes.
    ``steepness`` is the lattice's range per cell (c clears it within half a cell). A hollow
    shell (``hollow``: its envelope's kind) is cut by a half-space or a slab only (a bowl, a
    band): a cube or an octahedron around the centre would keep little but the hollow; a
    hollow torus is not cut at all (cut open, a ring's shell is a torn strip)."""
    if hollow == "torus" or not rng.random() < s.cut_prob:
        return [], None
    kind = str(rng.choice(("half", "slab") if hollow else ("half", "slab", "cube", "octahedron")))
    axis = int(rng.integers(0, 3))
    parts: list[tuple[PowerFunction, float]] = []  # (P, |grad P| on its surface)
    if kind == "half":
        h = round(float(rng.uniform(-0.3, 0.4)) * extent, 3)
        parts.append((PowerFunction((PowerTerm(-1.0, *_axis(axis, 1.0)), PowerTerm(-h))), 1.0))
        info: dict[str, Any] = {"kind": kind, "axis": "xyz"[axis], "at": -h}
    elif kind in ("slab", "cube"):
        lo, hi = (0.3, 0.65) if kind == "slab" else (0.55, 0.85)
        w = round(float(rng.uniform(lo, hi)) * extent, 3)
        for k in (axis,) if kind == "slab" else range(3):
            square = PowerTerm(1.0, *_axis(k, 2.0))
            parts.append((PowerFunction((square, PowerTerm(round_significant(-(w**2), 6)))), 2 * w))
        info = {"kind": kind, "half_width": w} | ({"axis": "xyz"[axis]} if kind == "slab" else {})
    else:
        w = round(float(rng.uniform(0.9, 1.5)) * extent, 3)
        terms = (*(PowerTerm(1.0, *_axis(k, 1.0)) for k in range(3)), PowerTerm(-w))
        parts.append((PowerFunction(terms, absolute=True), math.sqrt(3.0)))
        info = {"kind": kind, "size": w}
    out: list[tuple[Factor, ...]] = []
    for p, slope in parts:
        out += positive_part((only_a(p),), round_significant(2.0 * steepness / slope, 3))
    return out, info


def _hollow(
    rng: np.random.Generator,
    s: InfillSettings,
    envelope: tuple[Factor, ...],
    info: dict[str, Any],
    env_tree: Expr,
    c: float,
    thinnest: float,
) -> tuple[list[tuple[Factor, ...]], dict[str, Any] | None]:
    """A **perforated shell** (drawn with ``hollow_prob``, its solid share the larger of the
    level's quantile and its complement): the envelope's inside deeper than a drawn
    thickness clipped away as its outside is (``c max(-E - e, 0)``, one more pair of sum terms),
    so the lattice is left in a shell — a wiffle ball, a radiolarian's test, a pierced lamp. The
    thickness is a drawn share (``shell``) of the envelope's inradius (the smallest radius of a
    superellipsoid, the tube of a torus), at least ``thinnest`` (the struts' bound, in cells);
    ``e`` is ``-E`` that deep below the surface along that radius (exact for a superellipsoid,
    whose level sets are scaled copies; at the torus's outer equator). Only for envelopes that
    are one power function (not the product of two). ``([], None)`` when the shell would be
    nearly as thick as the envelope."""
    share = float(rng.uniform(*s.shell))
    if info["kind"] == "torus":  # along a radius of the ring's plane, from its outer equator
        inradius = info["tube"]
        k, surface = info["axis"].index(0.0), info["ring"] + inradius
    else:  # along the smallest radius
        inradius = min(info["radii"])
        k, surface = info["radii"].index(inradius), inradius
    thickness = max(share * inradius, thinnest)
    if thickness >= 0.8 * inradius:  # nothing left to hollow at this grid
        return [], None
    point = [0.0, 0.0, 0.0]
    point[k] = surface - thickness
    # One point: the reference evaluator (numpy, the same bits as the fast one) — the fast
    # one's points kernel would be compiled here, in every worker of a cold run, for one point.
    depth = -float(evaluate_points(env_tree, *point, evaluator="reference"))
    e = round_significant(depth, 4)
    p = envelope[0].powers[0]
    terms = (*(PowerTerm(-t.a, t.b, t.c, t.d) for t in p.terms), PowerTerm(-e))
    inner = only_a(PowerFunction(terms, p.absolute))
    return positive_part((inner,), c), {"thickness": round(thickness, 4), "level": e}


def _shifted(f: Factor, shift: float) -> Factor:
    """The wave ``H(w x_k)`` as ``H(w x_k + w shift)``: the lattice moved by ``-shift`` along
    every axis (along the diagonal, which the axis permutations keep: so is the symmetry)."""
    if shift == 0:
        return f
    p = f.powers[2]
    w = sum(t.a for t in p.terms)
    terms = (*p.terms, PowerTerm(round_significant(w * shift, 4)))
    return replace(f, powers=(*f.powers[:2], PowerFunction(terms, p.absolute), *f.powers[3:]))


def _range(unit: list) -> tuple[float, float]:
    """The lattice's lowest and highest value over one period (sampled)."""
    grid = Grid(Box((0.0,) * 3, (1.0,) * 3), (12,) * 3)
    v = evaluate(_tree(unit), grid, threads=1).values
    return float(v.min()), float(v.max())


def _surface_slope(env_tree: Expr, half: float, extent: float) -> tuple[float, float]:
    """The median |grad E| near the envelope's surface, and the largest ``r^2 / extent^2``
    inside it, on a 24^3 grid of the box."""
    # Deferred on purpose (as the carving's kernels): reading the registry loads no numba
    from surfgen.generator.model.slope import gradient_norm

    n = 24
    grid = Grid(Box.cube(half), (n,) * 3)
    e = evaluate(env_tree, grid, threads=1).values
    step = 2 * half / (n - 1)
    g = gradient_norm(e, step)
    with np.errstate(invalid="ignore", over="ignore"):
        band = np.isfinite(e) & np.isfinite(g) & (np.abs(e) < 1.5 * step * g)
        inside = np.isfinite(e) & (e < 0)
    x, y, z = np.meshgrid(*grid.axes(), indexing="ij")
    r2 = (x**2 + y**2 + z**2)[inside]
    reach = float(r2.max()) / extent**2 if r2.size else 1.0
    return (float(median(g[band])) if band.any() else 1.0), reach


def _axis(j: int, e: float) -> tuple[float, float, float]:
    return tuple(e if k == j else 0.0 for k in range(3))  # type: ignore[return-value]


FAMILY = Family(
    "infill",
    draw_infill,
    "an envelope filled with a triply periodic lattice (a gyroid-filled sculpture)",
    InfillSettings,
    mix_weight=0.17,
    one_body=True,
    porous=True,
)
