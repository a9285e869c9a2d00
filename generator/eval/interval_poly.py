"""Tighter bounds for formulas built of expanded polynomials: their Taylor forms.

The infill, assembly and twist families write a torus' or a twisted body's polynomial out as a
sum of monomials (``604.334*x^4 + 1208.67*x^2*y^2 + ... + 992.428*x + 151.342``) whose terms,
in the hundreds, cancel to nothing near the surface. Interval arithmetic bounds each monomial
over a box on its own, so the bound of the sum is as wide as the terms are large, not as the
polynomial varies: assembly-0 at 512^3 samples 79 287 leaves to keep 1 963.

:func:`polynomial_structure` splits a formula into its **polynomials** (maximal sub-trees of
``+ - * neg`` and whole powers over numbers and x, y, z, with three or more monomials of
degree two or more, one of them of two variables), **parts** (the sub-trees without such a
polynomial, each bounded by the base bounds as a program of its own) and the **operations
joining them** (``+ - * / neg abs max min``, a power with a real exponent, and numbers).
:func:`polynomial_bounds` bounds a box:

- a polynomial P by its Taylor form at the box's centre c: ``P(c + t) = Σ_β d_β t^β`` with
  ``|t_i| <= h_i`` (a ``t^β`` of even powers only is ``>= 0``), each ``d_β`` (a sum of
  ``c_α binom(α, β) c^(α-β)``, exact in its coefficients) computed in floats with a bound on
  its rounding; then the evaluator's value of P, which rounds each of the n operations on a
  path, by ``γ_n · P~(|x|)`` more (``P~``: the tree with every number's magnitude, every
  ``-`` a ``+``: the forward error bound of a sum of products whatever the order and
  contractions, Higham 2002, §3.1), ``P~`` at the box's largest ``|x|, |y|, |z|``;
- a part by the base bounds (over the grid's points: a value of one axis exactly);
- a quotient ``P / D`` or ``P / D^k`` (k real) of a polynomial P and any polynomial D in its
  centred form ``r + (P - r D) / D``, r its value at the box's centre (:func:`_centred`): a
  twist's lobe and its radius grow together, which the quotient of their bounds misses;
- a sum holding ``U cos θ + V sin θ`` (a twist's lobes) by its terms' bounds with each such
  pair bounded as one wave (:mod:`~surfgen.generator.eval.interval_harmonic`);
- the joining operations as intervals, each end moved one place outward (so each holds the
  exact and the rounded result of any values within its operands); a real power by its ends'
  powers (monotone over a base >= 0, which it needs), four units in the last place outward.

Every value the evaluator computes at a point of the box is then within the bound where every
part's and polynomial's bound is finite, the divisors' exclude 0 and the real powers' bases
are not negative (and positive below a negative exponent); there F is finite too. A box where
that fails keeps the formula's own bounds. The polynomials' Taylor shifts are bounded in
:data:`~.interval_taylor.MAX_PAIRS` pairs (a product of polynomials longer than that stays a
product of two); the structure is used only on boxes the base bounds leave undecided, and given up
where it decides next to none. The points sampled are the same; only fewer blocks are left to
sample.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from surfgen.generator.eval.compiler import Program, compile_tree
from surfgen.generator.eval.interval_harmonic import in_chains, sum_bounds, sum_terms
from surfgen.generator.eval.interval_taylor import (
    MAX_DEGREE,
    centre_values,
    taylor_bounds,
    taylor_pairs,
)
from surfgen.generator.eval.leaf_states import Bounds
from surfgen.generator.formula.expr import Expr, postorder

#: The most monomials a polynomial may have (its largest power of one variable: MAX_DEGREE).
MAX_MONOMIALS = 200
#: A polynomial is worth its Taylor form from this many monomials of degree 2 or more.
MIN_MONOMIALS = 3
_UNIT = 2.0**-53
#: The structure is given up once a call of this many boxes or more finds it deciding fewer
#: than this share of those its base bounds leave undecided.
TRIAL_BOXES = 2048
MIN_DECIDED = 0.05
#: Parts' bounds at or beyond this are not used (no operation on them overflows).
LIMIT = 1e150

__all__ = ["Structure", "polynomial_bounds", "polynomial_structure"]

_JOINS = ("+", "-", "*", "/", "neg", "abs", "max", "min")


@dataclass(frozen=True)
class Polynomial:
    """An expanded polynomial: ``coefs[m] * x^exps[m,0] * y^exps[m,1] * z^exps[m,2]``, the
    coefficients of its exact expansion rounded; ``absolute`` the same for ``P~`` (exponents,
    coefficients' magnitudes and their group, 0: as :func:`~.interval_taylor.taylor_bounds`
    reads them); ``ops`` the roundings on its longest path (the expansion's rounding of the
    coefficients included); ``taylor`` its Taylor shift's pairs."""

    exps: np.ndarray
    coefs: np.ndarray
    absolute: tuple[np.ndarray, np.ndarray, np.ndarray]
    ops: int
    taylor: tuple[np.ndarray, ...]  # :func:`~.interval_taylor.taylor_pairs`


