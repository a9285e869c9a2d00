"""The ``twist`` family: twisted columns — a capped column whose cross-section has m lobes that
turn along its axis (a twisted bar for m = 2, a drill or a twisted candle for more), all
inside equation (13).

With ``r^2 = x^2 + y^2`` and ``(x + i y)^m = Re_m + i Im_m`` (whole powers of x and y), the lobes
``r^2 cos(m (phi - k z))`` are ``(Re_m cos(m k z) + Im_m sin(m k z)) / r^(m-2)``: two factors
``A/D * B`` (A the polynomial ``Re_m`` or ``Im_m``, D the power function ``(x^2 + y^2 + δ)`` to
the power ``(m - 2)/2``, B the cosine or sine of ``m k z``). The column::

    F = r^2 (1 + β z^2/H^2) + ε r^2 cos(m (phi - k z)) + |z/H|^q - 1

(its section flattened to an ellipse with ``ellipse_prob``: ``y^2`` over a drawn ratio
squared; ``β >= 0`` narrows its ends into a barrel — a negative one would open it to infinity —,
``q`` rounds or flattens its ends) is inside where
``r^2 (1 + ε cos ...) < 1 - |z/H|^q``: lobes of depth ε. A **braid** adds a second set of lobes
(2m of them, smaller) turning the other way. With ``taper_prob`` the column is a **spire**:
``r^2`` becomes ``r^2 T(z)`` with ``T = (1 + τ z/H)^2`` (its odd part ``2τ r^2 z/H`` one more sum
term, of whole powers: no ``|·|``), wide at one end and narrow at the other (a horn, a drill
bit, a shell's spire), and the lobes scale with it; ``T`` is a square, so the column never
opens to the box. With ``swell_prob`` the lobes deepen towards one end: their depth
``ε (1 + γ z/H)`` (at most 0.8), from flutes that fade out to a plain tip to blades. With
``bend_prob`` the column is **bent** into a horn: its axis is the parabola ``x = b z^2`` (or
``y = b z^2``), ``x`` becoming ``x - b z^2`` in the section and the lobes (polynomials still:
the bent terms are whole powers, one more sum term beside the body's ``|·|`` one), its ends
``δ = b H^2`` to one side, ``δ/H`` drawn so the axis leans at most 45° (slope ``2δ/H <= 1``); a
bent column is not braided (see :data:`BENT_DIGITS`). The column lies along a drawn axis; the
box fits it with a margin, so it stands free.

Resolution (:mod:`.gridbound`): the lobes along the axis repeat every ``2 pi / (m k)``, which
must span ``[sampler] period_cells`` cells (k is lowered), and around it every ``2 pi R / m`` at
the valleys' radius, likewise (m is lowered). Its keys: the ``[sampler.twist]`` table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from surfgen.generator.eval.grid import Box
from surfgen.generator.formula.expr import add_all, mul_all
from surfgen.generator.model.draw import (
    ONE,
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
from surfgen.generator.model.families.bodies import Polynomial
from surfgen.generator.model.families.gridbound import fit_terms
from surfgen.generator.model.families.sculpture import envelope_extent
from surfgen.generator.model.families.symmetry import permute_factor
from surfgen.generator.model.settings import (
    require_fractions,
    require_low_high,
    require_numbers,
    require_range,
    require_weighted_pairs,
)

TABLE = "sampler.twist"
DELTA = 0.01  # keeps r^(m-2) from 0/0 on the axis
X, Y = Polynomial({(1, 0, 0): 1.0}), Polynomial({(0, 1, 0): 1.0})
# Significant digits of a bent column's coefficients: its lobes' numerators are polynomials in
# x - b z^2 expanded, whose terms cancel on the bent axis, where they are divided by DELTA^((m-2)/2);
# 6 digits left errors of 1e4 there (beads of inside along the axis beyond the ends). With 12,
# and m <= 6 (a bent column is not braided: 2m lobes cancel too much), the bent field is the
# straight one sheared to within 1e-3 of its values in the box.
BENT_DIGITS = 12


@dataclass(frozen=True)
class TwistSettings:
    """The ``[sampler.twist]`` table (``surfgen config show``)."""

    lobes: tuple[int, ...] = (2, 3, 4, 5, 6)  # m: lobes of the cross-section
    lobe_weights: tuple[float, ...] = (0.1, 0.25, 0.25, 0.2, 0.2)
    lobe_depth: tuple[float, float] = (0.4, 0.65)  # ε
    turns: tuple[float, float] = (0.6, 1.8)  # turns of a lobe from one end to the other
    height: tuple[float, float] = (1.3, 4.0)  # H / R: half-height over the column's radius
    cap: tuple[float, float] = (2.0, 8.0)  # q of |z/H|^q: round (2) to flat (8) ends
    bulge: tuple[float, float] = (0.0, 0.8)  # β: straight (0) to a barrel (narrower ends)
    braid_prob: float = 0.6  # a second set of 2m lobes turning the other way
    ellipse_prob: float = 0.5  # the column's section flattened along y to an ellipse ...
    ellipse: tuple[float, float] = (0.55, 0.9)  # ... of this ratio of its axes
    taper_prob: float = 0.5  # a spire: r^2 (1 + τ z/H)^2, wide at one end ...
    taper: tuple[float, float] = (0.2, 0.45)  # ... |τ| (its sign drawn)
    swell_prob: float = 0.5  # lobes deeper towards one end: depth ε (1 + γ z/H) ...
    swell: tuple[float, float] = (0.4, 0.9)  # ... |γ| (its sign drawn; ε(1+|γ|) kept <= 0.8)
    bend_prob: float = 0.5  # a horn: the axis bent into the parabola x = b z^2 ...
    bend: tuple[float, float] = (0.25, 0.5)  # ... its ends b H^2 = this * H to one side
    margin: tuple[float, float] = (0.08, 0.2)  # box half = extent * (1 + margin)

    def __post_init__(self) -> None:
        require_numbers(self, ("lobe_weights",), TABLE)
        require_weighted_pairs(self, (("lobes", "lobe_weights"),), TABLE)
        require_range(self, "lobes", 2, 12, TABLE)
        probabilities = ("braid_prob", "ellipse_prob", "taper_prob", "swell_prob", "bend_prob")
        require_fractions(self, probabilities, TABLE, "a probability")
        require_range(self, "ellipse", 0.2, 1.0, TABLE)
        names = (
            "lobe_depth",
            "turns",
            "height",
            "cap",
            "bulge",
            "margin",
            "ellipse",
            "taper",
            "swell",
            "bend",
        )
        require_low_high(self, names, TABLE)
        require_range(self, "lobe_depth", 0.0, 0.95, TABLE)
        require_range(self, "turns", 0.0, 10.0, TABLE)
        require_range(self, "height", 0.3, 5.0, TABLE)
        require_range(self, "cap", 1.0, 16.0, TABLE)
        require_range(self, "bulge", 0.0, 3.0, TABLE)
        require_range(self, "margin", 0.0, 2.0, TABLE)
        require_range(self, "taper", 0.0, 0.9, TABLE)
        require_range(self, "swell", 0.0, 3.0, TABLE)
        require_range(self, "bend", 0.0, 0.5, TABLE)


def harmonic(
    m: int, u: Polynomial | None = None, v: Polynomial | None = None
) -> tuple[Polynomial, Polynomial]:
    """``Re`` and ``Im`` of ``(u + i v)^m`` as polynomials: of ``(x + i y)^m`` by default, of a
    bent column's section coordinates when given."""
    u = X if u is None else u
    v = Y if v is None else v
    re, im = Polynomial.constant(1.0), Polynomial()
    for _ in range(m):
        re, im = re * u - im * v, re * v + im * u
    return re, im


