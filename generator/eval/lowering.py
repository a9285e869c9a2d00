"""Lowering a formula tree to primitive operations: the DAG of hash-consed operations with
constant folding (:class:`Dag`), and the lowering of every function of the formula language,
constituents included, to opcodes (:class:`Lowerer`). :func:`surfgen.generator.eval.compiler.compile_tree`
then schedules the DAG into a :class:`~surfgen.generator.eval.compiler.Program`.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from surfgen.generator import elementary as E
from surfgen.generator.errors import FormulaError
from surfgen.generator.eval.opcodes import OPCODES, SEGSUM_FCC, SEGSUM_FCC8, SERIES_SAFE, VAR_BITS
from surfgen.generator.formula import constituents as cf
from surfgen.generator.formula import logic
from surfgen.generator.formula.expr import Expr
from surfgen.generator.formula.functions import FUNCTIONS, match_rewrite

# ----------------------------------------------------------------------------- the DAG builder


@dataclass(frozen=True, slots=True)
class Node:
    op: str  # "const", "var", or an opcode name
    args: tuple[int, ...]
    imm: int | tuple[float, ...] | None
    level: int
    value: float | None = None  # for const


def _const_key(v: float) -> tuple:
    return ("const", struct.pack("<d", v))


class Dag:
    """Hash-consed primitive operations with constant folding."""

    def __init__(self) -> None:
        self.nodes: list[Node] = []
        self.index: dict[tuple, int] = {}

    def _intern(self, key: tuple, node: Node) -> int:
        hit = self.index.get(key)
        if hit is not None:
            return hit
        self.nodes.append(node)
        self.index[key] = len(self.nodes) - 1
        return len(self.nodes) - 1

    def const(self, value: float) -> int:
        v = float(value)
        return self._intern(_const_key(v), Node("const", (), None, 0, v))

    def var(self, name: str) -> int:
        return self._intern(("var", name), Node("var", (), None, VAR_BITS[name]))

    def is_const(self, n: int) -> bool:
        return self.nodes[n].op == "const"

    def value(self, n: int) -> float:
        return self.nodes[n].value  # type: ignore[return-value]

    def op(self, name: str, *args: int, imm=None) -> int:
        if name not in OPCODES:
            raise AssertionError(f"no opcode {name}")
        if name in ("add", "mul") and args[0] > args[1]:
            args = (args[1], args[0])  # IEEE + and * commute exactly: share a+b and b+a
        if all(self.is_const(a) for a in args):
            return self.const(_fold(name, [self.value(a) for a in args], imm))
        level = 0
        for a in args:
            level |= self.nodes[a].level
        return self._intern((name, args, imm), Node(name, tuple(args), imm, level))


def _fold(name: str, vals: list[float], imm) -> float:
    """Evaluate a primitive on constants with the reference's numpy functions."""
    a = [np.asarray(v, np.float64) for v in vals]
    with np.errstate(all="ignore"):
        if name in _NP_UNARY:
            out = _NP_UNARY[name](a[0])
        elif name in E.UNARY:
            out = E.call(name, a[0])
        elif name in E.ROUND_TRIPS:
            out = E.round_trip(name, a[0])
        elif name == "pow":
            out = E.power(a[0], a[1])
        elif name == "atan2":
            out = E.call("atan2", a[0], a[1])
        elif name in _NP_BINARY:
            out = _NP_BINARY[name](a[0], a[1])
        elif name == "square":
            out = a[0] * a[0]
        elif name == "recip":
            out = 1.0 / a[0]
        elif name == "usign":
            out = cf.unit_sign(a[0])
        elif name == "ratio1":
            out = cf._ratio(a[0], a[1])
        elif name in _LOGIC_FOLD:
            out = _LOGIC_FOLD[name](*a)
        else:  # powi is not emitted; series, segsum never see constants (folded whole)
            raise AssertionError(f"cannot fold {name}")
    return float(np.asarray(out, np.float64))


