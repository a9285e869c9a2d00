"""Sums holding ``U cos θ + V sin θ`` bounded with the pair as one wave.

A twist's lobes turn along its axis: ``P₁/D · cos(ω z) + P₂/D · sin(ω z)``, the two halves of
``R cos(ω z − ψ)``. Bounded apart, each term is as wide as its factor's range times its cosine's
or sine's over the block, and the two widths add although the waves they come from are a quarter
turn apart: where one term is at its widest the other is at its narrowest. Twist-0 at 512^3
sampled 20 554 leaves to keep 4 322, a third of the others six leaves or more from the surface,
outside the column, where the pair's bound still reached the level.

:func:`sum_terms` reads a sum (a chain of ``+`` and ``-``) as its signed terms and pairs a term
``U·cos θ`` with a term ``V·sin θ`` of the same ``θ`` (equal sub-trees); :func:`sum_bounds`
bounds such a sum over boxes from its terms' bounds:

- a pair over ``u ∈ [u], v ∈ [v], θ ∈ [θ]`` by its exact range there: for a given θ the pair is
  linear in ``(u, v)``, so its extremes are at a corner of ``[u] × [v]``, where it is
  ``R cos(θ − ψ)`` with ``R = hypot(u, v)``, ``ψ = atan2(v, u)``: the corners' ranges over
  ``[θ]`` (the angle interval widened by :data:`ANGLE_ROOM`, the result by ``R·`` that much, for
  this module's own roundings), joined;
- the evaluator's roundings by ``2 γ_{n+4} Σ|t|`` (``n`` terms, ``Σ|t|`` the terms' largest
  magnitudes, a pair's ``max|u| + max|v|``): its cosine and sine within 0.77 units in the last
  place and the products' rounding (two units each), then the sum's ``n − 1`` additions in
  whatever order it makes them, and this function's own sums of the ends (Higham 2002, §3.1);
  the result one place outward.

:mod:`~surfgen.generator.eval.interval_poly` uses these for the sums of its structures: the
twists' lobes have polynomial factors.
"""

from __future__ import annotations

import math
from collections.abc import Collection

import numpy as np

from surfgen.generator.formula.expr import Expr

#: Terms in a sum at most (a longer one is bounded term by term: the pairing is quadratic).
MAX_TERMS = 64
#: The angle interval widened by this times ``1 + |θ|`` and the pair's range by ``R`` times it:
#: far beyond this module's roundings (a few units of 2^-53 of those magnitudes).
ANGLE_ROOM = 1e-12
_UNIT = 2.0**-53
_TWO_PI = 2.0 * math.pi
_SIGNS = {"+": 1, "-": -1}


def in_chains(nodes: list[Expr]) -> set[int]:
    """The ids of the nodes that are a term of a larger sum (a ``+`` or ``-`` below another):
    only the whole sum is read as one."""
    return {id(a) for node in nodes if node.op in _SIGNS for a in node.args if a.op in _SIGNS}


def sum_terms(node: Expr, whole: Collection[int] = ()) -> tuple[tuple, list[Expr]] | None:
    """A sum's terms with its pairs (the module's docstring), or None where it has no pair
    (or more than :data:`MAX_TERMS` terms): ``(spec, kids)``, ``spec`` one entry per term in
    order, ``("one", sign)`` reading one kid (the term) or ``("pair", sign_cos, sign_sin)``
    reading three (``U``, ``V``, ``θ``). A sum whose id is in ``whole`` is one term (a
    polynomial bounded as one)."""
    terms = _flattened(node, whole)
    if terms is None:
        return None
    waves = [_wave(t) for _, t in terms]
    partner: dict[int, int] = {}
    for i, wi in enumerate(waves):
        if wi is None or wi[0] != "cos" or i in partner:
            continue
        for j, wj in enumerate(waves):
            if wj is not None and wj[0] == "sin" and j not in partner and wj[2] == wi[2]:
                partner[i], partner[j] = j, i
                break
    if not partner:
        return None
    spec: list[tuple] = []
    kids: list[Expr] = []
    for i, (sign, term) in enumerate(terms):
        if i not in partner:
            spec.append(("one", sign))
            kids.append(term)
        elif waves[i][0] == "cos":
            j = partner[i]
            spec.append(("pair", sign, terms[j][0]))
            kids.extend([waves[i][1], waves[j][1], waves[i][2]])
    return tuple(spec), kids