@dataclass(frozen=True)
class Quotient:
    """A quotient ``P / D^power`` of two polynomials, bounded in its centred form
    (:func:`_centred`): ``taylor`` the pairs of P and D together (D's in group 1),
    ``absolute`` the monomials of their ``P~`` with their groups, ``ops`` the larger count of
    roundings."""

    num: Polynomial
    den: Polynomial
    taylor: tuple[np.ndarray, ...]
    absolute: tuple[np.ndarray, ...]
    ops: int
    power: float = 1.0  # the divisor is D to this power (a real one: P / D^k)


@dataclass(frozen=True)
class Structure:
    """A formula as joining operations over polynomials and other parts (see the module's
    docstring): ``nodes`` in evaluation order, each ``(kind, payload, children)`` with kind
    ``"poly"`` (a :class:`Polynomial`), ``"part"`` (a sub-tree), ``"num"`` (a float) or a
    joining operation; the last node is the formula."""

    nodes: tuple[tuple[str, object, tuple[int, ...]], ...]


@functools.lru_cache(maxsize=64)
def polynomial_structure(tree: Expr) -> Structure | None:
    """``tree`` split into polynomials, other parts and the operations joining them; None when
    it has no polynomial worth its Taylor form (module docstring). Kept for recent trees (a
    sweep or the viewer bounds one formula many times; twist-0's takes 19 ms)."""
    polys = _polynomials(tree)
    made: dict[int, Polynomial] = {}  # the largest polynomials worth it, from the root down
    stack, seen = [tree], set()
    while stack:
        node = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        p = polys[id(node)]
        if p is not None and _worth(p) and (poly := _polynomial(p)) is not None:
            made[id(node)] = poly
        else:
            stack.extend(node.args)
    if not made:
        return None
    inside: dict[int, bool] = {}  # whether a sub-tree holds one
    nodes: list[tuple[str, object, tuple[int, ...]]] = []
    index: dict[int, int] = {}
    order = postorder(tree)  # each node once, children first
    inner = in_chains(order) | made.keys()  # a term of a larger sum, or a polynomial
    for node in order:
        inside[id(node)] = id(node) in made or any(inside[id(a)] for a in node.args)
        wave = None
        if inside[id(node)] and id(node) not in inner and node.op in ("+", "-"):
            wave = sum_terms(node, made.keys())  # a whole sum holding U cos θ + V sin θ
        if id(node) in made:
            nodes.append(("poly", made[id(node)], ()))
        elif wave is not None:
            nodes.append(("sum", wave[0], tuple(index[id(a)] for a in wave[1])))
        elif node.op == "num":
            nodes.append(("num", float(node.value), ()))
        elif inside[id(node)] and (node.op in _JOINS or _real_power(node)):
            quotient = _quotient_of(node, made, polys) if node.op == "/" else None
            kids = () if quotient is not None else tuple(index[id(a)] for a in node.args)
            nodes.append((node.op, quotient, kids))  # a quotient bounds P and D itself
        else:  # a part: bounded as a program of its own where a joining node reads it
            nodes.append(("part", node, ()))
        index[id(node)] = len(nodes) - 1
    keep = sorted(_used(nodes))  # the nodes the formula reads, in order
    new = {old: i for i, old in enumerate(keep)}
    return Structure(tuple((k, p, tuple(new[c] for c in kids)) for k, p, kids in
                           (nodes[i] for i in keep)))  # fmt: skip


