"""Formulas as data: a small immutable expression tree and its canonical printer.

A tree is made of :class:`Expr` nodes. ``op`` is one of

- ``"num"``: a literal, ``value`` is a finite float **>= 0** (a minus sign is always a ``neg`` node,
  so that printing and parsing are exact inverses);
- ``"var"``: ``value`` is ``"x"``, ``"y"`` or ``"z"``;
- ``"param"``: a named parameter, ``value`` is its name (bound to a number at evaluation);
- ``"pi"``: the constant pi;
- ``"neg"`` and ``"not"`` (one argument; ``not`` prints as ``!``), ``"+" "-" "*" "/" "^"`` and
  MathMod's ``"%" "<" "<=" ">" ">=" "=" "!=" "&" "|"`` (two arguments; meaning in
  :mod:`surfgen.generator.formula.logic`);
- the name of a function of :mod:`surfgen.generator.formula.functions` (``"sin"``, ``"saw1"``, ...).

Nodes are frozen and hashable, so identical sub-trees compare equal and can be shared.
The printer writes K3DSurf/MathMod syntax: ``^`` is right-associative and binds tighter than
unary minus (``-x^2`` is ``-(x^2)``), so a printed formula can be pasted into those programs
(the constituent functions are surfgen built-ins; ``expand_builtins`` is not needed to paste the
trigonometric ones).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field

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
    # The hash, computed once from the children's: hashing and comparing a tree never recurse,
    # so a 20,000-term flat sum (a left-deep tree) is as safe as a short formula.
    _hash: int = field(default=0, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.op == "num":
            v = self.value
            if not isinstance(v, float) or not math.isfinite(v) or v < 0:
                raise ValueError(f"num node needs a finite float >= 0, got {v!r}")
            if v == 0.0:  # fold -0.0 so equal trees print equally
                object.__setattr__(self, "value", 0.0)
        object.__setattr__(
            self, "_hash", hash((self.op, self.value, *(a._hash for a in self.args)))
        )

    def __hash__(self) -> int:
        return self._hash

    def __eq__(self, other: object) -> bool:
        if self is other:
            return True
        if not isinstance(other, Expr):
            return NotImplemented
        if not self.args or not other.args:  # a leaf (most comparisons): no walk to set up
            return (
                self._hash == other._hash
                and self.op == other.op
                and self.value == other.value
                and self.args == other.args
            )
        stack, seen = [(self, other)], set()
        while stack:  # iterative: deep trees compare without recursion
            a, b = stack.pop()
            if a is b or (id(a), id(b)) in seen:
                continue
            seen.add((id(a), id(b)))
            if a._hash != b._hash or a.op != b.op or a.value != b.value:
                return False
            if len(a.args) != len(b.args):
                return False
            stack.extend(zip(a.args, b.args, strict=True))
        return True

    def __reduce__(self):  # rebuild through __init__: the cached hash is per process
        return (Expr, (self.op, self.args, self.value))

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
    """The variable ``name``: one node per variable, shared by every tree (a tree's nodes are
    immutable; walks and comparisons then find a variable met again by identity)."""
    leaf = _VARIABLE_LEAVES.get(name)
    if leaf is None:
        raise ValueError(f"unknown variable {name!r}")
    return leaf


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
_VARIABLE_LEAVES = {name: Expr("var", (), name) for name in VARIABLES}
X, Y, Z = var("x"), var("y"), var("z")


# ----------------------------------------------------------------------------- queries


def walk(tree: Expr) -> Iterator[Expr]:
    """Every node, parents before children (with repetitions for shared sub-trees)."""
    stack = [tree]
    while stack:
        node = stack.pop()
        yield node
        stack.extend(reversed(node.args))


def postorder(tree: Expr, by_value: bool = False) -> list[Expr]:
    """Each distinct node once, children before parents, without recursion: distinct by
    identity, or with ``by_value`` by value (a copy of a sub-tree already listed is skipped
    whole, its root compared once).

    Consumers that memoise per node (the compiler, the reference evaluator) visit this list
    first, so their own recursion never goes deeper than one level.
    """
    out: list[Expr] = []
    stack: list[tuple[Expr, bool]] = [(tree, False)]
    if by_value:  # the nodes themselves in the set: equal sub-trees are one
        seen: set = set()
        while stack:
            node, done = stack.pop()
            if done:
                out.append(node)
            elif node not in seen:
                seen.add(node)
                stack.append((node, True))
                stack.extend([(a, False) for a in reversed(node.args) if a not in seen])
        return out
    ids: set[int] = set()  # the same loop on identities (no equality walked)
    while stack:
        node, done = stack.pop()
        if done:
            out.append(node)
        elif id(node) not in ids:
            ids.add(id(node))
            stack.append((node, True))
            stack.extend([(a, False) for a in reversed(node.args) if id(a) not in ids])
    return out


def tree_size(tree: Expr) -> int:
    """Nodes of the tree as written out (a shared sub-tree counts once per place it stands):
    the size of its canonical text, counted in time linear in the *distinct* nodes. A function
    inlined many times (MathMod's ``Funct``) shares its sub-trees, so this can be far more than
    ``len(postorder(tree))``; it is what printing, parsing the printed form and every walk with
    repetitions cost."""
    size: dict[int, int] = {}
    for node in postorder(tree):
        size[id(node)] = 1 + sum(size[id(a)] for a in node.args)
    return size[id(tree)]


def depth_of(tree: Expr) -> int:
    """Nodes on the longest path from the root to a leaf (1 for a leaf)."""
    depth: dict[int, int] = {}
    for node in postorder(tree):
        depth[id(node)] = 1 + max((depth[id(a)] for a in node.args), default=0)
    return depth[id(tree)]


def variables_of(tree: Expr) -> frozenset[str]:
    return frozenset(n.value for n in postorder(tree) if n.op == "var")  # type: ignore[misc]


def params_of(tree: Expr) -> frozenset[str]:
    return frozenset(n.value for n in postorder(tree) if n.op == "param")  # type: ignore[misc]


def substitute_params(tree: Expr, values: Mapping[str, float]) -> Expr:
    """Replace every ``param`` node named in ``values`` by its number."""

    def number(node: Expr) -> Expr | None:
        name = str(node.value)
        return num(values[name]) if node.op == "param" and name in values else None

    return _replace_leaves(tree, number)


def scale_variables(tree: Expr, factors: Mapping[str, float]) -> Expr:
    """Replace every variable named in ``factors`` by itself times its factor
    (``{"x": 2.0}``: ``x`` becomes ``x*2``)."""

    def scaled(node: Expr) -> Expr | None:
        name = str(node.value)
        return node * num(float(factors[name])) if node.op == "var" and name in factors else None

    return _replace_leaves(tree, scaled)


def _replace_leaves(tree: Expr, replace: Callable[[Expr], Expr | None]) -> Expr:
    """``tree`` with each leaf for which ``replace`` gives a tree replaced by it, the nodes above
    rebuilt (children first: no recursion; shared subtrees stay shared)."""
    memo: dict[int, Expr] = {}
    for node in postorder(tree):
        if node.args:
            out = Expr(node.op, tuple(memo[id(a)] for a in node.args), node.value)
        else:
            out = replace(node) or node
        memo[id(node)] = out
    return memo[id(tree)]


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
    """Canonical K3DSurf/MathMod text of ``tree``; ``parse(to_string(t)) == t``.

    Iterative (an explicit stack of nodes and text pieces), so any depth prints.
    """
    out: list[str] = []
    stack: list[Expr | str] = [tree]
    while stack:
        item = stack.pop()
        if isinstance(item, str):
            out.append(item)
            continue
        op = item.op
        if op == "num":
            out.append(format_number(item.value))  # type: ignore[arg-type]
        elif op in ("var", "param"):
            out.append(str(item.value))
        elif op == "pi":
            out.append("pi")
        elif op in _UNARY_TEXT:
            out.append(_UNARY_TEXT[op])
            _push(stack, item.args[0], _bare(item, 0))
        elif op in _BINARY_PREC:
            a, b = item.args
            _push(stack, b, _bare(item, 1))  # pushed first, printed last
            stack.append(op)
            _push(stack, a, _bare(item, 0))
        else:
            out.append(f"{op}(")
            stack.append(")")
            for k, a in enumerate(reversed(item.args)):
                if k:
                    stack.append(",")
                stack.append(a)
    return "".join(out)


def _bare(parent: Expr, k: int) -> bool:
    """Whether the printer writes argument ``k`` of an operator node without parentheses."""
    child = parent.args[k]
    if parent.op in _UNARY_TEXT:  # '-' and '!' apply to a power or an atom bare; '-(-x)' keeps
        return _prec(child) >= _PREC_POW
    if parent.op == "^":  # right-associative: base needs an atom, exponent a power or unary
        if k == 0:
            return _prec(child) >= _PREC_ATOM
        return _prec(child) >= (_PREC_POW if child.op in _UNARY_TEXT else _PREC_NEG)
    p = _BINARY_PREC[parent.op]  # left-associative: the right operand needs higher precedence
    if k == 0:
        return _prec(child) >= p
    return child.op not in _UNARY_TEXT and _prec(child) >= p + 1


def printed_nesting(tree: Expr) -> int:
    """The deepest nesting of parentheses (grouping and function calls) in ``to_string(tree)``,
    computed without printing: the parser's nesting limit applies to it."""
    depth: dict[int, int] = {}
    for node in postorder(tree):
        best = 0
        for k, a in enumerate(node.args):
            if node.op in _BINARY_PREC or node.op in _UNARY_TEXT:
                extra = 0 if _bare(node, k) else 1
            else:  # a function call: its own parentheses
                extra = 1
            best = max(best, depth[id(a)] + extra)
        depth[id(node)] = best
    return depth[id(tree)]


def _push(stack: list[Expr | str], node: Expr, bare: bool) -> None:
    """Schedule ``node`` for printing, in parentheses unless ``bare``."""
    if bare:
        stack.append(node)
    else:
        stack.extend((")", node, "("))