def _flattened(node: Expr, whole: Collection[int]) -> list[tuple[int, Expr]] | None:
    """The signed terms of the chain of ``+`` and ``-`` rooted at ``node`` (a sum in ``whole``
    one term), in the evaluator's order; None beyond :data:`MAX_TERMS`."""
    out: list[tuple[int, Expr]] = []
    stack = [(1, node)]
    while stack:
        sign, n = stack.pop()
        if n.op in _SIGNS and (n is node or id(n) not in whole):
            a, b = n.args
            stack.append((sign * _SIGNS[n.op], b))
            stack.append((sign, a))
        else:
            out.append((sign, n))
            if len(out) > MAX_TERMS:
                return None
    return out


def _wave(term: Expr) -> tuple[str, Expr, Expr] | None:
    """``(kind, U, θ)`` for a term ``U · cos θ`` or ``U · sin θ`` (either factor first)."""
    if term.op != "*":
        return None
    for trig, other in ((term.args[1], term.args[0]), (term.args[0], term.args[1])):
        if trig.op in ("cos", "sin"):
            return trig.op, other, trig.args[0]
    return None


def sum_bounds(spec: tuple, vals: list[tuple[np.ndarray, np.ndarray]]):
    """Bounds of the sum ``spec`` (:func:`sum_terms`) over boxes from its kids' bounds
    ``vals`` (in the order of the kids)."""
    lo = hi = mag = 0.0
    k = 0
    for entry in spec:
        if entry[0] == "one":
            (a0, a1), k = vals[k], k + 1
            if entry[1] < 0:
                a0, a1 = -a1, -a0
            lo, hi = lo + a0, hi + a1
            mag = mag + np.maximum(np.abs(a0), np.abs(a1))
        else:
            (u0, u1), (v0, v1), theta = vals[k], vals[k + 1], vals[k + 2]
            k += 3
            if entry[1] < 0:
                u0, u1 = -u1, -u0
            if entry[2] < 0:
                v0, v1 = -v1, -v0
            p0, p1 = pair_range((u0, u1), (v0, v1), theta)
            lo, hi = lo + p0, hi + p1
            mag = mag + np.maximum(np.abs(u0), np.abs(u1)) + np.maximum(np.abs(v0), np.abs(v1))
    n = len(spec) + sum(1 for entry in spec if entry[0] == "pair") + 4
    room = 2.0 * _gamma(n) * mag
    return np.nextafter(lo - room, -np.inf), np.nextafter(hi + room, np.inf)


def _gamma(n: int) -> float:
    return n * _UNIT / (1 - n * _UNIT)


def pair_range(u, v, theta) -> tuple[np.ndarray, np.ndarray]:
    """The range of ``u cos θ + v sin θ`` over ``[u] × [v] × [θ]`` (exact, then widened by
    :data:`ANGLE_ROOM`): the corners' ``R cos(θ − ψ)`` over ``[θ]``, joined."""
    t0, t1 = theta
    room = ANGLE_ROOM * (1.0 + np.maximum(np.abs(t0), np.abs(t1)))
    lo = hi = None
    for uc in u:
        for vc in v:
            r = np.hypot(uc, vc) * (1.0 + 4 * _UNIT)
            psi = np.arctan2(vc, uc)
            c0, c1 = _cos_range(t0 - psi - room, t1 - psi + room)
            slack = r * ANGLE_ROOM
            a, b = r * c0 - slack, r * c1 + slack
            lo = a if lo is None else np.minimum(lo, a)
            hi = b if hi is None else np.maximum(hi, b)
    return lo, hi


def _cos_range(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``cos`` over ``[a, b]``: its ends' values, 1 where a multiple of 2π lies within, -1
    where an odd multiple of π does (all of [-1, 1] over a turn or more)."""
    ca, cb = np.cos(a), np.cos(b)
    lo, hi = np.minimum(ca, cb), np.maximum(ca, cb)
    top = _TWO_PI * np.ceil(a / _TWO_PI) <= b
    bottom = _TWO_PI * np.ceil((a - math.pi) / _TWO_PI) + math.pi <= b
    turn = ~(b - a < _TWO_PI)  # NaN too
    hi = np.where(top | turn, 1.0, np.minimum(hi, 1.0))
    lo = np.where(bottom | turn, -1.0, np.maximum(lo, -1.0))
    return lo, hi