def polynomial_bounds(
    base: Bounds,
    program: Program,
    structure: Structure,
    level: float | None,
    params: Mapping[str, float] | None = None,
    threads: int = 1,
) -> Bounds:
    """``base`` for ``program``, and where that leaves a box undecided at ``level`` (None: every
    box), the bounds through ``structure`` too (the module's docstring), the two intersected;
    other programs by ``base`` alone. ``threads``: the polynomials' boxes in that many runs.

    Once a call of :data:`TRIAL_BOXES` boxes or more finds the structure deciding fewer than
    :data:`MIN_DECIDED` of them, later calls (the finer levels) use ``base`` alone: the
    structure costs 0.5-2 microseconds a box, and a leaf it decides saves that leaf's
    sampling, 10-30. A Taylor form tightens as the boxes shrink, so a coarse level's share
    says little of the finer ones' (twist-2 at 512^3: 7 %, 11 %, then 47 % and 67 % at the
    leaves; given up from the second, 124 000 leaves were sampled to keep 5 500, 3.1 s; now
    24 000), and the threshold is low: next to nothing decided."""
    programs = {
        i: compile_tree(payload, dict(params or {}))
        for i, (kind, payload, _) in enumerate(structure.nodes)
        if kind == "part"
    }

    active = [True]

    def bounds(prog: Program, lo: np.ndarray, hi: np.ndarray):
        flo, fhi, finite = base(prog, lo, hi)
        if prog is not program or not active[0]:
            return flo, fhi, finite
        if level is None:
            todo = np.arange(len(flo))
        else:
            todo = np.flatnonzero(~((flo > level) | (finite & (fhi < level))))
        if len(todo) == 0:
            return flo, fhi, finite
        lo_t = np.ascontiguousarray(np.asarray(lo, dtype=np.float64)[todo])
        hi_t = np.ascontiguousarray(np.asarray(hi, dtype=np.float64)[todo])
        slo, shi, ok = _structure_bounds(structure, programs, base, lo_t, hi_t, threads)
        decided = ok & ((slo > level) | (shi < level)) if level is not None else ok
        if len(todo) >= TRIAL_BOXES and decided.mean() < MIN_DECIDED:
            active[0] = False  # it decides next to nothing more: not worth its cost below
        flo, fhi, finite = flo.copy(), fhi.copy(), finite.copy()
        at = todo[ok]
        flo[at] = np.maximum(flo[at], slo[ok])
        fhi[at] = np.minimum(fhi[at], shi[ok])
        finite[at] = True
        return flo, fhi, finite

    return bounds


def _structure_bounds(structure, programs, base, lo, hi, threads):
    """The bounds through ``structure`` of the boxes ``lo``, ``hi``, and where they hold (every
    part's and polynomial's bounds finite, the divisors' without 0)."""
    ok = np.ones(len(lo), dtype=np.bool_)
    vals: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    with np.errstate(all="ignore"):
        for i, (kind, payload, kids) in enumerate(structure.nodes):
            if kind == "poly":
                vlo, vhi = _poly_bounds(payload, lo, hi, threads)
            elif kind == "part":
                vlo, vhi, finite = base(programs[i], lo, hi)
                ok &= finite
            elif kind == "num":
                vlo = vhi = np.full(len(lo), payload)
            elif kind == "sum":
                vlo, vhi = sum_bounds(payload, [vals[k] for k in kids])
            elif kind == "/" and payload is not None:  # a quotient of polynomials
                vlo, vhi = _quotient_bounds(payload, lo, hi, ok, threads)
            else:
                vlo, vhi = _join(kind, [vals[k] for k in kids], ok)
            ok &= np.isfinite(vlo) & np.isfinite(vhi) & (vlo <= vhi)
            ok &= (np.abs(vlo) < LIMIT) & (np.abs(vhi) < LIMIT)
            vals[i] = (vlo, vhi)
    flo, fhi = vals[len(structure.nodes) - 1]
    return flo, fhi, ok