def lobe_terms(
    m: int,
    amplitude: float,
    rate: float,
    profile: Polynomial | None = None,
    section: tuple[Polynomial, Polynomial] | None = None,
) -> list[tuple[Factor, ...]]:
    """``amplitude P(z) r^2 cos(m (phi - rate z))`` as two sum terms of one factor each (``P``
    the polynomial ``profile``, 1 when None). ``section``: the section's coordinates ``(u, v)``
    in place of ``(x, y)`` (``r^2 = u^2 + v^2``, ``phi`` the angle of ``(u, v)``), for a bent
    column."""
    if section is None:
        re, im = harmonic(m)
        divisor = PowerFunction((PowerTerm(1.0, 2.0), PowerTerm(1.0, 0.0, 2.0), PowerTerm(DELTA)))
    else:
        u, v = section
        re, im = harmonic(m, u, v)
        divisor = (u * u + v * v + Polynomial.constant(DELTA)).to_power_function(BENT_DIGITS)
    if profile is not None:
        re, im = re * profile, im * profile
    digits = 6 if section is None else BENT_DIGITS
    lam = (m - 2) / 2
    w = round_significant(m * rate, 4)
    out = []
    for poly, h in ((re, "cos"), (im, "sin")):
        arg = PowerFunction((PowerTerm(w, 0.0, 0.0, 1.0),))
        powers = (poly.scaled(amplitude).to_power_function(digits), divisor if lam else ONE, arg)
        out.append(
            (
                Factor(
                    powers=(*powers, *(ONE,) * 5),
                    lambdas=(1.0, lam, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0),
                    mus=(1.0, 0.0, 0.0, 0.0),
                    h=Transform(h),
                    g=Transform("asin"),
                ),
            )
        )
    return out


