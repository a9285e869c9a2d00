"""Equation (13) of the paper as a structured, JSON-serialisable model.

    F(x,y,z) = sum_i prod_m ( A/D * B/E * C/F ) - d

with, for each factor (m, i),

    A = P1^l1            D = P2^l2
    B = H(P3^l3)^mu1     E = H(P4^l4)^mu2
    C = G(H(P5^l5 / P6^l6))^mu3     F = G(H(P7^l7 / P8^l8))^mu4

where P1..P8 are power functions (eq. 8, ``sum a x^b y^c z^d``), H and G are direct or inverse
trigonometric functions (or, as the paper's conclusion suggests, constituent functions with
their parameters), and each of A..F may be replaced by its absolute value.

:meth:`Equation13.to_tree` builds the expression tree; printing it gives a formula a K3DSurf or
MathMod user can paste (when H and G are trigonometric). Trivial parts are left out of the tree
(``u^1``, ``/1``, a power function that is the constant 1) so printed formulas stay readable;
the value is unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from surfgen.generator.errors import SpecError
from surfgen.generator.formula.expr import Expr, add_all, call, mul_all, num, var

DIRECT_TRIG = ("sin", "cos", "tan", "cot", "sec", "csc")
INVERSE_TRIG = ("asin", "acos", "atan", "acot")
# Constituent functions usable as H or G, with the names of their constant parameters.
CONSTITUENT_TRANSFORMS: dict[str, tuple[str, ...]] = {
    "saw1": ("r", "p"),
    "tri1": ("r", "p"),
    "stair1": ("r", "h", "p"),
    "rect1": ("t",),
    "rect2": ("r", "t"),
    "rect3": ("t",),
    "saw2": ("r",),
    "tri2": ("r",),
    "tri3": ("r",),
    "stair2": ("r", "h"),
}
TRANSFORMS: dict[str, tuple[str, ...]] = {
    **{n: () for n in DIRECT_TRIG + INVERSE_TRIG},
    **CONSTITUENT_TRANSFORMS,
}
ELEMENTS = ("A", "B", "C", "D", "E", "F")


def _finite(name: str, v: float) -> float:
    v = float(v)
    if not math.isfinite(v):
        raise SpecError(f"eq13: {name} must be a finite number, got {v}")
    return v


@dataclass(frozen=True)
class PowerTerm:
    """One term ``a x^b y^c z^d`` of a power function."""

    a: float
    b: float = 0.0
    c: float = 0.0
    d: float = 0.0

    def __post_init__(self) -> None:
        a, b, c, d = float(self.a), float(self.b), float(self.c), float(self.d)
        if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(c) and math.isfinite(d)):
            for k, v in zip("abcd", (a, b, c, d), strict=True):  # the first one named
                _finite(f"power term {k}", v)
        set_field = object.__setattr__  # frozen: the fields as floats (a draw makes hundreds)
        set_field(self, "a", a)
        set_field(self, "b", b)
        set_field(self, "c", c)
        set_field(self, "d", d)


class _KeptTrees:
    """What a frozen equation object builds from its fields once and keeps in its
    ``__dict__`` under names starting ``_kept_``: not fields (not compared, not printed), and
    not pickled (a worker rebuilds them where it needs them)."""

    def _kept(self, name: str, build: Callable[[], Any]) -> Any:
        kept = self.__dict__.get(name)
        if kept is None:
            kept = self.__dict__[name] = build()
        return kept

    def __getstate__(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if not k.startswith("_kept_")}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)


@dataclass(frozen=True)
class PowerFunction(_KeptTrees):
    """Eq. (8): ``sum a x^b y^c z^d``; with ``absolute`` the variables are ``|x|, |y|, |z|``
    (as in the paper's examples, which keeps real exponents of negative bases defined)."""

    terms: tuple[PowerTerm, ...]
    absolute: bool = False

    def __post_init__(self) -> None:
        if not self.terms:
            raise SpecError("eq13: a power function needs at least one term")
        object.__setattr__(self, "terms", tuple(self.terms))

    @classmethod
    def constant(cls, value: float = 1.0) -> PowerFunction:
        return cls((PowerTerm(value),))

    def is_one(self) -> bool:
        if len(self.terms) != 1:
            return False
        t = self.terms[0]
        return t.a == 1.0 and t.b == 0.0 and t.c == 0.0 and t.d == 0.0

    def to_tree(self) -> Expr:
        """The sum, written with ``-`` for negative coefficients after the first term. Built
        once and kept (a factor reads its power functions again for every element and every
        check of the families that draw it)."""
        return self._kept("_kept_tree", self._build_tree)

    def _build_tree(self) -> Expr:
        bases = _ABS_BASES if self.absolute else _BASES
        out: Expr | None = None
        for t in self.terms:
            if out is None:  # a leading minus binds to the coefficient: "-1.5*x^2"
                out = _term_tree(t.a, t, bases)
            else:
                term = _term_tree(abs(t.a), t, bases)
                out = out - term if t.a < 0 else out + term
        return out  # type: ignore[return-value]


_BASES = {name: var(name) for name in "xyz"}
_ABS_BASES = {name: call("abs", var(name)) for name in "xyz"}


def _term_tree(a: float, t: PowerTerm, bases: dict[str, Expr]) -> Expr:
    """``a x^b y^c z^d`` of the term ``t`` with the coefficient ``a`` (``bases``: the
    variables, or their absolute values): factors with exponent 0 left out, exponents 1 and
    coefficient 1 not written."""
    factors: list[Expr] = []
    for name, e in (("x", t.b), ("y", t.c), ("z", t.d)):
        if e == 0:
            continue
        base = bases[name]
        factors.append(base if e == 1 else Expr("^", (base, num(e))))
    if not factors:
        return num(a)
    if a == 1:
        return mul_all(factors)
    return mul_all([num(a), *factors])


@dataclass(frozen=True)
class Transform:
    """H_t or G_t: a function name of :data:`TRANSFORMS` and its constant parameters."""

    name: str
    params: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if self.name not in TRANSFORMS:
            raise SpecError(
                f"eq13: unknown transform '{self.name}' (allowed: {', '.join(TRANSFORMS)})"
            )
        want = TRANSFORMS[self.name]
        if len(self.params) != len(want):
            raise SpecError(
                f"eq13: {self.name} takes {len(want)} parameter(s) "
                f"({', '.join(want) or 'none'}), got {len(self.params)}"
            )
        object.__setattr__(
            self, "params", tuple(_finite(f"{self.name} parameter", p) for p in self.params)
        )

    def apply(self, arg: Expr) -> Expr:
        return call(self.name, arg, *self.params)


def _power(base: Expr, exponent: float) -> Expr:
    return base if exponent == 1 else Expr("^", (base, num(exponent)))


@dataclass(frozen=True)
class Factor(_KeptTrees):
    """One factor (m, i) of eq. (13): ``A/D * B/E * C/F``."""

    powers: tuple[PowerFunction, ...]  # P1..P8
    lambdas: tuple[float, ...]  # l1..l8
    mus: tuple[float, ...]  # mu1..mu4
    h: Transform
    g: Transform
    absolute: tuple[bool, ...] = (False,) * 6  # A, B, C, D, E, F

    def __post_init__(self) -> None:
        for name, seq, n in (
            ("powers", self.powers, 8),
            ("lambdas", self.lambdas, 8),
            ("mus", self.mus, 4),
            ("absolute", self.absolute, 6),
        ):
            if len(seq) != n:
                raise SpecError(f"eq13: a factor needs {n} {name}, got {len(seq)}")
        object.__setattr__(self, "powers", tuple(self.powers))
        object.__setattr__(self, "lambdas", tuple(_finite("lambda", v) for v in self.lambdas))
        object.__setattr__(self, "mus", tuple(_finite("mu", v) for v in self.mus))
        object.__setattr__(self, "absolute", tuple(bool(v) for v in self.absolute))

    def _p(self, k: int) -> Expr:
        """``P_k ^ lambda_k`` for k = 1..8 (``1`` when lambda_k is 0), built once and kept."""
        kept = self._kept("_kept_powers", dict)
        tree = kept.get(k)
        if tree is None:
            if self.lambdas[k - 1] == 0:
                tree = num(1.0)
            else:
                tree = _power(self.powers[k - 1].to_tree(), self.lambdas[k - 1])
            kept[k] = tree
        return tree

    def _trivial(self, k: int) -> bool:
        return self.powers[k - 1].is_one() or self.lambdas[k - 1] == 0

    def elements(self) -> dict[str, Expr | None]:
        """A..F as trees; ``None`` for an element that is identically 1: a power function that
        is the constant 1, or an exponent 0 (C's ``pow(u, 0)`` is 1 even for NaN u)."""
        h, g, mu, lam = self.h, self.g, self.mus, self.lambdas
        out: dict[str, Expr | None] = {
            "A": None if self._trivial(1) or lam[0] == 0 else self._p(1),
            "D": None if self._trivial(2) or lam[1] == 0 else self._p(2),
            "B": None if mu[0] == 0 else _power(h.apply(self._p(3)), mu[0]),
            "E": None if mu[1] == 0 else _power(h.apply(self._p(4)), mu[1]),
            "C": None if mu[2] == 0 else _power(g.apply(h.apply(self._ratio(5, 6))), mu[2]),
            "F": None if mu[3] == 0 else _power(g.apply(h.apply(self._ratio(7, 8))), mu[3]),
        }
        for name, flag in zip(ELEMENTS, self.absolute, strict=True):
            if flag and out[name] is not None:
                out[name] = call("abs", out[name])
        return out

    def h_arguments(self) -> tuple[tuple[str, Expr], ...]:
        """The arguments of H in the factor's B, E, C and F (those not left out), with the
        element's name: ``P3^l3``, ``P4^l4``, ``P5^l5/P6^l6``, ``P7^l7/P8^l8`` (what the
        resolution bound samples)."""
        args = (self._p(3), self._p(4), self._ratio(5, 6), self._ratio(7, 8))
        return tuple(
            (name, a) for name, a, mu in zip("BECF", args, self.mus, strict=True) if mu != 0
        )

    def _ratio(self, top: int, bottom: int) -> Expr:
        return self._p(top) if self._trivial(bottom) else self._p(top) / self._p(bottom)

    def to_tree(self) -> Expr:
        """``(A/D * B/E) * C/F`` leaving out the elements that are identically 1.

        Built once per factor and kept: the copies of a factor in many products (a sampled
        ornament under a power) are then one tree, which the compiler lowers once."""
        return self._kept("_kept_tree", self._build_tree)

    def _build_tree(self) -> Expr:
        e = self.elements()
        out: Expr | None = None
        for top, bottom in (("A", "D"), ("B", "E"), ("C", "F")):
            part = e[top]
            if e[bottom] is not None:
                part = (num(1.0) if part is None else part) / e[bottom]
            if part is not None:
                out = part if out is None else out * part
        return num(1.0) if out is None else out


@dataclass(frozen=True)
class Equation13:
    """``sum_i prod_m factor(m, i) - d``; ``terms[i][m]`` is the factor (m, i)."""

    terms: tuple[tuple[Factor, ...], ...]
    d: float = 0.0

    def __post_init__(self) -> None:
        if not self.terms or any(not t for t in self.terms):
            raise SpecError("eq13: needs at least one sum term, each with at least one factor")
        object.__setattr__(self, "terms", tuple(tuple(t) for t in self.terms))
        object.__setattr__(self, "d", _finite("d", self.d))

    def body(self) -> Expr:
        """The sum of products, without ``- d``."""
        return add_all([mul_all([f.to_tree() for f in prod]) for prod in self.terms])

    def to_tree(self) -> Expr:
        s = self.body()
        if self.d == 0:
            return s
        return s - num(self.d) if self.d > 0 else s + num(-self.d)

    def with_d(self, d: float) -> Equation13:
        return Equation13(self.terms, d)

    # -- JSON
    def to_dict(self) -> dict[str, Any]:
        return {"terms": [[_factor_to_dict(f) for f in prod] for prod in self.terms], "d": self.d}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Equation13:
        try:
            terms = tuple(tuple(_factor_from_dict(f) for f in prod) for prod in data["terms"])
            return cls(terms, float(data.get("d", 0.0)))
        except (KeyError, TypeError, ValueError) as exc:
            raise SpecError(f"eq13: malformed model ({exc})") from None


def _factor_to_dict(f: Factor) -> dict[str, Any]:
    return {
        "P": [
            {"terms": [[t.a, t.b, t.c, t.d] for t in p.terms], "absolute": p.absolute}
            for p in f.powers
        ],
        "lambda": list(f.lambdas),
        "mu": list(f.mus),
        "H": {"name": f.h.name, "params": list(f.h.params)},
        "G": {"name": f.g.name, "params": list(f.g.params)},
        "abs": list(f.absolute),
    }


def _factor_from_dict(d: Mapping[str, Any]) -> Factor:
    powers = tuple(
        PowerFunction(tuple(PowerTerm(*t) for t in p["terms"]), bool(p.get("absolute", False)))
        for p in d["P"]
    )
    return Factor(
        powers=powers,
        lambdas=tuple(d["lambda"]),
        mus=tuple(d["mu"]),
        h=Transform(d["H"]["name"], tuple(d["H"].get("params", ()))),
        g=Transform(d["G"]["name"], tuple(d["G"].get("params", ()))),
        absolute=tuple(d.get("abs", (False,) * 6)),
    )