def _quotient_of(node: Expr, made: dict[int, Polynomial], polys: dict) -> Quotient | None:
    """A ``/`` node as a :class:`Quotient` where it is ``P / D`` or ``P / D^k`` (k a real
    number), P a polynomial found and D any polynomial (a twist's radius ``x^2 + y^2 + δ`` is
    too short to be one of its own)."""
    num, den = node.args
    power = 1.0
    if _real_power(den):
        den, power = den.args[0], float(den.args[1].value)
    if id(num) not in made or polys.get(id(den)) is None:
        return None
    divisor = made.get(id(den)) or _polynomial(polys[id(den)])
    return None if divisor is None else _quotient(made[id(num)], divisor, power)


def _quotient(num: Polynomial, den: Polynomial, power: float = 1.0) -> Quotient | None:
    """``num / den^power`` as a :class:`Quotient`; None beyond
    :data:`~.interval_taylor.MAX_PAIRS` pairs together."""
    tags = [0] * len(num.exps) + [1] * len(den.exps)
    taylor = taylor_pairs(
        np.vstack([num.exps, den.exps]), np.concatenate([num.coefs, den.coefs]), tags
    )
    if taylor is None:
        return None
    (e0, c0, g0), (e1, c1, g1) = num.absolute, den.absolute
    absolute = (np.vstack([e0, e1]), np.concatenate([c0, c1]), np.concatenate([g0, g1 + 1]))
    return Quotient(num, den, taylor, absolute, max(num.ops, den.ops), power)


def _quotient_bounds(q: Quotient, lo: np.ndarray, hi: np.ndarray, ok: np.ndarray, threads: int):
    """A quotient's bounds in its centred form (:func:`_centred`), and where that fails (D's
    bound reaching 0 or below) P's bound over D's (``ok`` cleared where that fails too)."""
    den = _poly_bounds(q.den, lo, hi, threads)
    vlo, vhi = _centred(q, lo, hi, den, threads)
    bad = np.flatnonzero(~(np.isfinite(vlo) & np.isfinite(vhi)))
    if len(bad):
        held = np.ones(len(bad), dtype=np.bool_)
        num = _poly_bounds(q.num, lo[bad], hi[bad], threads)
        d = (den[0][bad], den[1][bad])
        if q.power != 1.0:
            d = _join("^", [d, (np.full(len(bad), q.power),) * 2], held)
        vlo[bad], vhi[bad] = _join("/", [num, d], held)
        ok[bad] &= held
    return vlo, vhi


def _centred(q: Quotient, lo: np.ndarray, hi: np.ndarray, den, threads: int):
    """Bounds of the evaluator's ``P / D`` over the boxes as ``r + (P - r D) / D``, ``r`` its
    value at each box's centre (any number would do: the form is exact), the numerator bounded
    by its Taylor form (with the evaluator's roundings of P and of ``r D``), ``den`` D's
    bounds (NaN where they hold 0), the quotient's rounding four units outward; ``P / D^k``
    as that times ``D^(1 - k)`` (a base > 0: elsewhere NaN), the power's, the quotient's and
    the product's roundings eight units outward."""
    r = centre_values(q.num.exps, q.num.coefs, lo, hi) / centre_values(
        q.den.exps, q.den.coefs, lo, hi
    )
    r = np.where(np.isfinite(r), r, 0.0)
    w = np.stack([np.ones(len(lo)), -r])
    num = taylor_bounds(q.taylor, q.absolute, q.ops, _UNIT, lo, hi, threads, w)
    held = np.ones(len(lo), dtype=np.bool_)  # cleared where D's bound holds 0
    qlo, qhi = _join("/", [num, den], held)
    vlo, vhi = _down(np.where(held, r + qlo, np.nan)), _up(np.where(held, r + qhi, np.nan))
    room = 4.0
    if q.power != 1.0:
        d0, d1 = den
        base0, base1 = np.where(d0 > 0, d0, np.nan), np.where(d0 > 0, d1, np.nan)
        f = (np.power(base0, 1.0 - q.power), np.power(base1, 1.0 - q.power))
        f0, f1 = _down(np.fmin(*f) * (1 - 4 * _UNIT)), _up(np.fmax(*f) * (1 + 4 * _UNIT))
        corners = np.stack([vlo * f0, vlo * f1, vhi * f0, vhi * f1])
        vlo, vhi, room = _down(corners.min(axis=0)), _up(corners.max(axis=0)), 8.0
    return _down(vlo - room * _UNIT * np.abs(vlo)), _up(vhi + room * _UNIT * np.abs(vhi))