def draw_twist(seed: int, index: int, cfg: DrawSettings, s: TwistSettings) -> Draw:
    """The ``twist`` family (see the module docstring)."""
    rng = rng_for(seed, index)
    m = int(choose(rng, s.lobes, s.lobe_weights))
    eps = round(float(rng.uniform(*s.lobe_depth)), 2)
    turns = float(rng.uniform(*s.turns)) * (1 if rng.random() < 0.5 else -1)
    height = round(float(rng.uniform(*s.height)), 2)
    q = round(float(rng.uniform(*s.cap)), 1)
    beta = round(float(rng.uniform(*s.bulge)), 2)
    braid = bool(rng.random() < s.braid_prob)
    braid_eps = round(eps * float(rng.uniform(0.25, 0.5)), 2)
    axis = int(rng.integers(0, 3))
    margin = float(rng.uniform(*s.margin))
    flat = round(float(rng.uniform(*s.ellipse)), 2) if rng.random() < s.ellipse_prob else 1.0
    tau = _signed(rng, s.taper) if rng.random() < s.taper_prob else 0.0
    gamma = _signed(rng, s.swell) if rng.random() < s.swell_prob else 0.0
    if gamma:  # the deepest lobes stay under 0.8 (deeper, thin blades stack into plates)
        gamma = math.copysign(min(abs(gamma), math.floor((0.8 / eps - 1.0) * 100) / 100), gamma)
        gamma = gamma if abs(gamma) >= 0.1 else 0.0
    bend, bend_axis = 0.0, 0
    if rng.random() < s.bend_prob:
        bend, bend_axis = _signed(rng, s.bend), int(rng.integers(0, 2))
    shape = Shape(flat, tau, gamma, bend, bend_axis)
    # the column has radius 1 and half-height H: a first box for the cell, grown (and the
    # column built again for its cell) until it holds the column's measured extent
    # a bent column's ends lean aside: the box holds the section there, its lobes at their
    # deepest (a straight one's first box keeps the unswollen depth, as before the bend)
    deepest = eps * (1 + abs(gamma)) if bend else eps
    section = 1.0 / (math.sqrt(1.0 - deepest) * (1 - abs(tau)))
    half = round(max(height, abs(bend) * height + section) * (1 + margin), 2)
    for _ in range(4):
        cell = cfg.cell(half)
        column = _column(m, eps, turns, height, q, beta, braid, braid_eps, axis, shape, cell, cfg)
        terms, m_used, braided, alpha, cells = column
        tree = add_all([mul_all([f.to_tree() for f in t]) for t in terms])
        extent = envelope_extent(tree) or 2.5
        need = round(extent * (1 + margin), 2)
        if need <= half:
            break
        half = need
    structure: dict[str, Any] = {
        "lobes": m_used,
        "lobe_depth": eps,
        "turns": round(turns * alpha, 3),
        "height": height,
        "cap": q,
        "bulge": beta,
        "braid": braided,
        "axis": "xyz"[axis],
        "flat": flat,
        "taper": tau,
        "swell": gamma,
        "bend": bend,
        "cells_per_period": round(min(cells, 9999.0), 2),
        "extent": round(extent, 4),
    }
    if braided:
        structure["braid_depth"] = braid_eps
    if bend:  # the side the ends lean to: the section's x (or y), where z went to the axis
        structure["bend_toward"] = "xyz"[(bend_axis + axis + 1) % 3]
    return Draw(Equation13(tuple(terms), 0.0), Box.cube(half), None, "twist", structure, 0.0)