# Exact operations (no rounding choices): numpy's own functions are the reference's too.
_NP_UNARY = {
    "copy": lambda u: u,
    "neg": np.negative,
    "abs": np.abs,
    "sqrt": np.sqrt,
    "sign": np.sign,
    "floor": np.floor,
    "ceil": np.ceil,
}
_NP_BINARY = {
    "add": np.add,
    "sub": np.subtract,
    "mul": np.multiply,
    "div": np.divide,
    "min": np.minimum,
    "max": np.maximum,
}
_LOGIC_FOLD = {
    "lt": logic.lt,
    "le": logic.le,
    "eq": logic.eq,
    "ne": logic.ne,
    "and": logic.and_,
    "or": logic.or_,
    "not": logic.not_,
    "pick": logic.pick,
    "pickn": logic.pickn,
    "fmod": logic.fmod,
    "trunc": logic.trunc,
}
_TREE_BINARY = {"+": "add", "-": "sub", "*": "mul", "/": "div"}
# MathMod operators: (opcode, operands swapped?)
_TREE_LOGIC = {
    "<": ("lt", False),
    "<=": ("le", False),
    ">": ("lt", True),
    ">=": ("le", True),
    "=": ("eq", False),
    "!=": ("ne", False),
    "&": ("and", False),
    "|": ("or", False),
    "%": ("fmod", False),
}
# Functions of the formula language that are one opcode.
_DIRECT = frozenset(
    ("sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh", "asinh", "acosh")
    + ("atanh", "exp", "log", "log10", "sqrt", "cbrt", "abs", "sign", "floor", "ceil")
)


# ----------------------------------------------------------------------------- lowering


