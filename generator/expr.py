"""Formulas as data: a small immutable expression tree and its canonical printer.

A tree is made of :class:`Expr` nodes. ``op`` is one of

- ``"num"``: a literal, ``value`` is a finite float **>= 0** (a minus sign is always a ``neg`` node,
  so that printing and parsing are exact inverses);
- ``"var"``: ``value`` is ``"x"``, ``"y"`` or ``"z"``;
- ``"param"``: a named parameter, ``value`` is its name (bound to a number at evaluation);
- ``"pi"``: the constant pi;
- ``"neg"`` and ``"not"`` (one argument; ``not`` prints as ``!``), ``"+" "-" "*" "/" "^"`` and
  MathMod's ``"%" "<" "<=" ">" ">=" "=" "!=" "&" "|"`` (two arguments; meaning in
  :mod:`surfgen.generator.logic`);
- the name of a function of :mod:`surfgen.generator.functions` (``"sin"``, ``"saw1"``, ...).

Nodes are frozen and hashable, so identical sub-trees compare equal and can be shared.
The printer writes K3DSurf/MathMod syntax: ``^`` is right-associative and binds tighter than
unary minus (``-x^2`` is ``-(x^2)``), so a printed formula can be pasted into those programs
(the constituent functions are surfgen built-ins; ``expand_builtins`` is not needed to paste the
trigonometric ones).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

VARIABLES = ("x", "y", "z")
BINARY_OPS = ("+", "-", "*", "/", "^", "%", "<", "<=", ">", ">=", "=", "!=", "&", "|")
UNARY_OPS = ("neg", "not")
LEAF_OPS = ("num", "var", "param", "pi")

# Binding strength used by the printer; the parser implements the same grammar (fparser's).
_PREC_OR, _PREC_AND, _PREC_CMP, _PREC_ADD, _PREC_MUL, _PREC_NEG, _PREC_POW, _PREC_ATOM = range(1, 9)
_BINARY_PREC = {
    "|": _PREC_OR,
    "&": _PREC_AND,
    **dict.fromkeys(("<", "<=", ">", ">=", "=", "!="), _PREC_CMP),
    "+": _PREC_ADD,
    "-": _PREC_ADD,
    "*": _PREC_MUL,
    "/": _PREC_MUL,
    "%": _PREC_MUL,
    "^": _PREC_POW,
}
_UNARY_TEXT = {"neg": "-", "not": "!"}


@dataclass(frozen=True, slots=True)
class Expr:
    """One node of a formula tree (see the module docstring for the meaning of ``op``)."""

    op: str
    args: tuple[Expr, ...] = ()
    value: float | str | None = None

    def __post_init__(self) -> None:
        if self.op == "num":
            v = self.value
            if not isinstance(v, float) or not math.isfinite(v) or v < 0:
                raise ValueError(f"num node needs a finite float >= 0, got {v!r}")
            if v == 0.0:  # fold -0.0 so equal trees print equally
                object.__setattr__(self, "value", 0.0)

    def __str__(self) -> str:
        return to_string(self)

    def __repr__(self) -> str:
        return f"Expr<{to_string(self)}>"

    # Operator sugar so that builders read like the paper.
    def __add__(self, other: Expr | float) -> Expr:
        return Expr("+", (self, as_expr(other)))

    def __radd__(self, other: float) -> Expr:
        return Expr("+", (as_expr(other), self))

    def __sub__(self, other: Expr | float) -> Expr:
        return Expr("-", (self, as_expr(other)))

    def __rsub__(self, other: float) -> Expr:
        return Expr("-", (as_expr(other), self))

    def __mul__(self, other: Expr | float) -> Expr:
        return Expr("*", (self, as_expr(other)))

    def __rmul__(self, other: float) -> Expr:
        return Expr("*", (as_expr(other), self))

    def __truediv__(self, other: Expr | float) -> Expr:
        return Expr("/", (self, as_expr(other)))

    def __rtruediv__(self, other: float) -> Expr:
        return Expr("/", (as_expr(other), self))

    def __pow__(self, other: Expr | float) -> Expr:
        return Expr("^", (self, as_expr(other)))

    def __neg__(self) -> Expr:
        return Expr("neg", (self,))


# ----------------------------------------------------------------------------- builders


def num(value: float) -> Expr:
    """A literal; negative values become ``neg(num(|value|))``."""
    value = float(value)
    if value < 0:
        return Expr("neg", (Expr("num", (), -value),))
    return Expr("num", (), value)


def as_expr(value: Expr | float | int) -> Expr:
    return value if isinstance(value, Expr) else num(value)


def var(name: str) -> Expr:
    if name not in VARIABLES:
        raise ValueError(f"unknown variable {name!r}")
    return Expr("var", (), name)


def param(name: str) -> Expr:
    return Expr("param", (), name)


def call(name: str, *args: Expr | float) -> Expr:
    return Expr(name, tuple(as_expr(a) for a in args))


def add_all(terms: list[Expr]) -> Expr:
    """Left-folded sum of one or more terms."""
    if not terms:
        raise ValueError("add_all needs at least one term")
    out = terms[0]
    for t in terms[1:]:
        out = Expr("+", (out, t))
    return out


def mul_all(factors: list[Expr]) -> Expr:
    """Left-folded product of one or more factors."""
    if not factors:
        raise ValueError("mul_all needs at least one factor")
    out = factors[0]
    for f in factors[1:]:
        out = Expr("*", (out, f))
    return out


PI = Expr("pi")
X, Y, Z = var("x"), var("y"), var("z")


# ----------------------------------------------------------------------------- queries


def walk(tree: Expr) -> Iterator[Expr]:
    """Every node, parents before children (with repetitions for shared sub-trees)."""
    stack = [tree]
    while stack:
        node = stack.pop()
        yield node
        stack.extend(reversed(node.args))


def variables_of(tree: Expr) -> frozenset[str]:
    return frozenset(n.value for n in walk(tree) if n.op == "var")  # type: ignore[misc]


def params_of(tree: Expr) -> frozenset[str]:
    return frozenset(n.value for n in walk(tree) if n.op == "param")  # type: ignore[misc]


def substitute_params(tree: Expr, values: Mapping[str, float]) -> Expr:
    """Replace every ``param`` node named in ``values`` by its number."""
    memo: dict[Expr, Expr] = {}

    def sub(node: Expr) -> Expr:
        if node in memo:
            return memo[node]
        if node.op == "param" and node.value in values:
            out = num(values[node.value])  # type: ignore[index]
        elif node.args:
            out = Expr(node.op, tuple(sub(a) for a in node.args), node.value)
        else:
            out = node
        memo[node] = out
        return out

    return sub(tree)


# ----------------------------------------------------------------------------- printing


def format_number(value: float) -> str:
    """Shortest text that parses back to exactly ``value`` (integers without ``.0``)."""
    if value.is_integer() and value < 1e15:
        return str(int(value))
    return repr(value)


def _prec(node: Expr) -> int:
    if node.op in _BINARY_PREC:
        return _BINARY_PREC[node.op]
    if node.op in _UNARY_TEXT:
        return _PREC_NEG
    return _PREC_ATOM


def to_string(tree: Expr) -> str:
    """Canonical K3DSurf/MathMod text of ``tree``; ``parse(to_string(t)) == t``."""
    op = tree.op
    if op == "num":
        return format_number(tree.value)  # type: ignore[arg-type]
    if op in ("var", "param"):
        return str(tree.value)
    if op == "pi":
        return "pi"
    if op in _UNARY_TEXT:
        (a,) = tree.args
        # '-' applies to a power or an atom without parentheses; '-(-x)' keeps them for clarity.
        inner = to_string(a)
        return _UNARY_TEXT[op] + (inner if _prec(a) >= _PREC_POW else f"({inner})")
    if op in _BINARY_PREC:
        a, b = tree.args
        p = _BINARY_PREC[op]
        if op == "^":  # right-associative: base needs an atom, exponent may be a power or neg
            left = _wrap(a, _PREC_ATOM)
            right = _wrap(b, _PREC_NEG) if b.op not in _UNARY_TEXT else _wrap(b, _PREC_POW)
        else:  # left-associative: the right operand needs strictly higher precedence
            left = _wrap(a, p)
            right = f"({to_string(b)})" if b.op in _UNARY_TEXT else _wrap(b, p + 1)
        return f"{left}{op}{right}"
    return f"{op}({','.join(to_string(a) for a in tree.args)})"


def _wrap(node: Expr, min_prec: int) -> str:
    text = to_string(node)
    return text if _prec(node) >= min_prec else f"({text})"