@dataclass(frozen=True)
class Shape:
    """The column's section and profile: its ellipse ratio ``flat``, taper ``tau``, the lobes'
    swell ``gamma`` and the axis's ``bend`` (its ends' lean over the half-height, towards the
    section's x or y: ``bend_axis`` 0 or 1) (0: none)."""

    flat: float = 1.0
    tau: float = 0.0
    gamma: float = 0.0
    bend: float = 0.0
    bend_axis: int = 0


def _signed(rng, bounds: tuple[float, float]) -> float:
    """A magnitude drawn in ``bounds``, rounded to 2 digits, with a drawn sign."""
    return round(float(rng.uniform(*bounds)), 2) * (1 if rng.random() < 0.5 else -1)


def _column(
    m: int,
    eps: float,
    turns: float,
    height: float,
    q: float,
    beta: float,
    braid: bool,
    braid_eps: float,
    axis: int,
    shape: Shape,
    cell: float,
    cfg: DrawSettings,
) -> tuple[list[tuple[Factor, ...]], int, bool, float, float]:
    """The column's sum terms for the run's ``cell``: (terms, lobes, braided, the twist's
    slow-down, cells per period). Lobes around the axis are fewer when ``2 pi R / m`` (R the
    valleys' radius at the column's narrow end, where the lobes are deepest) would span fewer
    than ``period_cells`` cells; the braid is left out then."""
    tau, gamma = shape.tau, shape.gamma
    valley = 1.0 / (math.sqrt(1.0 + eps * (1 + abs(gamma))) * (1 + abs(tau)))
    if cfg.period_cells > 0:
        m = max(2, min(m, int(2 * math.pi * valley / (cfg.period_cells * cell))))
    rate = round_significant(2 * math.pi * turns / (2 * height), 4)  # radians per unit of z
    # the lobes' profile along the axis: T(z) (1 + γ z/H)
    profile = None
    if tau or gamma:
        grow = Polynomial.linear((0.0, 0.0, round_significant(tau / height, 4)), 1.0).power(2)
        profile = grow * Polynomial.linear((0.0, 0.0, round_significant(gamma / height, 4)), 1.0)
    if shape.bend:
        body, section = _bent_body(height, q, beta, shape)
    else:
        body, section = _straight_body(height, q, beta, shape), None
    lobes = lobe_terms(m, eps, rate, profile, section)
    braid = braid and 2 * math.pi * valley / (2 * m) >= cfg.period_cells * cell
    braid = braid and not shape.bend  # 2m lobes of x - b z^2: cancellation (BENT_DIGITS)
    if braid:
        lobes += lobe_terms(2 * m, braid_eps, -rate, profile, section)
    box = Box.cube(1.0)  # the arguments are linear: any box measures them exactly
    lobes, alpha, cells = fit_terms(lobes, box, cell, cfg.period_cells, n=4)
    terms = [*body, *lobes]
    perm = tuple((k + axis + 1) % 3 for k in range(3))  # z goes to the drawn axis
    return [tuple(permute_factor(f, perm) for f in t) for t in terms], m, braid, alpha, cells


