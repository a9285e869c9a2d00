"""Tighter bounds for a sum that holds a power of a sum multiplied out: ``(O_1 + ... + O_n)^k``.

A sculpture's ornament summed over its symmetry group and raised to the power k
(:mod:`surfgen.generator.model.families.sculpture`) is written multiplied out, as equation (13)
requires: ``(U + V + W)^2`` is ``a U U + 2a U V + 2a U W + a V V + 2a V W + a W W``. Interval
arithmetic bounds each product on its own, as if U, V and W could take their extremes
independently in every one: where they have mixed signs, ``2a U V`` reaches far below zero while
the square it is a part of never does, and the blocks around the surface are left to sample
(sculpture-3 at 512^3 samples 77 000 leaves to keep 10 900).

:func:`regroup` finds such an expansion among the formula's top-level terms (the product terms
whose factors are k of n shared sub-expressions, each of which has a term of its own power k,
every multiset of them once, with coefficients ``a`` times the multinomial ones) and writes
the formula with it folded back (``compact``: ``a (O_1 + ... + O_n)^k`` and the other terms),
plus a bound on what folding it back can change (``spread``). For every point p, with ``o_i``
the values the evaluator computes for the shared ``O_i`` (one node each, so the same float in
every term) and ``t_j`` the top-level terms' values:

- ``compact`` at the ``o_i`` is, in exact arithmetic, the sum of the ``t_j`` with each product
  replaced by its exact value, but for the coefficients' residuals
  ``δ_m = c_m - a · multinomial(m)`` (exact, with fractions);
- the evaluator's F(p) differs from that exact sum by the rounding of its products (k
  multiplications each) and of its sum (T terms, in any order): at most ``γ · Σ |t_j|`` with
  ``γ = (T + k) u / (1 - (T + k) u)``, u = 2^-53 (Higham, *Accuracy and Stability of Numerical
  Algorithms*, 2002, §3.1 and §4.2).

So ``F(p)`` lies in ``compact(p) ± spread(p)`` with ``spread = γ' Σ |t_j| + Σ_m |δ_m| |Π O^m|``
(``γ'`` four times γ, and the residuals rounded up). In ``compact`` the other terms of one
axis are summed together too (:func:`_by_axis`: a cubic envelope's ``|x|^4.5 - 0.58 x^3``,
whose terms bounded apart each take their own extremes, becomes one value of x, bounded at the
grid's coordinates exactly), the reordering's rounding being within the same ``γ Σ |t_j|``.

:func:`regrouped_bounds` bounds the program by ``compact ± spread`` instead of its own terms:
``spread`` (about ``1e-14 Σ |t_j|`` where the coefficients are exact) is bounded once over the
hull of the boxes where that is finite, else box by box; a box where both are finite (so
every ``o_i`` and ``t_j`` is, and F too) gets ``[lo(compact) - hi(spread), hi(compact) +
hi(spread)]`` and is finite; the others, near a pole, the program's own bounds. The sampled
points are the same; only fewer blocks are left to sample (figures: the intervals reference,
docs/reference/intervals.md).

The same ``compact ± spread`` holds a maximum or minimum written through ``|·|`` among the
terms (``c A + c B + c |A - B|`` as ``2 max(c A, c B)``: :mod:`~.interval_extrema`, whose
groups add their own residuals and roundings to ``spread``); ``compact``'s polynomials are
bounded by their Taylor forms (:mod:`~.interval_poly`).
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Mapping
from dataclasses import dataclass, replace
from fractions import Fraction
from itertools import combinations_with_replacement

import numpy as np

from surfgen.generator.eval.compiler import Program, compile_tree
from surfgen.generator.eval.interval_extrema import Extremum, extrema
from surfgen.generator.eval.interval_poly import polynomial_bounds, polynomial_structure
from surfgen.generator.eval.leaf_states import Bounds
from surfgen.generator.formula.expr import Expr, add_all, as_expr, call, mul_all, postorder

#: The largest power folded back (the sampler's ornaments use 1 to 3).
MAX_POWER = 4
#: The largest number of distinct factors of one expansion.
MAX_FACTORS = 6
#: A coefficient may differ from ``a`` times its multinomial coefficient by this share of it
#: (the sampler rounds them to four significant digits); beyond, the residuals would make the
#: bound no better than the terms' own.
MAX_RESIDUAL = 1e-2
#: Sums of the terms' magnitudes at or beyond this are not used (no sum below it overflows).
SPREAD_LIMIT = 1e300
_UNIT = 2.0**-53

__all__ = ["Regrouped", "regroup", "regrouped_bounds"]


@dataclass(frozen=True)
class Expansion:
    """One power of a sum found multiplied out: ``a (factors[0] + ...)^power``."""

    factors: tuple[Expr, ...]
    power: int
    a: float
    terms: int  # the product terms it stands for


@dataclass(frozen=True)
class Regrouped:
    """A formula with its expansions folded back (the module's docstring): ``compact`` and
    ``spread`` as trees, and what was found."""

    compact: Expr
    spread: Expr
    expansions: tuple[Expansion, ...]
    gamma: float  # the factor of ``Σ |t_j|`` in ``spread``
    extrema: tuple[Extremum, ...] = ()


def regroup(tree: Expr) -> Regrouped | None:
    """The formula ``tree`` with every multiplied-out power of a sum among its top-level terms
    folded back and every maximum or minimum written through ``|·|`` as one
    (:mod:`~.interval_extrema`), and the bound on the difference (the module's docstring); None
    when it has neither (then interval bounds of ``tree`` are as tight as regrouping would make
    them)."""
    axes = _axes_of(tree)
    terms = _terms(tree, axes)
    products: dict[int, list[tuple[int, float, tuple[Expr, ...]]]] = defaultdict(list)
    one: dict[Expr, Expr] = {}  # equal factors as one object: later lookups compare identities
    for j, term in enumerate(terms):
        coefficient, factors = _product(term)
        if len(factors) >= 2 and coefficient != 0.0:
            factors = tuple(one.setdefault(f, f) for f in factors)
            products[len(factors)].append((j, coefficient, factors))
    found: list[tuple[Expansion, list[int], Expr]] = []
    for k, group in sorted(products.items()):
        if k > MAX_POWER:
            continue
        # The candidates: factors with a pure power term (``c O^k``), and the terms made of
        # them alone, in sets linked by their factors.
        pure = {fs[0] for *_, fs in group if all(f is fs[0] for f in fs)}
        group = [g for g in group if all(f in pure for f in g[2])]
        for members in _linked(group):
            made = _expansion(k, [group[i] for i in members])
            if made is not None:
                found.append(made)
    folded = {j for _, js, _ in found for j in js}
    others = [j for j in range(len(terms)) if j not in folded]
    groups = [  # their terms numbered among all the terms
        replace(g, terms=tuple(None if j is None else others[j] for j in g.terms))
        for g in extrema([terms[j] for j in others])
    ]
    if not found and not groups:
        return None
    folded.update(j for g in groups for j in g.terms if j is not None)
    rest = _by_axis([t for j, t in enumerate(terms) if j not in folded], axes)
    powers = [
        _times(e.a, Expr("^", (add_all(list(e.factors)), as_expr(float(e.power)))))
        for e, _, _ in found
    ]
    gamma = (len(terms) + MAX_POWER) * _UNIT
    gamma = 4.0 * gamma / (1.0 - gamma)
    spread = [_times(gamma, add_all([call("abs", t) for t in terms]))]
    spread += [residual for _, _, residual in found if residual is not None]
    spread += [g.spread for g in groups]
    return Regrouped(
        compact=add_all(rest + powers + [g.compact for g in groups]),
        spread=add_all(spread),
        expansions=tuple(e for e, _, _ in found),
        gamma=gamma,
        extrema=tuple(groups),
    )


def regrouped_bounds(
    base: Bounds,
    program: Program,
    regrouped: Regrouped,
    params: Mapping[str, float] | None = None,
    level: float | None = None,
    threads: int = 1,
) -> Bounds:
    """``base`` with ``program`` bounded as ``compact ± spread`` (the module's docstring);
    other programs, and the boxes where ``compact`` or ``spread`` may not be finite, by
    ``base`` itself. ``compact`` is bounded through its polynomials' Taylor forms where it has
    some worth them (:mod:`~.interval_poly`, with ``level`` and ``threads``): a maximum's
    operands are often such polynomials.

    ``spread`` is a rounding error (``γ Σ |t_j|``, about ``1e-15 Σ |t_j|``) plus the
    coefficients' residuals: its bound over the hull of the boxes serves every box where it is
    finite (one box bounded instead of K), else it is bounded per box."""
    compact = compile_tree(regrouped.compact, dict(params or {}))
    spread = compile_tree(regrouped.spread, dict(params or {}))
    limit = regrouped.gamma * SPREAD_LIMIT  # so that no sum of the terms can overflow
    compact_bounds = base
    if (structure := polynomial_structure(regrouped.compact)) is not None:
        compact_bounds = polynomial_bounds(base, compact, structure, level, params, threads)

    def bounds(prog: Program, lo: np.ndarray, hi: np.ndarray):
        if prog is not program or len(lo) == 0:
            return base(prog, lo, hi)
        lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
        glo, ghi, gfinite = compact_bounds(compact, lo, hi)
        margin = np.full(len(glo), np.inf)
        _, whole, wfinite = base(spread, lo.min(axis=0)[None], hi.max(axis=0)[None])
        if wfinite[0] and whole[0] <= limit:
            margin[:] = whole[0]
        else:  # a pole or a jump to infinity somewhere: per box
            todo = np.flatnonzero(gfinite)
            _, shi, sfinite = base(spread, lo[todo], hi[todo])
            margin[todo] = np.where(sfinite, shi, np.inf)
        finite = gfinite & (margin <= limit)
        with np.errstate(invalid="ignore", over="ignore"):
            flo = np.nextafter(glo - margin, -np.inf)
            fhi = np.nextafter(ghi + margin, np.inf)
        rest = np.flatnonzero(~finite)
        if len(rest):
            flo[rest], fhi[rest], finite[rest] = base(program, lo[rest], hi[rest])
        return flo, fhi, finite

    return bounds


# ----------------------------------------------------------------------------- the terms


def _axes_of(tree: Expr) -> dict[int, frozenset[str]]:
    """The variables of every node of ``tree`` (by identity), in one pass."""
    axes: dict[int, frozenset[str]] = {}
    for node in postorder(tree):
        if node.op == "var":
            axes[id(node)] = frozenset((node.value,))
        else:
            axes[id(node)] = frozenset().union(*(axes[id(a)] for a in node.args))
    return axes


def _terms(tree: Expr, axes: dict[int, frozenset[str]]) -> list[Expr]:
    """The top-level terms of a sum, each with its sign (a subtracted term as ``neg``); a sum of
    one axis is one term (the evaluator computes it as one value of that axis). The tree's
    order of summation does not matter to the bound (any order's rounding is within
    ``γ Σ |t_j|``)."""
    out: list[Expr] = []
    stack: list[tuple[Expr, bool]] = [(tree, False)]
    while stack:
        node, negative = stack.pop()
        if len(axes[id(node)]) <= 1 and node.op in ("+", "-"):
            out.append(Expr("neg", (node,)) if negative else node)  # one value of one axis
        elif node.op == "+":
            stack += [(node.args[1], negative), (node.args[0], negative)]
        elif node.op == "-":
            stack += [(node.args[1], not negative), (node.args[0], negative)]
        elif node.op == "neg":
            stack.append((node.args[0], not negative))
        else:
            out.append(Expr("neg", (node,)) if negative else node)
    return out


def _by_axis(terms: list[Expr], axes: dict[int, frozenset[str]]) -> list[Expr]:
    """The terms with those of one axis summed together, per axis (a constant with the first
    of them): a sum of one axis is bounded at each of the grid's coordinates exactly
    (:func:`~.intervals.grid_point_bounds`), where its terms bounded apart each take their own
    extremes (``|x|^4.5 - 0.58 x^3``, a cubic envelope's). Done where an expansion is folded
    back: alone, it decides few more blocks (sculpture-2 at 512^3 samples 9 590 leaves
    instead of 11 834, its run 3 % faster) and costs a second program's bounds where a term
    can be infinite (a twist: its classification 104 -> 240 ms, for 0.2 % fewer leaves)."""
    groups: dict[str, list[Expr]] = defaultdict(list)
    others: list[Expr] = []
    for t in terms:
        names = axes.get(id(t))
        if names is None:  # a subtracted term, wrapped in a neg of its own
            names = axes[id(t.args[0])]
        if len(names) <= 1:
            groups[next(iter(names), "")].append(t)
        else:
            others.append(t)
    constants = groups.pop("", [])
    sums = [add_all(ts) for _, ts in sorted(groups.items())]
    if sums and constants:
        sums[0] = add_all([sums[0], *constants])
    else:
        sums += constants
    return sums + others


def _product(term: Expr) -> tuple[float, tuple[Expr, ...]]:
    """A term as ``coefficient * f_1 * ... * f_k`` along its left spine of products (the
    order the evaluator multiplies in: ``c*(U)*(V)`` is ``(c U) V``); the coefficient is a
    number at the spine's end, else 1."""
    sign = 1.0
    while term.op == "neg":
        sign, term = -sign, term.args[0]
    factors: list[Expr] = []
    while term.op == "*":
        factors.append(term.args[1])
        term = term.args[0]
    number = term
    negated = False
    while number.op == "neg":
        negated, number = not negated, number.args[0]
    if number.op == "num":
        coefficient = float(number.value) * (-1.0 if negated else 1.0)
    else:
        factors.append(term)
        coefficient = 1.0
    return sign * coefficient, tuple(reversed(factors))


def _linked(group: list[tuple[int, float, tuple[Expr, ...]]]) -> list[list[int]]:
    """The product terms of ``group`` in sets linked by shared factors (union-find)."""
    parent: dict[Expr, Expr] = {}

    def root(f: Expr) -> Expr:
        while parent[f] is not f:
            parent[f] = parent[parent[f]]
            f = parent[f]
        return f

    for _, _, factors in group:
        for f in factors:
            parent.setdefault(f, f)
        for f in factors[1:]:
            a, b = root(factors[0]), root(f)
            if a is not b:
                parent[b] = a
    sets: dict[int, list[int]] = defaultdict(list)
    for i, (_, _, factors) in enumerate(group):
        sets[id(root(factors[0]))].append(i)
    return list(sets.values())


def _expansion(
    k: int, members: list[tuple[int, float, tuple[Expr, ...]]]
) -> tuple[Expansion, list[int], Expr | None] | None:
    """The power of a sum these product terms of k factors multiply out, its terms' indices
    and the bound on its coefficients' residuals (None when they are exact); None when they
    are not every multiset of their factors once, with coefficients in proportion."""
    factors = list(dict.fromkeys(f for *_, fs in members for f in fs))  # as they first appear
    n = len(factors)
    if n > MAX_FACTORS or (n == 1 and k < 3) or len(members) != math.comb(n + k - 1, k):
        return None
    index = {f: i for i, f in enumerate(factors)}
    by_key: dict[tuple[int, ...], float] = {}
    for _, c, fs in members:
        by_key[tuple(sorted(index[f] for f in fs))] = c
    combos = list(combinations_with_replacement(range(n), k))
    if set(by_key) != set(combos):
        return None
    a = by_key[(0,) * k]
    residuals: list[Expr] = []
    for combo in combos:
        c = by_key[combo]
        exact = Fraction(c) - Fraction(a) * _multinomial(combo)
        if abs(exact) > MAX_RESIDUAL * abs(Fraction(c)):
            return None
        if exact:
            size = float(np.nextafter(float(abs(exact)), np.inf))
            residuals.append(_times(size, call("abs", mul_all([factors[i] for i in combo]))))
    expansion = Expansion(tuple(factors), k, a, len(members))
    return expansion, [j for j, *_ in members], add_all(residuals) if residuals else None


def _multinomial(combo: tuple[int, ...]) -> int:
    out = math.factorial(len(combo))
    for i in set(combo):
        out //= math.factorial(combo.count(i))
    return out


def _times(c: float, tree: Expr) -> Expr:
    """``c * tree`` (a negative c as ``neg``: numbers are written non-negative)."""
    if c < 0:
        return Expr("neg", (Expr("*", (as_expr(-c), tree)),))
    return Expr("*", (as_expr(c), tree))
