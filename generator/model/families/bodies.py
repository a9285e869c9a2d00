"""Bodies as power functions, and min/max through ``|u|``: the building blocks of the
``infill`` and ``assembly`` families.

A power function (eq. 8) has no shift: ``a x^b y^c z^d``. A body away from the origin is a
polynomial in ``x - c``: whole exponents expand (``(x - c)^2 = x^2 - 2 c x + c^2``), so balls,
rounded boxes (exponent 4) and tori anywhere, along any axis, are power functions
(:class:`Polynomial` expands them).

``|u|`` gives min and max: ``max(a, b) = (a + b + |a - b|)/2`` and
``min(a, b) = (a + b - |a - b|)/2``. When a and b are power functions, ``a - b`` is one, so
both are sums of eq. (13) terms (:func:`union`, :func:`intersection`, :func:`difference`);
``max(a, 0) = (a + |a|)/2`` needs only a (:func:`positive_part`), which clips any field to a
body: ``L + c max(E, 0)`` is L inside the body ``E < 0`` and grows fast outside it.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

from surfgen.generator.model.draw import constant, only_a, round_significant
from surfgen.generator.model.equation13 import Factor, PowerFunction, PowerTerm

Monomial = tuple[int, int, int]


@dataclass
class Polynomial:
    """A polynomial in x, y, z: ``{(i, j, k): coefficient}`` of ``x^i y^j z^k``."""

    coefficients: dict[Monomial, float] = field(default_factory=dict)

    @classmethod
    def constant(cls, value: float) -> Polynomial:
        return cls({(0, 0, 0): float(value)})

    @classmethod
    def linear(cls, weights: Sequence[float], offset: float = 0.0) -> Polynomial:
        """``w . (x, y, z) + offset``."""
        out = {(0, 0, 0): float(offset)}
        for axis, w in enumerate(weights):
            if w:
                out[tuple(1 if j == axis else 0 for j in range(3))] = float(w)  # type: ignore[index]
        return cls(out)

    def __add__(self, other: Polynomial) -> Polynomial:
        out: dict[Monomial, float] = defaultdict(float, self.coefficients)
        for m, c in other.coefficients.items():
            out[m] += c
        return Polynomial(dict(out))

    def __sub__(self, other: Polynomial) -> Polynomial:
        return self + other.scaled(-1.0)

    def __mul__(self, other: Polynomial) -> Polynomial:
        out: dict[Monomial, float] = defaultdict(float)
        for (a, b, c), u in self.coefficients.items():
            for (d, e, f), v in other.coefficients.items():
                out[(a + d, b + e, c + f)] += u * v
        return Polynomial(dict(out))

    def scaled(self, k: float) -> Polynomial:
        return Polynomial({m: c * k for m, c in self.coefficients.items()})

    def power(self, n: int) -> Polynomial:
        out = Polynomial.constant(1.0)
        for _ in range(n):
            out = out * self
        return out

    def to_power_function(self, digits: int = 6) -> PowerFunction:
        """The power function (terms in a fixed order: by degree, then exponents; coefficients
        to ``digits`` significant digits, zeros left out)."""
        terms = [
            PowerTerm(round_significant(c, digits), *map(float, m))
            for m, c in sorted(self.coefficients.items(), key=lambda mc: (-sum(mc[0]), mc[0]))
            if round_significant(c, digits) != 0
        ]
        return PowerFunction(tuple(terms) or (PowerTerm(0.0),))


def ball(centre: Sequence[float], radii: Sequence[float], p: int = 2) -> Polynomial:
    """``Σ ((x_k - c_k) / r_k)^p - 1`` (p even): an ellipsoid (2) or a rounded box (4, 6)."""
    if p % 2:
        raise ValueError(f"a ball's exponent must be even, got {p}")
    out = Polynomial.constant(-1.0)
    for axis in range(3):
        w = [0.0, 0.0, 0.0]
        w[axis] = 1.0 / radii[axis]
        out = out + Polynomial.linear(w, -centre[axis] / radii[axis]).power(p)
    return out


def torus(centre: Sequence[float], axis: Sequence[float], ring: float, tube: float) -> Polynomial:
    """``((|x-c|^2 + R^2 - a^2)^2 - 4 R^2 (|x-c|^2 - ((x-c).n)^2)) / (4 R^2 a^2)``: a torus of
    ring radius R and tube radius a around the unit axis n through c (negative inside)."""
    norm = math.sqrt(sum(v * v for v in axis))
    n = [v / norm for v in axis]
    shifted = [
        Polynomial.linear([1.0 if j == k else 0.0 for j in range(3)], -centre[k]) for k in range(3)
    ]
    square = shifted[0].power(2) + shifted[1].power(2) + shifted[2].power(2)
    along = Polynomial.constant(0.0)
    for k in range(3):
        along = along + shifted[k].scaled(n[k])
    inner = square + Polynomial.constant(ring**2 - tube**2)
    planar = square - along.power(2)
    out = inner.power(2) - planar.scaled(4 * ring**2)
    return out.scaled(1.0 / (4 * ring**2 * tube**2))


def body_factor(p: Polynomial, absolute: bool = False) -> Factor:
    """The body as one factor (its A), in ``|.|`` with ``absolute``."""
    f = only_a(p.to_power_function())
    return replace(f, absolute=(True,) + (False,) * 5) if absolute else f


def _scaled_term(k: float, factors: tuple[Factor, ...]) -> tuple[Factor, ...]:
    return (constant(round_significant(k, 6)), *factors)


def positive_part(body: Sequence[Factor], k: float) -> list[tuple[Factor, ...]]:
    """``k max(B, 0) = k (B + |B|) / 2`` for a body B that is one product of factors (each A
    alone): two sum terms (``|B| = Π |factor|``)."""
    absolute = tuple(replace(f, absolute=(True,) + (False,) * 5) for f in body)
    return [_scaled_term(k / 2, tuple(body)), _scaled_term(k / 2, absolute)]


def union(a: Polynomial, b: Polynomial) -> list[tuple[Factor, ...]]:
    """``min(a, b) = (a + b - |a - b|) / 2``: inside either body."""
    return _combine(a, b, -1.0, 1.0)


def intersection(a: Polynomial, b: Polynomial) -> list[tuple[Factor, ...]]:
    """``max(a, b) = (a + b + |a - b|) / 2``: inside both bodies."""
    return _combine(a, b, 1.0, 1.0)


def difference(a: Polynomial, b: Polynomial) -> list[tuple[Factor, ...]]:
    """``max(a, -b) = (a - b + |a + b|) / 2``: inside a, outside b."""
    return _combine(a, b, 1.0, -1.0)


def power_max(a: PowerFunction, b: PowerFunction) -> list[tuple[Factor, ...]]:
    """``max(a, b) = (a + b + |a - b|) / 2`` of two power functions of one kind (both in
    ``|x|, |y|, |z|`` or neither): the intersection of their bodies, as three sum terms."""
    if a.absolute != b.absolute:
        raise ValueError("both power functions must use |x|, |y|, |z| or neither")
    neg = tuple(PowerTerm(-t.a, t.b, t.c, t.d) for t in b.terms)
    diff = PowerFunction((*a.terms, *neg), a.absolute)
    return [
        _scaled_term(0.5, (only_a(a),)),
        _scaled_term(0.5, (only_a(b),)),
        _scaled_term(0.5, (replace(only_a(diff), absolute=(True,) + (False,) * 5),)),
    ]


def _combine(a: Polynomial, b: Polynomial, sign: float, b_sign: float) -> list[tuple[Factor, ...]]:
    """``(a + s_b b + sign |a - s_b b|) / 2`` as three sum terms."""
    b = b.scaled(b_sign)
    return [
        _scaled_term(0.5, (body_factor(a),)),
        _scaled_term(0.5, (body_factor(b),)),
        _scaled_term(0.5 * sign, (body_factor(a - b, absolute=True),)),
    ]