def _real_power(node: Expr) -> bool:
    """A power with a number for exponent that is not whole (the evaluator's ``pow``: its base
    is not negative where it is defined)."""
    if node.op != "^" or node.args[1].op != "num":
        return False
    return not float(node.args[1].value).is_integer()


def _used(nodes: list[tuple[str, object, tuple[int, ...]]]) -> set[int]:
    """The nodes the formula (the last one) reads."""
    used, todo = set(), [len(nodes) - 1]
    while todo:
        i = todo.pop()
        if i not in used:
            used.add(i)
            todo.extend(nodes[i][2])
    return used


# ----------------------------------------------------------------------------- the joining ops


def _down(v: np.ndarray) -> np.ndarray:
    return np.nextafter(v, -np.inf)


def _up(v: np.ndarray) -> np.ndarray:
    return np.nextafter(v, np.inf)


def _join(op: str, args: list[tuple[np.ndarray, np.ndarray]], ok: np.ndarray):
    """An interval operation, each end one place outward; a divisor that may hold 0 clears
    ``ok``."""
    if op == "neg":
        ((a0, a1),) = args
        return -a1, -a0
    if op == "abs":
        ((a0, a1),) = args
        lo = np.where(a0 > 0, a0, np.where(a1 < 0, -a1, 0.0))
        return lo, np.maximum(np.abs(a0), np.abs(a1))
    (a0, a1), (b0, b1) = args
    if op == "^":  # a real exponent b0 == b1 (a number): monotone over a base >= 0
        p = b0
        ok &= (a0 >= 0) & ((a0 > 0) | (p > 0))
        with np.errstate(all="ignore"):
            c0, c1 = np.power(np.maximum(a0, 0.0), p), np.power(np.maximum(a1, 0.0), p)
        lo, hi = np.minimum(c0, c1), np.maximum(c0, c1)
        # the evaluator's pow within 0.77 ulp, numpy's within 1: 4 u covers both
        return _down(lo * (1 - 4 * _UNIT)), _up(hi * (1 + 4 * _UNIT))
    if op in ("max", "min"):  # exact: no rounding
        f = np.maximum if op == "max" else np.minimum
        return f(a0, b0), f(a1, b1)
    if op == "+":
        return _down(a0 + b0), _up(a1 + b1)
    if op == "-":
        return _down(a0 - b1), _up(a1 - b0)
    if op == "/":
        ok &= (b0 > 0) | (b1 < 0)
        corners = np.stack([a0 / b0, a0 / b1, a1 / b0, a1 / b1])
        return _down(corners.min(axis=0)), _up(corners.max(axis=0))
    corners = np.stack([a0 * b0, a0 * b1, a1 * b0, a1 * b1])
    return _down(corners.min(axis=0)), _up(corners.max(axis=0))


# ----------------------------------------------------------------------------- polynomials


def _polynomials(tree: Expr) -> dict[int, dict | None]:
    """Every node's expansion (monomial exponents -> exact coefficient, as fractions), None
    where it is not a polynomial; with each, its roundings' count and ``P~``'s expansion."""
    out: dict[int, dict | None] = {}
    for node in postorder(tree):
        out[id(node)] = _expand(node, out)
    return out