def _straight_body(height: float, q: float, beta: float, shape: Shape) -> list[tuple[Factor, ...]]:
    """The straight column's body: ``r^2 (1 + k z^2) + |z/H|^q - 1`` in ``|·|`` (``r^2`` with the
    section's ellipse, ``k = (β + τ^2)/H^2``) and, for a spire, its odd part ``2τ/H r^2 z`` (whole
    powers: its sign matters), the column's second sum term."""
    flat, tau = shape.flat, shape.tau
    body = PowerFunction(
        (
            PowerTerm(1.0, 2.0),
            PowerTerm(round_significant(flat**-2, 4), 0.0, 2.0),
            PowerTerm(round_significant((beta + tau**2) / height**2, 4), 2.0, 0.0, 2.0),
            PowerTerm(round_significant((beta + tau**2) / height**2 / flat**2, 4), 0.0, 2.0, 2.0),
            PowerTerm(round_significant(height**-q, 4), 0.0, 0.0, q),
            PowerTerm(-1.0),
        ),
        absolute=True,
    )
    terms = [(only_a(body),)]
    if tau:  # the spire's odd part: 2τ/H (x^2 + y^2/flat^2) z, whole powers (its sign matters)
        k = round_significant(2 * tau / height, 4)
        spire = PowerFunction(
            (
                PowerTerm(k, 2.0, 0.0, 1.0),
                PowerTerm(round_significant(k / flat**2, 4), 0.0, 2.0, 1.0),
            )
        )
        terms.append((only_a(spire),))
    return terms


def _bent_body(
    height: float, q: float, beta: float, shape: Shape
) -> tuple[list[tuple[Factor, ...]], tuple[Polynomial, Polynomial]]:
    """The bent column's body and its section's coordinates ``(u, v)``: ``(x - b z^2, y)`` (or
    ``(x, y - b z^2)``), ``b = bend / H``, so the axis is the parabola whose ends lean ``bend * H``
    to one side. The section's part, ``(u^2 + v^2/flat^2)(1 + k z^2 + 2τ z/H)``, is one
    polynomial (whole powers, no ``|·|``); the ends' ``|z/H|^q - 1`` the ``|·|`` term after it."""
    flat, tau = shape.flat, shape.tau
    lean = Polynomial({(0, 0, 2): -round_significant(shape.bend / height, 4)})
    u, v = (X + lean, Y) if shape.bend_axis == 0 else (X, Y + lean)
    k = round_significant((beta + tau**2) / height**2, 4)
    along = Polynomial(
        {(0, 0, 0): 1.0, (0, 0, 2): k, (0, 0, 1): round_significant(2 * tau / height, 4)}
    )
    section = (u * u + (v * v).scaled(round_significant(flat**-2, 4))) * along
    ends = PowerFunction(
        (PowerTerm(round_significant(height**-q, 4), 0.0, 0.0, q), PowerTerm(-1.0)),
        absolute=True,
    )
    return [(only_a(section.to_power_function(BENT_DIGITS)),), (only_a(ends),)], (u, v)


FAMILY = Family(
    "twist",
    draw_twist,
    "twisted columns: a capped column whose m lobes turn along its axis (optionally braided)",
    TwistSettings,
    mix_weight=0.06,
    one_body=True,
    outline=False,  # a screw's grooves show inside a convex outline
    aspect_limit=1.5,  # squashed further, a column is a lens, a sliver or a stack of plates
)
