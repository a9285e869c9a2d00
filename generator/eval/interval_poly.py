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
joining them** (``+ - * / neg abs max min``, a power with a real exponent, and numbers). :func:`polynomial_bounds` bounds a box:

- a polynomial P by its Taylor form at the box's centre c: ``P(c + t) = Σ_β d_β t^β`` with
  ``|t_i| <= h_i`` (a ``t^β`` of even powers only is ``>= 0``), each ``d_β`` (a sum of
  ``c_α binom(α, β) c^(α-β)``, exact in its coefficients) computed in floats with a bound on
  its rounding; then the evaluator's value of P, which rounds each of the n operations on a
  path, by ``γ_n · P~(|x|)`` more (``P~``: the tree with every number's magnitude, every
  ``-`` a ``+``: the forward error bound of a sum of products whatever the order and
  contractions, Higham 2002, §3.1), ``P~`` at the box's largest ``|x|, |y|, |z|``;
- a part by the base bounds (over the grid's points: a value of one axis exactly);
- a sum holding ``U cos θ + V sin θ`` (a twist's lobes) by its terms' bounds with each such
  pair bounded as one wave (:mod:`~surfgen.generator.eval.interval_harmonic`);
- the joining operations as intervals, each end moved one place outward (so each holds the
  exact and the rounded result of any values within its operands); a real power by its ends'
  powers (monotone over a base >= 0, which it needs), four units in the last place outward.

Every value the evaluator computes at a point of the box is then within the bound where every
part's and polynomial's bound is finite, the divisors' exclude 0 and the real powers' bases
are not negative (and positive below a negative exponent); there F is finite too. A box where
that fails keeps the formula's own bounds. The polynomials' Taylor shifts are
bounded in :data:`MAX_PAIRS` pairs (a product of polynomials longer than that stays a product
of two); the structure is used only on boxes the base bounds leave undecided, and given up
where it decides next to none. The points sampled are the same; only fewer blocks are left to
sample.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
from numba import njit

from surfgen.generator.eval.compiler import Program, compile_tree
from surfgen.generator.eval.interval_harmonic import in_chains, sum_bounds, sum_terms
from surfgen.generator.eval.leaf_states import Bounds
from surfgen.generator.eval.tape import run_at_once
from surfgen.generator.formula.expr import Expr, postorder
from surfgen.generator.jit.options import KERNEL

#: The largest power of one variable in a polynomial, and the most monomials it may have.
MAX_DEGREE = 16
MAX_MONOMIALS = 200
#: The most pairs of a polynomial's Taylor shift (monomial α, β <= α): its cost a box.
MAX_PAIRS = 1024
#: A polynomial is worth its Taylor form from this many monomials of degree 2 or more.
MIN_MONOMIALS = 3
_UNIT = 2.0**-53
#: The structure is given up once a call of this many boxes or more finds it deciding fewer
#: than this share of those its base bounds leave undecided.
TRIAL_BOXES = 2048
MIN_DECIDED = 0.05
#: Boxes a thread takes at least in a polynomial's bounds.
THREAD_BOXES = 4096
#: Parts' bounds at or beyond this are not used (no operation on them overflows).
LIMIT = 1e150

__all__ = ["Structure", "polynomial_bounds", "polynomial_structure"]

_JOINS = ("+", "-", "*", "/", "neg", "abs", "max", "min")


@dataclass(frozen=True)
class Polynomial:
    """An expanded polynomial: ``coefs[m] * x^exps[m,0] * y^exps[m,1] * z^exps[m,2]``, the
    coefficients of its exact expansion rounded; ``absolute`` the same for ``P~``; ``ops`` the
    roundings on its longest path (the expansion's rounding of the coefficients included);
    ``taylor`` its Taylor shift's pairs (:func:`_taylor`)."""

    exps: np.ndarray
    coefs: np.ndarray
    absolute: tuple[np.ndarray, np.ndarray]
    ops: int
    taylor: tuple[np.ndarray, ...]  # :func:`_taylor`


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
    terms = in_chains(order)
    for node in order:
        inside[id(node)] = id(node) in made or any(inside[id(a)] for a in node.args)
        wave = None
        if inside[id(node)] and id(node) not in terms and node.op in ("+", "-"):
            wave = sum_terms(node, made.keys())  # a whole sum holding U cos θ + V sin θ
        if id(node) in made:
            nodes.append(("poly", made[id(node)], ()))
        elif wave is not None:
            nodes.append(("sum", wave[0], tuple(index[id(a)] for a in wave[1])))
        elif node.op == "num":
            nodes.append(("num", float(node.value), ()))
        elif inside[id(node)] and (node.op in _JOINS or _real_power(node)):
            nodes.append((node.op, None, tuple(index[id(a)] for a in node.args)))
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
            else:
                vlo, vhi = _join(kind, [vals[k] for k in kids], ok)
            ok &= np.isfinite(vlo) & np.isfinite(vhi) & (vlo <= vhi)
            ok &= (np.abs(vlo) < LIMIT) & (np.abs(vhi) < LIMIT)
            vals[i] = (vlo, vhi)
    flo, fhi = vals[len(structure.nodes) - 1]
    return flo, fhi, ok


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
    taylor = _taylor(exps, coefs)
    if taylor is None:
        return None
    return Polynomial(exps, coefs, arrays(p["a"]), p["ops"] + 1, taylor)


def _taylor(exps: np.ndarray, coefs: np.ndarray) -> tuple[np.ndarray, ...] | None:
    """The Taylor shift's pairs: for each monomial α and β <= α, the coefficient
    ``c_α · Π binom(α_i, β_i)`` (P,), the power ``α - β`` of the centre (P, 3), where each β's
    pairs start (B,) and the β's (B, 3); None beyond :data:`MAX_PAIRS`."""
    if int(np.prod(exps + 1, axis=1).sum()) > MAX_PAIRS:
        return None
    coef, expo, into, betas = [], [], [], {}
    for e, c in zip(exps.tolist(), coefs.tolist(), strict=True):
        for b0 in range(e[0] + 1):
            for b1 in range(e[1] + 1):
                for b2 in range(e[2] + 1):
                    k = math.comb(e[0], b0) * math.comb(e[1], b1) * math.comb(e[2], b2)
                    coef.append(c * k)
                    expo.append((e[0] - b0, e[1] - b1, e[2] - b2))
                    into.append(betas.setdefault((b0, b1, b2), len(betas)))
    order = np.argsort(np.array(into), kind="stable")  # each β's pairs together
    into_arr = np.array(into, dtype=np.int64)[order]
    starts = np.flatnonzero(np.r_[True, into_arr[1:] != into_arr[:-1]])
    return (np.array(coef)[order], np.array(expo, dtype=np.int64).reshape(-1, 3)[order],
            starts, np.array(list(betas), dtype=np.int64).reshape(-1, 3))  # fmt: skip


def _poly_bounds(p: Polynomial, lo: np.ndarray, hi: np.ndarray, threads: int = 1):
    """The bounds of the evaluator's value of ``p`` over each box (the module's docstring):
    its Taylor form at the box's centre c, ``Σ_β d_β t^β`` with ``|t_i| <= h_i``, each
    ``d_β`` computed with a bound on its rounding (:func:`_taylor_kernel`), in ``threads`` runs
    of boxes at once."""
    coef, expo, starts, betas = p.taylor
    out_lo, out_hi = np.empty(len(lo)), np.empty(len(lo))
    abs_exps, abs_coefs = p.absolute
    abs_coefs = np.abs(abs_coefs)
    runs = max(1, min(int(threads), len(lo) // THREAD_BOXES))
    cuts = [len(lo) * r // runs for r in range(runs + 1)]

    def run(r: int) -> None:
        v = slice(cuts[r], cuts[r + 1])
        _taylor_kernel(coef, expo, starts, betas, abs_exps, abs_coefs, float(p.ops), _UNIT, lo[v],
                       hi[v], out_lo[v], out_hi[v])  # fmt: skip

    run_at_once([functools.partial(run, r) for r in range(runs)])
    return out_lo, out_hi


#: Boxes a Taylor kernel's inner loops run over at once (the compiler vectorises them).
CHUNK = 32


@njit(**KERNEL)
def _powers_of(lo, hi, k0, m, cp, hp, tp):
    """Boxes ``k0:k0+m``'s powers ``j < MAX_DEGREE + 1`` (by repeated products: j roundings
    each) of their centre ``c`` (``cp[a, j, k]``), half-width ``h`` (rounded up: ``hp``) and
    largest ``|x|`` (``tp``), per axis a."""
    for a in range(3):
        for k in range(m):
            c = (lo[k0 + k, a] + hi[k0 + k, a]) / 2
            h = max(
                np.nextafter(hi[k0 + k, a] - c, np.inf), np.nextafter(c - lo[k0 + k, a], np.inf)
            )
            t = max(abs(lo[k0 + k, a]), abs(hi[k0 + k, a]))
            cp[a, 0, k] = hp[a, 0, k] = tp[a, 0, k] = 1.0
            for j in range(1, MAX_DEGREE + 1):
                cp[a, j, k] = cp[a, j - 1, k] * c
                hp[a, j, k] = hp[a, j - 1, k] * h
                tp[a, j, k] = tp[a, j - 1, k] * t


@njit(**KERNEL)
def _taylor_kernel(coef, expo, starts, betas, abs_exps, abs_coefs, ops, u, lo, hi, out_lo, out_hi):
    """Per box: ``Σ_β d_β t^β`` over ``|t| <= h`` around ``c``, plus the roundings of the
    ``d_β`` (``4 (P + 56) u`` of their terms' magnitudes: each term ``3 MAX_DEGREE + 3``
    roundings at most, each sum P), of the reach ``h^β`` and of the sums (``slack``), and the
    evaluator's rounding of P (``2 (ops + 2) u P~(|x|)``). The boxes are taken :data:`CHUNK` at
    a time, each pair's term computed for all of them in one loop (the same operations, in
    the same order, for each box: twist-0's 636 pairs 5 -> 0.8 microseconds a box)."""
    n_pairs, n_betas = coef.shape[0], betas.shape[0]
    cp = np.empty((3, MAX_DEGREE + 1, CHUNK))
    hp = np.empty((3, MAX_DEGREE + 1, CHUNK))
    tp = np.empty((3, MAX_DEGREE + 1, CHUNK))
    sums = np.empty((6, CHUNK))  # the sums' low and high ends, magnitude, d, size, P~
    sum_lo, sum_hi, mag, d, size, p_abs = sums[0], sums[1], sums[2], sums[3], sums[4], sums[5]
    rel = 4.0 * (n_pairs + 3 * MAX_DEGREE + 8) * u
    for k0 in range(0, lo.shape[0], CHUNK):
        m = min(CHUNK, lo.shape[0] - k0)
        _powers_of(lo, hi, k0, m, cp, hp, tp)
        sums[:3] = 0.0
        for b in range(n_betas):
            d[:] = 0.0
            size[:] = 0.0
            for q in range(starts[b], starts[b + 1] if b + 1 < n_betas else n_pairs):
                cq, c0, c1, c2 = coef[q], cp[0, expo[q, 0]], cp[1, expo[q, 1]], cp[2, expo[q, 2]]
                for k in range(m):
                    t = cq * c0[k] * c1[k] * c2[k]
                    d[k] += t
                    size[k] += abs(t)
            b0, b1, b2 = betas[b, 0], betas[b, 1], betas[b, 2]
            centre = b0 == 0 and b1 == 0 and b2 == 0
            even = b0 % 2 == 0 and b1 % 2 == 0 and b2 % 2 == 0
            h0, h1, h2 = hp[0, b0], hp[1, b1], hp[2, b2]
            for k in range(m):
                err = rel * size[k]
                if centre:
                    tlo, thi = d[k] - err, d[k] + err
                else:
                    reach = h0[k] * h1[k] * h2[k] * (1.0 + 64.0 * u)
                    low = 0.0 if even else -reach
                    if d[k] >= 0:
                        tlo, thi = d[k] * low - err * reach, d[k] * reach + err * reach
                    else:
                        tlo, thi = d[k] * reach - err * reach, d[k] * low + err * reach
                sum_lo[k] += tlo
                sum_hi[k] += thi
                mag[k] += abs(tlo) + abs(thi)
        p_abs[:] = 0.0
        for q in range(abs_exps.shape[0]):
            ac = abs_coefs[q]
            t0, t1, t2 = tp[0, abs_exps[q, 0]], tp[1, abs_exps[q, 1]], tp[2, abs_exps[q, 2]]
            for k in range(m):
                p_abs[k] += ac * t0[k] * t1[k] * t2[k]
        for k in range(m):
            slack = 4.0 * (n_betas + 4) * u * mag[k]
            err_p = 2.0 * (ops + 2.0) * u * p_abs[k] * (1.0 + 4.0 * (abs_exps.shape[0] + 56) * u)
            out_lo[k0 + k] = np.nextafter(sum_lo[k] - slack - err_p, -np.inf)
            out_hi[k0 + k] = np.nextafter(sum_hi[k] + slack + err_p, np.inf)
