"""Tighter bounds for a maximum or minimum written through ``|·|``: ``(a + b + |a - b|) / 2``.

The assembly family combines two bodies by ``max(A, B) = (A + B + |A - B|) / 2`` (or ``min``
with ``-|A - B|``: :func:`~surfgen.generator.model.families.bodies.intersection`,
``union``, ``difference``, ``power_max``), each of A, B and ``A - B`` written out; the infill
family keeps a body's inside by ``c X + c |X| = 2 c max(X, 0)``, X a polynomial, a product of
two power functions or a plane. Interval arithmetic bounds the three terms apart, as if A and
``A - B`` were unrelated: where A is far above B, ``0.5 B + 0.5 |A - B|`` is ``0.5 A``, but
bounded term by term it is as wide as B and ``A - B`` are large (assembly-1's torus, whose
terms are in the hundreds, at 512^3: 261 000 leaves sampled to keep 8 700); ``c X + c |X|``
bounded term by term is ``2 c`` times X's width around 0 where it is 0 (infill's ``150.5 (-x -
0.078) + 150.5 |-x - 0.078|`` a quarter of the box wide).

:func:`extrema` finds such groups among a formula's top-level terms, in the terms' *linear
forms*: a term is, in exact arithmetic, a sum of coefficients times products of *atoms* (the
sub-trees other than ``+ - * neg`` and numbers: ``x``, ``|x|^2.9``, ``sin(...)``, ``|P|``),
which the evaluator computes once each (equal sub-trees are one node of its program, so every
term reads the same float). A group is terms ``t_1``, ``t_2`` (or none: ``t_2 = 0``) and ``t_3
= σ |Z|`` (a number times ``|·|`` factors only: ``|P| |Q|`` is ``|P Q|``) with ``|Z| = |t_1 -
t_2|`` up to a residual R (exact, with fractions): then

    t_1 + t_2 + t_3 = 2 max(t_1, t_2)  (σ = +1),  2 min(t_1, t_2)  (σ = -1),

up to ``|R|`` and the rounding of the three terms by the evaluator: each computes a sum of
products of the atoms' floats, within ``γ_K L~`` of its linear form's exact value (``L~``: its
coefficients' and atoms' magnitudes; K the roundings of the three terms, Higham, *Accuracy and
Stability of Numerical Algorithms*, 2002, §3.1). :func:`~.interval_regroup.regroup` puts
``2 max(t_1, t_2)`` in the formula's ``compact`` form and ``|R|~ + γ_K (L_1~ + L_2~ + L_3~)``
(about 1e-15 of the terms' magnitudes) in its ``spread``, and bounds the formula by ``compact
± spread``: over a box, ``max`` takes the larger of each end, so the tight operand decides.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from surfgen.generator.formula.expr import Expr, add_all, as_expr, call, mul_all

#: The most products a term's linear form may have (a product of sums is multiplied out).
MAX_PRODUCTS = 256
#: The residual ``R`` may be this share of ``|Z|``'s coefficients at most (the families write
#: ``A - B`` with its coefficients rounded to twelve digits: 2.4e-6 of them in assembly-18 of
#: seed 5); beyond, no group (its spread would be as wide as the terms' own bounds).
MAX_RESIDUAL = 1e-4
#: Pairs of partners are looked for among at most this many terms sharing an atom with ``Z``
#: (the families': 2-3; a formula of many such terms is looked at for single partners only).
MAX_PAIRED = 64
#: Roundings added to a group's count: an atom met in two terms is one node of the program,
#: but a margin of a few units costs nothing (the spread is about 1e-15 of the terms).
EXTRA_ROUNDINGS = 4
_UNIT = 2.0**-53
#: The weights' factor for the rounding of the spread's own evaluation (its products and sum:
#: below 2^13 roundings, each 2^-53 at most).
_ROOM = 1 + Fraction(1, 2**40)

__all__ = ["Extremum", "extrema"]

#: A linear form: products of atoms (sorted atom numbers) -> exact coefficient.
Form = dict[tuple[int, ...], Fraction]


@dataclass(frozen=True)
class Extremum:
    """A group found (the module's docstring): the top-level terms it stands for (``terms``:
    ``t_1``, ``t_2``, ``t_3``; ``t_2`` None for ``max(t_1, 0)``), ``kind`` ``"max"`` or
    ``"min"``, ``compact`` (``2 max(t_1, t_2)``) and ``spread`` (its bound on the difference)."""

    terms: tuple[int, int | None, int]
    kind: str
    compact: Expr
    spread: Expr


def extrema(terms: list[Expr]) -> list[Extremum]:
    """The groups among the top-level ``terms`` (each signed: a subtracted term as ``neg``),
    each term in one group at most, in the order of their ``|·|`` terms."""
    forms = _Forms()
    absolute = {j: inner for j, t in enumerate(terms) if (inner := forms.absolute(t)) is not None}
    if not absolute:
        return []
    linear = {j: forms.linear(t) for j, t in enumerate(terms)}
    keys = {j: set(lin.form) for j, lin in linear.items()}  # each term's products of atoms
    used: set[int] = set()
    found: list[Extremum] = []
    for j3, (sigma, l3) in absolute.items():
        if j3 in used:
            continue
        near = [j for j in linear if j != j3 and j not in used and not keys[j].isdisjoint(l3.form)]
        match = _partners(near, linear, keys, l3.form)
        if match is None:
            continue
        j1, j2, residual = match
        group = [linear[j1], l3] + ([linear[j2]] if j2 is not None else [])
        used.update(j for j in (j1, j2, j3) if j is not None)
        kind = "max" if sigma > 0 else "min"
        other = terms[j2] if j2 is not None else as_expr(0.0)
        found.append(
            Extremum(
                terms=(j1, j2, j3),
                kind=kind,
                compact=Expr("*", (as_expr(2.0), call(kind, terms[j1], other))),
                spread=forms.spread(residual, group),
            )
        )
    return found


@dataclass(frozen=True)
class _Linear:
    """A term in exact arithmetic over the atoms: ``form``; ``size``, the same with every
    coefficient's magnitude and every ``-`` a ``+`` (what its rounding is bounded by); ``ops``,
    the roundings it takes (its ``+ - *`` outside the atoms)."""

    form: Form
    size: Form
    ops: int


def _partners(near: list[int], linear: dict[int, _Linear], keys: dict[int, set], l3: Form):
    """``(j1, j2, R)`` with ``l3 = ±(L_j1 - L_j2) + R`` (``j2`` None: ``l3 = ±L_j1 + R``), R
    within :data:`MAX_RESIDUAL` of ``l3``: of the pairs and single terms (``keys``: their
    products of atoms), the one with the least residual (a single term on a tie); None where
    there is none."""
    size = sum(abs(c) for c in l3.values())
    need = l3.keys()
    singles = [(a, None) for a in near if need <= keys[a]]
    paired = near if len(near) <= MAX_PAIRED else []
    pairs = [(a, b) for i, a in enumerate(paired) for b in paired[i + 1 :]
             if need <= keys[a] | keys[b]]  # fmt: skip
    best = None
    for j1, j2 in singles + pairs:
        diff = linear[j1].form if j2 is None else _add(linear[j1].form, linear[j2].form, -1)
        for sign in (1, -1):
            residual = _add(l3, diff, -sign)
            off = sum(abs(c) for c in residual.values())
            if off <= MAX_RESIDUAL * size and (best is None or off < best[0]):
                best = (off, j1, j2, residual)
    return None if best is None else best[1:]


def _add(a: Form, b: Form, sign: int = 1) -> Form:
    """``a + sign * b``, without zero coefficients."""
    out = dict(a)
    for k, c in b.items():
        out[k] = out.get(k, 0) + sign * c
    return {k: c for k, c in out.items() if c}


def _mul(a: Form, b: Form) -> Form:
    out: Form = {}
    for ka, ca in a.items():
        for kb, cb in b.items():
            k = tuple(sorted(ka + kb))
            out[k] = out.get(k, 0) + ca * cb
    return {k: c for k, c in out.items() if c}


class _Forms:
    """Linear forms of terms over atoms numbered as they are met (equal atoms one number)."""

    def __init__(self) -> None:
        self.atoms: list[Expr] = []
        self.number: dict[Expr, int] = {}

    def linear(self, term: Expr) -> _Linear:
        """``term`` over the atoms; a product whose form would have more than
        :data:`MAX_PRODUCTS` products is an atom."""
        done: dict[int, _Linear] = {}
        stack: list[tuple[Expr, bool]] = [(term, False)]
        while stack:
            node, ready = stack.pop()
            if id(node) in done:
                continue
            linear_op = node.op in ("+", "-", "*", "neg")
            if linear_op and not ready:
                stack.append((node, True))
                stack.extend((a, False) for a in node.args)
                continue
            done[id(node)] = self._node(node, [done[id(a)] for a in node.args] if linear_op else [])
        return done[id(term)]

    def _node(self, node: Expr, kids: list[_Linear]) -> _Linear:
        op = node.op
        if op == "num":
            v = Fraction(node.value)
            return _Linear({(): v} if v else {}, {(): v} if v else {}, 0)
        if op == "neg":
            (a,) = kids
            return _Linear({k: -c for k, c in a.form.items()}, a.size, a.ops)
        if op in ("+", "-"):
            a, b = kids
            form = _add(a.form, b.form, 1 if op == "+" else -1)
            return _Linear(form, _add(a.size, b.size), a.ops + b.ops + 1)
        if op == "*" and len(kids[0].size) * len(kids[1].size) <= MAX_PRODUCTS:
            a, b = kids
            return _Linear(_mul(a.form, b.form), _mul(a.size, b.size), a.ops + b.ops + 1)
        one = {(self._atom(node),): Fraction(1)}
        return _Linear(one, one, 0)

    def _atom(self, node: Expr) -> int:
        if node not in self.number:
            self.number[node] = len(self.atoms)
            self.atoms.append(node)
        return self.number[node]

    def absolute(self, term: Expr) -> tuple[int, _Linear] | None:
        """For ``term = c |Z_1| ... |Z_k|`` (k >= 1, c a number, signs by ``neg``): the sign of
        c and ``|c| Z_1 ... Z_k`` over the atoms, with the term's roundings; else None."""
        sign, factors, number, products = 1, [], Fraction(1), 0
        stack = [term]
        while stack:
            node = stack.pop()
            if node.op == "neg":
                sign = -sign
                stack.append(node.args[0])
            elif node.op == "*":
                products += 1
                stack.extend(node.args)
            elif node.op == "num":
                number *= Fraction(node.value)
            elif node.op == "abs":
                factors.append(node.args[0])
            else:
                return None
        if not factors or not number:
            return None
        inner = self.linear(mul_all(factors))
        if not any(inner.form):  # a constant
            return None
        scaled = ({k: number * c for k, c in d.items()} for d in (inner.form, inner.size))
        return sign, _Linear(*scaled, inner.ops + products)

    def spread(self, residual: Form, group: list[_Linear]) -> Expr:
        """``Σ (|r| + γ_K Σ s) |atom| ...`` over the products of ``residual`` and the group's
        sizes ``s``: the bound on ``|R|`` plus the three terms' rounding (the module's
        docstring), each weight rounded up and by :data:`_ROOM` (so the spread's float value
        is not below the exact one); γ_K four times Higham's (K their roundings and
        :data:`EXTRA_ROUNDINGS`), as the regrouped spread's."""
        ops = sum(lin.ops for lin in group) + EXTRA_ROUNDINGS
        gamma = ops * _UNIT / (1.0 - ops * _UNIT)
        gamma = Fraction(4.0 * gamma)
        weight: Form = {k: abs(c) for k, c in residual.items()}
        for lin in group:
            for k, c in lin.size.items():
                weight[k] = weight.get(k, 0) + gamma * c
        parts = []
        for k, w in weight.items():  # up by the rounding of the spread's own sum of products
            size = as_expr(float(np.nextafter(float(w * _ROOM), np.inf)))
            parts.append(mul_all([size, *(call("abs", self.atoms[a]) for a in k)]))
        return add_all(parts)
