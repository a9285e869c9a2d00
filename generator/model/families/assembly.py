"""The ``assembly`` family: 2-5 bodies placed by a symmetry group, joined or kept apart,
optionally carved by an ornament — compositions, all inside equation (13).

The bodies (:mod:`.bodies`: balls, rounded boxes, tori — polynomials, so power functions) sit
on the orbit of an **arrangement**: ``pair`` (two along x), ``row`` (three along x),
``triangle`` (three in the plane x+y+z = 0, the cyclic permutations of one point), ``tetra``
(the four vertices of a tetrahedron), ``square`` (four in the xy plane), optionally one more at
the centre; or a ``chain`` of 2-4 linked tori (every other one smaller, or not). They are put together by a **join**:

- ``blend``: the field ``t - Σ w / (ρ_i + ε)`` of the bodies' shape functions ``ρ_i`` (one
  factor ``A/D`` each, A the constant ``-w``, D the body's ``ρ_i + ε``): near bodies merge
  smoothly, far ones stay apart (t sets how far they reach);
- ``product``: ``Π B_i`` (one sum term of one factor per body): the union of bodies that do not
  overlap (linked tori, separate rings), kept apart: a product hollows an overlap into webs
  and debris, so the rings' tube is thinned until any two are apart (under 0.3 of their
  closest approach each: the gap between them is at least 0.4 of it), and rings that would
  cross (or nearly: a tube under 0.15 of the ring radius) are linked into a chain instead
  (since sampler 12; they were balls, ornamented: lumps);
- ``boolean``: two bodies by min/max through ``|·|`` (:func:`~.bodies.union`,
  :func:`~.bodies.intersection`, :func:`~.bodies.difference`): a ring through a ball, a box
  with a ball cut out, ...

Balls and boxes (plain lumps, bare) are carved by a pole-free ornament of the sculpture family
summed over the arrangement's group, as it carves an envelope (:mod:`.sculpture`); rings are
left bare (an ornament on a product of rings throws the surface out to the box).
Its keys: the ``[sampler.assembly]`` table (:class:`AssemblySettings`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from surfgen.generator.eval.grid import Box
from surfgen.generator.formula.expr import Expr, add_all, mul_all
from surfgen.generator.model.draw import (
    Draw,
    DrawSettings,
    Family,
    choose,
    constant,
    rng_for,
    round_significant,
)
from surfgen.generator.model.equation13 import Equation13, Factor, PowerFunction, PowerTerm
from surfgen.generator.model.families import sculpture
from surfgen.generator.model.families.bodies import (
    Polynomial,
    ball,
    body_factor,
    difference,
    intersection,
    torus,
    union,
)
from surfgen.generator.model.families.symmetry import GROUP_PERMUTATIONS
from surfgen.generator.model.settings import (
    require_fractions,
    require_low_high,
    require_names,
    require_numbers,
    require_range,
    require_weighted_pairs,
)

SIZE = 0.5  # a body's radius (a torus's ring radius)
APART = 0.3  # a product's rings: tube radius at most this share of their closest approach
MIN_TUBE = 0.15  # ... and not thinner than this share of the ring radius (else a chain)
ARRANGEMENTS = ("pair", "row", "triangle", "tetra", "square", "chain")
BODIES = ("ball", "box", "torus")
JOINS = ("blend", "product", "boolean")
TABLE = "sampler.assembly"
_S6 = 1.0 / (3.0 * math.sqrt(2.0))
_UNIT_ORBITS: dict[str, tuple[tuple[float, float, float], ...]] = {
    # centres at unit spacing (nearest centres 1 apart)
    "pair": ((-0.5, 0.0, 0.0), (0.5, 0.0, 0.0)),
    "row": ((-1.0, 0.0, 0.0), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0)),
    "triangle": tuple(
        (2 * _S6 * a, 2 * _S6 * b, 2 * _S6 * c)
        for a, b, c in ((1.0, -0.5, -0.5), (-0.5, 1.0, -0.5), (-0.5, -0.5, 1.0))
    ),
    "tetra": tuple(
        (s[0] / (2 * math.sqrt(2)), s[1] / (2 * math.sqrt(2)), s[2] / (2 * math.sqrt(2)))
        for s in ((1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1))
    ),
    "square": ((0.5, 0.5, 0.0), (-0.5, 0.5, 0.0), (-0.5, -0.5, 0.0), (0.5, -0.5, 0.0)),
}
# The ornament's group for each arrangement: its permutations and whether it mirrors.
_GROUPS = {
    "pair": "mirror",
    "row": "mirror",
    "triangle": "cyclic",
    "tetra": "cyclic",
    "square": "mirror",
    "chain": "none",
}


@dataclass(frozen=True)
class AssemblySettings:
    """The ``[sampler.assembly]`` table (``surfgen config show``)."""

    arrangements: tuple[str, ...] = ARRANGEMENTS
    arrangement_weights: tuple[float, ...] = (0.175, 0.175, 0.225, 0.225, 0.1, 0.1)
    bodies: tuple[str, ...] = BODIES
    body_weights: tuple[float, ...] = (0.1, 0.1, 0.8)
    joins: tuple[str, ...] = JOINS
    join_weights: tuple[float, ...] = (0.25, 0.45, 0.3)
    spacing: tuple[float, float] = (1.3, 2.2)  # centre distance / body radius
    reach: tuple[float, float] = (0.45, 0.85)  # blend: t = reach / (1 + ε); lower reaches farther
    centre_prob: float = 0.35  # one more body at the centre (triangle, tetra, square)
    depth: tuple[float, float] = (0.2, 0.4)  # the ornament's carving depth / body size
    margin: tuple[float, float] = (0.1, 0.25)  # box half = extent * (1 + depth + margin)
    tube: tuple[float, float] = (0.22, 0.42)  # a torus's tube radius / ring radius
    stretch_prob: float = 0.5  # the whole assembly stretched along the axes by 0.75-1.3 each
    chain_links: tuple[int, ...] = (2, 3, 4)  # rings of a chain
    chain_weights: tuple[float, ...] = (0.2, 0.45, 0.35)
    alternate_prob: float = 0.5  # every other ring of a chain smaller

    def __post_init__(self) -> None:
        require_names(self, "arrangements", ARRANGEMENTS, TABLE)
        require_names(self, "bodies", BODIES, TABLE)
        require_names(self, "joins", JOINS, TABLE)
        weights = ("arrangement_weights", "body_weights", "join_weights", "chain_weights")
        require_numbers(self, weights, TABLE)
        require_weighted_pairs(
            self,
            (
                ("arrangements", "arrangement_weights"),
                ("bodies", "body_weights"),
                ("joins", "join_weights"),
                ("chain_links", "chain_weights"),
            ),
            TABLE,
        )
        probabilities = ("centre_prob", "stretch_prob", "alternate_prob")
        require_fractions(self, probabilities, TABLE, "a probability")
        require_low_high(self, ("spacing", "reach", "depth", "margin", "tube"), TABLE)
        require_range(self, "tube", 0.05, 0.9, TABLE)
        require_range(self, "spacing", 0.5, 5.0, TABLE)
        require_range(self, "reach", 0.05, 0.99, TABLE)
        require_range(self, "depth", 0.0, 1.0, TABLE)
        require_range(self, "margin", 0.0, 2.0, TABLE)
        require_range(self, "chain_links", 2, 8, TABLE)


def _body(kind: str, centre, size: float, axis, p: int, tube: float = 0.32) -> Polynomial:
    if kind == "torus":
        return torus(centre, axis, size, round(size * tube, 3))
    return ball(centre, (size,) * 3, 2 if kind == "ball" else p)


def _shape_function(kind: str, centre, size: float, p: int) -> Polynomial:
    """``ρ = Σ ((x_k - c_k)/r)^p`` (>= 0, 1 on the body's surface), for the blend."""
    return ball(centre, (size,) * 3, 2 if kind == "ball" else p) + Polynomial.constant(1.0)


def draw_assembly(seed: int, index: int, cfg: DrawSettings, s: AssemblySettings) -> Draw:
    """The ``assembly`` family (see the module docstring)."""
    rng = rng_for(seed, index)
    arrangement = str(choose(rng, s.arrangements, s.arrangement_weights))
    kind = str(choose(rng, s.bodies, s.body_weights))
    join = str(choose(rng, s.joins, s.join_weights))
    spacing = round(float(rng.uniform(*s.spacing)), 2)
    p = 4 if rng.random() < 0.5 else 6  # a rounded box's exponent
    axis = [0.0, 0.0, 0.0]
    axis[int(rng.integers(0, 3))] = 1.0
    centre_body = bool(rng.random() < s.centre_prob)
    reach = float(rng.uniform(*s.reach))
    depth = round(float(rng.uniform(*s.depth)), 2)
    margin = float(rng.uniform(*s.margin))
    tube = round(float(rng.uniform(*s.tube)), 2)
    tilt = round(float(rng.uniform(0.0, 1.2)), 2)
    stretch = (1.0, 1.0, 1.0)
    if rng.random() < s.stretch_prob:
        stretch = tuple(round(float(rng.uniform(0.75, 1.3)), 2) for _ in range(3))
    if kind == "torus" and arrangement != "chain" and join != "boolean":
        # rings joined by a product must not touch (the product hollows their overlap into
        # webs and debris): the tube is thinned to keep them apart; rings that would cross
        # are linked into a chain instead (balls there were lumps more often than not, rings
        # spread apart three of a kind)
        apart = _rings_apart(arrangement, spacing, axis, tilt, tube)
        if apart is None:
            arrangement = "chain"
        else:
            tube = apart
    if arrangement == "chain":
        kind, join = "torus", "product"
    # bare balls and boxes, blended or apart, are plain lumps: they are carved; rings (chains
    # too) are not (an ornament on a product of rings throws the surface out to the box)
    ornamented = kind != "torus"
    if join == "blend" and kind == "torus":
        join = "product"  # a torus has no positive shape function to blend
    if join == "boolean":
        arrangement = "pair"
    info: dict[str, Any] = {
        "arrangement": arrangement,
        "body": kind,
        "join": join,
        "spacing": spacing,
    }
    size = SIZE
    t = 0.0  # the blend's level
    if arrangement == "chain":
        terms, bodies_tree, chain = _chain(rng, size, s)
        info.update(chain)
    elif join == "boolean":
        terms, bodies_tree, op = _boolean(rng, kind, size, spacing, p, axis)
        info.update(bodies=2, operation=op)
    else:
        centres = _orbit(arrangement, spacing, size)
        if centre_body and arrangement in ("triangle", "tetra", "square") and kind != "torus":
            centres.append((0.0, 0.0, 0.0))
        axes = _axes(arrangement, centres, axis, kind, tilt)
        if kind == "torus" and arrangement in ("triangle", "tetra"):
            info["tilt"] = tilt
        if join == "blend" or kind != "torus" and (spacing < 2.05 or not ornamented):
            # balls overlapping (their product would hollow the overlap) or apart and plain
            # (convex lumps): blended
            join = info["join"] = "blend"
            terms, bodies_tree, t = _blend(kind, centres, size, p, reach)
            info["reach"] = round(reach, 3)
        else:
            factors = [
                body_factor(_body(kind, c, size, a, p, tube))
                for c, a in zip(centres, axes, strict=True)
            ]
            terms = [tuple(factors)]
            bodies_tree = mul_all([f.to_tree() for f in factors])
        info["bodies"] = len(centres)
    if stretch != (1.0, 1.0, 1.0):  # the whole assembly stretched along the axes
        terms = [tuple(_stretched(f, stretch) for f in t) for t in terms]
        bodies_tree = add_all([mul_all([f.to_tree() for f in t]) for t in terms])
        if join == "blend":
            bodies_tree = add_all([bodies_tree, constant(t).to_tree()])
        info["stretch"] = list(stretch)
    if kind == "torus" and arrangement != "chain":
        info["tube"] = tube
    if kind == "box":
        info["exponent"] = p
    group = _GROUPS[arrangement] if kind != "torus" or arrangement in ("pair", "row") else "none"
    if stretch != (1.0, 1.0, 1.0):
        group = "mirror" if _GROUPS[arrangement] == "mirror" else "none"
    info["group"] = group
    extent = sculpture.envelope_extent(bodies_tree)
    if extent is None:
        extent = 2.5
    half = round(extent * (1 + depth * ornamented + margin), 2)
    d = -t if join == "blend" else 0.0
    if ornamented:
        s_sc = _sculpture_settings(cfg)
        perms = GROUP_PERMUTATIONS[group]
        ornament, freq, products, checks, strength_d, tries = sculpture.coarse_ornament(
            rng,
            cfg,
            s_sc,
            bodies_tree,
            Box.cube(half),
            perms,
            group.endswith("mirror"),
            1,
            depth * size,
        )
        strength, od = strength_d
        if od is not None and checks is not None:
            for coef, prod in products:
                c = round_significant(strength * coef, 3) or 1.0
                terms.append((constant(c), *prod))
            d = round_significant(d + od, 6)
            info["ornament"] = {
                "factor": Equation13(((ornament,),)).to_dict()["terms"][0][0],
                "frequency": freq,
                "depth": depth,
                "strength": strength,
                "tries": tries,
            }
            info["ornament"]["cells_per_period"] = round(min(checks[4], 9999.0), 2)
    info["extent"] = round(extent, 4)
    envelope = bodies_tree if "ornament" in info else None
    return Draw(Equation13(tuple(terms), 0.0), Box.cube(half), None, "assembly", info, d, envelope)


def _stretched(f: Factor, k: tuple[float, float, float]) -> Factor:
    """The factor with x, y, z replaced by x/kx, y/ky, z/kz (each power term's coefficient
    divided by the stretches to its exponents)."""

    def pf(p: PowerFunction) -> PowerFunction:
        terms = tuple(
            PowerTerm(
                round_significant(t.a / (k[0] ** t.b * k[1] ** t.c * k[2] ** t.d), 6), t.b, t.c, t.d
            )
            for t in p.terms
        )
        return PowerFunction(terms, p.absolute)

    return replace(f, powers=tuple(pf(p) for p in f.powers))


def _sculpture_settings(cfg: DrawSettings) -> sculpture.SculptureSettings:
    """The sculpture family's settings of this config (or the defaults) for the ornaments,
    always pole-free: a pole between two bodies throws sheets across the gap."""
    settings = getattr(cfg, "settings", None)
    found = settings("sculpture") if callable(settings) else None
    found = found if found is not None else sculpture.SculptureSettings()
    return replace(found, pole_free_prob=1.0, bounded_prob=1.0)


def _axes(arrangement: str, centres, axis, kind: str, tilt: float) -> list:
    """Each body's axis (a torus's): on the triangle and the tetrahedron, the radial direction
    turned by ``tilt`` towards the diagonal (1, 1, 1), which the cyclic permutations keep (so
    the group maps ring to ring); else the drawn one."""
    if kind != "torus" or arrangement not in ("triangle", "tetra"):
        return [axis] * len(centres)
    out = []
    for c in centres:
        norm = math.sqrt(sum(v * v for v in c)) or 1.0
        out.append(
            [round(math.cos(tilt) * v / norm + math.sin(tilt) / math.sqrt(3.0), 4) for v in c]
        )
    return out


def _blend(kind: str, centres, size: float, p: int, reach: float) -> tuple[list, Expr, float]:
    """``Σ -1 / (ρ_i + ε)`` (one factor A/D per body) and t: the blend's terms, its tree and t."""
    eps = 0.1
    terms = []
    for c in centres:
        rho = _shape_function(kind, c, size, p) + Polynomial.constant(eps)
        one = body_factor(Polynomial.constant(-1.0))
        powers = (one.powers[0], rho.to_power_function(), *one.powers[2:])
        terms.append((replace(one, powers=powers, lambdas=(1.0, 1.0, *one.lambdas[2:])),))
    t = round_significant(reach / (1 + eps), 4)
    tree = add_all([f.to_tree() for (f,) in terms])
    return terms, add_all([tree, constant(t).to_tree()]), t


def _chain(
    rng: np.random.Generator, size: float, s: AssemblySettings
) -> tuple[list, Expr, dict[str, Any]]:
    """A chain of linked tori along x, each turned a quarter turn (plus a drawn twist) about
    x from the one before; with ``alternate_prob`` every other ring smaller (a drawn ratio). Two
    rings: their centres a drawn share (0.8-1.2) of their mean radius apart; more: near the
    share (1-1.7) that leaves the most room between any two rings. The tube is kept under :data:`APART` of
    the closest approach of any two rings (links never touch: a gap of cells between them at
    the sampler's grid)."""
    n = int(choose(rng, s.chain_links, s.chain_weights))
    gap = float(rng.uniform(0.8, 1.2))
    twist = round(float(rng.uniform(-0.8, 0.8)), 2)
    tube = size * float(rng.uniform(0.2, 0.32))
    ratio = round(float(rng.uniform(0.75, 0.9)), 2) if rng.random() < s.alternate_prob else 1.0
    radii = [size * (ratio if i % 2 else 1.0) for i in range(n)]
    axes = [
        (
            0.0,
            round(math.sin(i * (math.pi / 2 + twist)), 4),
            round(math.cos(i * (math.pi / 2 + twist)), 4),
        )
        for i in range(n)
    ]

    def layout(gap: float) -> tuple[list[tuple[float, float, float]], float]:
        steps = [round(gap * (radii[i] + radii[i + 1]) / 2, 3) for i in range(n - 1)]
        xs = np.concatenate([[0.0], np.cumsum(steps)])
        centres = [(round(float(x - xs[-1] / 2), 4), 0.0, 0.0) for x in xs]
        closest = min(
            _ring_gap(centres[i], axes[i], centres[j], axes[j], radii[i], radii[j])
            for i in range(n)
            for j in range(i + 1, n)
        )
        return centres, closest

    if n > 2:  # every ring crosses the chain's axis: rings two apart clear each other only
        # from 1 mean radius on, links thin out towards 2; near the gap with the most room
        # between any two rings (the drawn share of 0.8-1.2 moves it by -4 to +8 %)
        best = max(np.linspace(1.0, 1.7, 15), key=lambda g: layout(float(g))[1])
        gap = min(1.7, float(best) * (1.0 + 0.3 * (gap - 1.0) + 0.02))
    centres, closest = layout(float(gap))
    tube = round(min(tube, APART * closest), 3)
    factors = [
        body_factor(torus(c, a, round(r, 4), tube))
        for c, a, r in zip(centres, axes, radii, strict=True)
    ]
    info = {"bodies": n, "gap": round(gap, 3), "twist": twist, "tube": round(tube / size, 3)}
    if ratio != 1.0:
        info["ratio"] = ratio
    return [tuple(factors)], mul_all([f.to_tree() for f in factors]), info


def _orbit(arrangement: str, spacing: float, size: float) -> list[tuple[float, ...]]:
    """The bodies' centres: the arrangement's unit orbit scaled to ``spacing`` body radii."""
    return [tuple(size * spacing * c for c in pt) for pt in _UNIT_ORBITS[arrangement]]


def _rings_apart(
    arrangement: str, spacing: float, axis, tilt: float, tube: float, size: float = SIZE
) -> float | None:
    """The tube (share of the ring radius ``size``) at most ``tube`` with which the rings of
    ``arrangement`` stay apart: under :data:`APART` of the closest approach of any two rings
    (so two tubes fill at most 0.6 of it: a gap of cells at the sampler's grid); None when that leaves less than :data:`MIN_TUBE`
    (the rings cross or nearly do)."""
    centres = _orbit(arrangement, spacing, size)
    axes = _axes(arrangement, centres, axis, "torus", tilt)
    closest = min(
        _ring_gap(centres[i], axes[i], centres[j], axes[j], size)
        for i in range(len(centres))
        for j in range(i + 1, len(centres))
    )
    room = APART * closest / size
    return None if room < MIN_TUBE else round(min(tube, room), 2)


def _ring_gap(
    c1, a1, c2, a2, radius: float, radius2: float | None = None, samples: int = 96
) -> float:
    """The closest approach of two circles of ``radius`` (the second of ``radius2`` if given;
    centres c, unit axes a), sampled: the smallest distance between ``samples`` points of each
    (the squared distances summed x, y, z in that order, the root of the smallest taken)."""
    r2 = radius if radius2 is None else radius2
    p = np.asarray(c1) + _circle_offsets(tuple(map(float, a1)), float(radius), samples)
    q = np.asarray(c2) + _circle_offsets(tuple(map(float, a2)), float(r2), samples)
    dx, dy, dz = (p[:, k, None] - q[None, :, k] for k in range(3))
    return float(np.sqrt((dx * dx + dy * dy + dz * dz).min()))


@functools.lru_cache(maxsize=512)
def _circle_offsets(axis: tuple[float, ...], radius: float, samples: int) -> np.ndarray:
    """``(samples, 3)``: points of the circle of ``radius`` about the origin, square to
    ``axis`` (a chain's layouts move its rings, not their axes and radii: computed once)."""
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    u = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(a, u)
    t = np.linspace(0, 2 * np.pi, samples, endpoint=False)[:, None]
    out = radius * (np.cos(t) * u + np.sin(t) * v)
    out.flags.writeable = False
    return out


def _boolean(
    rng: np.random.Generator, kind: str, size: float, spacing: float, p: int, axis
) -> tuple[list, Expr, str]:
    """Two bodies, the second smaller and off-centre (on the ring of a torus), as their union,
    intersection or difference (intersections of two convex bodies are convex: those become
    differences)."""
    second = str(rng.choice(BODIES))
    op = str(rng.choice(("union", "intersection", "difference")))
    if op == "intersection" and "torus" not in (kind, second):
        op = "difference"
    r2 = size * float(rng.uniform(0.55, 0.95))
    offset = size * float(rng.uniform(0.3, 1.1))
    direction = [0.0, 0.0, 0.0]
    pick = int(rng.integers(0, 3))
    axis2 = [0.0, 0.0, 0.0]
    axis2[int(rng.integers(0, 3))] = 1.0
    if kind == "torus":  # the second body on the ring (in its hole it would cut nothing)
        pick = (axis.index(1.0) + 1 + pick % 2) % 3
        offset = size * 1.2 * (0.8 + 0.4 * offset / (1.1 * size))
    direction[pick] = 1.0
    a = _body(kind, (0.0, 0.0, 0.0), size * 1.2, axis, p)
    b = _body(second, tuple(offset * v for v in direction), r2, axis2, p)
    terms = {"union": union, "intersection": intersection, "difference": difference}[op](a, b)
    tree = add_all([mul_all([f.to_tree() for f in t]) for t in terms])
    return terms, tree, f"{kind} {op} {second}"


FAMILY = Family(
    "assembly",
    draw_assembly,
    "2-5 bodies placed by a symmetry group, blended, kept apart or combined by min/max",
    AssemblySettings,
    mix_weight=0.13,
)