class Lowerer:
    def __init__(self, params: Mapping[str, float]) -> None:
        self.dag = Dag()
        self.params = params
        # Keyed by the tree itself (hash cached per node, equality iterative): equal sub-trees
        # built as separate objects (a sampled ornament's copies, each product's factors) are
        # lowered once, as the DAG's hash-consing would merge them anyway.
        self.memo: dict[Expr, int] = {}
        # The same by identity first (the node kept, so its id stays its own): a node met again
        # is found without walking the equality of its sub-tree.
        self.seen: dict[int, tuple[Expr, int]] = {}

    def lower(self, node: Expr) -> int:
        known = self.seen.get(id(node))
        if known is not None and known[0] is node:
            return known[1]
        out = self.memo.get(node)
        if out is None:
            out = self._lower(node)
            self.memo[node] = out
        self.seen[id(node)] = (node, out)
        return out

    def _lower(self, node: Expr) -> int:
        d = self.dag
        op = node.op
        if op == "num":
            return d.const(node.value)  # type: ignore[arg-type]
        if op == "pi":
            return d.const(np.pi)
        if op == "param":
            return d.const(float(np.float64(self.params[node.value])))  # type: ignore[index]
        if op == "var":
            return d.var(node.value)  # type: ignore[arg-type]
        if op == "neg":
            return d.op("neg", self.lower(node.args[0]))
        rewrite = match_rewrite(node)
        if rewrite is not None:  # the same rewrite the reference applies
            return d.op(rewrite[0], self.lower(rewrite[1]))
        if op == "not":
            return d.op("not", self.lower(node.args[0]))
        if op in _TREE_LOGIC:
            name, swap = _TREE_LOGIC[op]
            a, b = self.lower(node.args[0]), self.lower(node.args[1])
            return d.op(name, b, a) if swap else d.op(name, a, b)
        if op in _TREE_BINARY:
            return d.op(_TREE_BINARY[op], self.lower(node.args[0]), self.lower(node.args[1]))
        if op == "^":
            return self._pow(self.lower(node.args[0]), self.lower(node.args[1]))
        fdef = FUNCTIONS.get(op)
        if fdef is None:
            raise FormulaError(f"unknown function '{op}'")
        args = [self.lower(a) for a in node.args]
        if fdef.const_from is not None and not all(d.is_const(a) for a in args[fdef.const_from :]):
            raise FormulaError(f"{op}: parameters must be constant")
        if all(d.is_const(a) for a in args):
            return d.const(self._fold_function(op, args))
        if fdef.const_from is not None:
            consts = [d.value(a) for a in args[fdef.const_from :]]
            with np.errstate(all="ignore"):  # the reference's own parameter checks
                fdef.reference(*[np.zeros(())] * fdef.const_from, *consts)
            return self._constituent(op, args[0], consts)
        if op == "fcc8":
            return self._constituent(op, args[0], [])
        return self._function(op, args)

    def _fold_function(self, op: str, args: list[int]) -> float:
        fdef = FUNCTIONS[op]
        vals: list = [np.asarray(self.dag.value(a), np.float64) for a in args]
        if fdef.const_from is not None:
            vals = vals[: fdef.const_from] + [float(v) for v in vals[fdef.const_from :]]
        with np.errstate(all="ignore"):
            out = fdef.reference(*vals)
        return float(np.asarray(out, np.float64))

    def _pow(self, base: int, expo: int) -> int:
        d = self.dag
        if d.is_const(expo) and not d.is_const(base):
            e = d.value(expo)
            # The x^c convention (elementary.POW_SHORTCUTS), as one cheap operation.
            if e == 2.0:
                return d.op("square", base)
            if e == 0.5:
                return d.op("sqrt", base)
            if e == -1.0:
                return d.op("recip", base)
            if e == 1.0:
                return base
            if e == 0.0:
                return d.const(1.0)
        return d.op("pow", base, expo)

    def _function(self, op: str, args: list[int]) -> int:
        d = self.dag
        if op in _DIRECT:
            return d.op(op, args[0])
        if op in ("min", "max", "atan2"):
            return d.op(op, args[0], args[1])
        if op == "cot":
            return d.op("recip", d.op("tan", args[0]))
        if op == "sec":
            return d.op("recip", d.op("cos", args[0]))
        if op == "csc":
            return d.op("recip", d.op("sin", args[0]))
        if op == "acot":
            return self._acot(args[0])
        if op == "if":
            c, a, b = args
            return d.op("add", d.op("pick", c, a), d.op("pickn", c, b))
        if op == "int":
            return d.op("floor", d.op("add", args[0], d.const(0.5)))
        if op == "trunc":
            return d.op("trunc", args[0])
        raise AssertionError(f"no lowering for {op}")  # pragma: no cover

    # -- pieces of the constituent functions, written as constituents.py writes them
    def _acot(self, u: int) -> int:
        return self.dag.op("sub", self.dag.const(np.pi / 2), self.dag.op("atan", u))

    def _acot_cot(self, u: int) -> int:
        return self.dag.op("acotcot", u)

    def _pi_x_over_r(self, x: int, r: float) -> int:
        d = self.dag
        return d.op("div", d.op("mul", d.const(np.pi), x), d.const(r))

    def _constituent(self, op: str, x: int, c: list[float]) -> int:
        d = self.dag
        k = d.const
        pi = k(np.pi)
        if op == "rect1":
            (t,) = c
            us = d.op("usign", d.op("add", d.op("sin", d.op("mul", pi, x)), k(t)))
            return d.op("sub", k(0.5), d.op("mul", k(0.5), us))
        if op == "rect2":
            r, t = c
            a = d.op(
                "div", self._acot_cot(d.op("div", d.op("mul", pi, d.op("add", x, k(t))), k(r))), pi
            )
            b = d.op("div", self._acot_cot(self._pi_x_over_r(x, r)), pi)
            return d.op("add", d.op("sub", k(t / r), a), b)
        if op == "rect3":
            (t,) = c
            u = d.op("mul", pi, x)
            v = d.op("mul", pi, d.op("add", x, k(t)))
            first = d.op("ratio1", d.op("asinsin", u), d.op("atantan", u))
            second = d.op("ratio1", d.op("atantan", v), d.op("asinsin", v))
            return d.op("mul", k(0.5), d.op("sub", d.op("mul", first, second), k(1.0)))
        if op == "saw2":
            (r,) = c
            return d.op("div", self._acot_cot(self._pi_x_over_r(x, r)), pi)
        if op == "tri2":
            (r,) = c
            w = d.op("div", d.op("mul", k(2.0 * np.pi), x), k(r))
            return d.op("div", d.op("acoscos", w), pi)
        if op == "tri3":
            (r,) = c
            a = self._acot_cot(self._pi_x_over_r(x, r))
            return d.op("abs", d.op("sub", d.op("mul", k(2.0 / np.pi), a), k(1.0)))
        if op == "stair2":
            r, h = c
            a = d.op("div", self._acot_cot(self._pi_x_over_r(x, r)), pi)
            return d.op("mul", k(h), d.op("sub", d.op("div", x, k(r)), a))
        if op in ("saw1", "tri1", "stair1"):
            r, p = c[0], c[-1]
            exact_loop = 0.0 if r * (p + 1) <= SERIES_SAFE else 1.0
            s = d.op("series", x, imm=(r, p, exact_loop))
            if op == "saw1":
                return d.op("div", s, k(2.0 * r))
            if op == "tri1":
                return d.op("abs", d.op("sub", d.op("div", s, k(r)), k(1.0)))
            h = c[1]
            return d.op("mul", k(h / r), d.op("sub", x, d.op("mul", k(0.5), s)))
        if op == "fcc":
            pts = list(zip(c[0::2], c[1::2], strict=True))
            rows: list[float] = []
            for (x0, y0), (x1, y1) in zip(pts, pts[1:], strict=False):
                rows += [x0, x1, y1 - y0, y0 * x1, y1 * x0, x1 - x0]
            return d.op("segsum", x, imm=(SEGSUM_FCC, len(pts) - 1, *rows))
        if op == "fcc8":
            rows = []
            for a, b, slope, intercept in cf.FIGURE_1_1_SEGMENTS:
                rows += [a, b, slope, intercept, 0.0, 1.0]
            return d.op("segsum", x, imm=(SEGSUM_FCC8, len(cf.FIGURE_1_1_SEGMENTS), *rows))
        raise AssertionError(f"no lowering for {op}")  # pragma: no cover