def _expand(node: Expr, done: dict[int, dict | None]):
    op = node.op
    if op == "num":
        return {"p": {(0, 0, 0): Fraction(node.value)}, "a": {(0, 0, 0): Fraction(node.value)},
                "ops": 0}  # fmt: skip
    if op == "pi":
        v = Fraction(float(np.pi))
        return {"p": {(0, 0, 0): v}, "a": {(0, 0, 0): v}, "ops": 0}
    if op == "var":
        e = tuple(int(node.value == v) for v in "xyz")
        return {"p": {e: Fraction(1)}, "a": {e: Fraction(1)}, "ops": 0}
    kids = [done[id(a)] for a in node.args]
    if any(k is None for k in kids) or op not in ("+", "-", "*", "neg", "^"):
        return None
    if op == "neg":
        (k,) = kids
        return {"p": {e: -c for e, c in k["p"].items()}, "a": k["a"], "ops": k["ops"]}
    a, b = kids
    if op in ("+", "-"):
        p = _add(a["p"], b["p"], 1 if op == "+" else -1)
        return _checked(p, _add(a["a"], b["a"]), max(a["ops"], b["ops"]) + 1)
    if op == "*":
        if len(a["a"]) * len(b["a"]) > 4 * MAX_MONOMIALS or _degree(a) + _degree(b) > MAX_DEGREE:
            return None  # too long a product: left a product of two (not multiplied out)
        return _checked(_mul(a["p"], b["p"]), _mul(a["a"], b["a"]), max(a["ops"], b["ops"]) + 1)
    # a power: a whole exponent, from 0 up
    if set(b["p"]) != {(0, 0, 0)} or b["ops"]:
        return None
    k = b["p"][(0, 0, 0)]
    if k.denominator != 1 or not 0 <= k <= MAX_DEGREE:
        return None
    k = int(k)
    if k > 1 and (len(a["a"]) ** k > 4 * MAX_MONOMIALS or k * _degree(a) > MAX_DEGREE):
        return None
    p, q = {(0, 0, 0): Fraction(1)}, {(0, 0, 0): Fraction(1)}
    for _ in range(k):
        p, q = _mul(p, a["p"]), _mul(q, a["a"])
    return _checked(p, q, a["ops"] + 2 * max(k, 1))  # pow: within 0.77 ulp, counted as 2


def _degree(p: dict) -> int:
    """The largest power of one variable in ``p``."""
    return max((max(e) for e in p["a"]), default=0)


def _add(a: dict, b: dict, sign: int = 1) -> dict:
    """``a + sign * b`` (``P~``'s, whose coefficients are all >= 0, with sign 1)."""
    out = dict(a)
    for e, c in b.items():
        out[e] = out.get(e, 0) + sign * c
    return out


def _mul(a: dict, b: dict) -> dict:
    out: dict = {}
    for ea, ca in a.items():
        for eb, cb in b.items():
            e = (ea[0] + eb[0], ea[1] + eb[1], ea[2] + eb[2])
            out[e] = out.get(e, 0) + ca * cb
    return out


def _checked(p: dict, a: dict, ops: int):
    if len(p) > MAX_MONOMIALS or len(a) > MAX_MONOMIALS:
        return None
    if any(max(e) > MAX_DEGREE for e in a):
        return None
    return {"p": {e: c for e, c in p.items() if c}, "a": a, "ops": ops}


def _worth(p: dict) -> bool:
    """Three or more monomials of degree two or more, one of them of two variables or more: a
    sum of one-variable terms is bounded well term by term (each is a value of one axis)."""
    high = [e for e in p["p"] if sum(e) >= 2]
    return len(high) >= MIN_MONOMIALS and any(sum(1 for v in e if v) >= 2 for e in high)


def _polynomial(p: dict) -> Polynomial | None:
    def arrays(d: dict) -> tuple[np.ndarray, np.ndarray]:
        keys = sorted(d)
        exps = np.array(keys, dtype=np.int64).reshape(-1, 3)
        return exps, np.array([float(d[e]) for e in keys])

    exps, coefs = arrays(p["p"])
    taylor = taylor_pairs(exps, coefs)
    if taylor is None:
        return None
    abs_exps, abs_coefs = arrays(p["a"])
    absolute = (abs_exps, np.abs(abs_coefs), np.zeros(len(abs_exps), dtype=np.int64))
    return Polynomial(exps, coefs, absolute, p["ops"] + 1, taylor)


def _poly_bounds(p: Polynomial, lo: np.ndarray, hi: np.ndarray, threads: int = 1):
    """The bounds of the evaluator's value of ``p`` over each box (the module's docstring):
    its Taylor form at the box's centre c, ``Σ_β d_β t^β`` with ``|t_i| <= h_i``, each
    ``d_β`` computed with a bound on its rounding (:func:`~.interval_taylor.taylor_bounds`),
    in ``threads`` runs of boxes at once."""
    return taylor_bounds(p.taylor, p.absolute, p.ops, _UNIT, lo, hi, threads)
