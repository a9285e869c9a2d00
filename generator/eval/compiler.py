"""Compile a formula tree to a flat :class:`Program` that one numba interpreter runs on any grid.

Pipeline: bind the parameters, fold every constant sub-tree with numpy exactly as the reference
does, lower the constituent functions to primitive operations (a few dedicated opcodes remain
for their piecewise sums), share identical sub-expressions, then **hoist**: every operation is
placed in the *level* of the variables it depends on and computed over that domain only.

===========  ===========================================  =====================================
level        domain (computed ...)                         run along
===========  ===========================================  =====================================
const        folded here, once, with numpy                 -
x, y, z      once per grid, 1-D arrays                      that axis
yz           once per grid, an (Ny, Nz) plane                z, one j row at a time
xy, xz       once per x index (per slab, per thread)        y or z
xyz          per point, one z row (tile) at a time          z
===========  ===========================================  =====================================

A level block reads values of lower levels: those that vary along its run axis are copied in as
vectors, the others are scalars for the row. Power functions ``sum a x^b y^c z^d`` (eq. 8) thus
cost one multiply-add per term and point; ``x^b`` is computed Nx times, ``a x^b y^c`` Nx*Ny times.

Numeric semantics are those of :mod:`surfgen.generator.eval.reference`, operation for operation in
the same order: every transcendental is surfgen's own (:mod:`surfgen.generator.elementary`),
whose numba rows the kernels call and whose numpy twins the reference and the constant folding
call, so results are bit-identical on every CPU. Both evaluators apply the same tree-level
rewrites (:func:`surfgen.generator.formula.functions.match_rewrite`): the round trips ``atan(tan u)``,
``asin(sin u)``, ``acos(cos u)``, ``acot(cot u)`` are one closed-form operation each and
``u/|u|`` is ``usign``. ``x^c`` with ``c = 2, 0.5, -1, 1, 0`` gives ``x*x``, ``sqrt(x)``, ``1/x``,
``x`` and ``1`` (numpy's fast path of ``np.power``, kept as a convention that both evaluators
apply per element, also when the exponent varies); every other power is surfgen's ``pow``.

Tape format (all int64, see :class:`Program`): ``code`` rows ``(op, mode, dst, a, b, imm)``;
``mode`` says which operands are vectors (W rows) or row scalars (S slots); ``imm`` is an
integer immediate (the exponent of ``powi``) or an offset into ``consts`` (parameters of
``series`` and ``segsum``). Opcode numbers are a file format: append to :data:`OPCODES`, never
renumber.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from surfgen.generator import elementary as E
from surfgen.generator.errors import FormulaError
from surfgen.generator.formula import constituents as cf
from surfgen.generator.formula import logic
from surfgen.generator.formula.expr import Expr, params_of, postorder, to_string
from surfgen.generator.formula.functions import FUNCTIONS, match_rewrite

# ----------------------------------------------------------------------------- the opcode table

# name -> (number, arity). APPEND ONLY: numbers are stored with programs and cached kernels.
OPCODES: dict[str, tuple[int, int]] = {
    "copy": (0, 1),
    "neg": (1, 1),
    "abs": (2, 1),
    "sin": (3, 1),
    "cos": (4, 1),
    "tan": (5, 1),
    "asin": (6, 1),
    "acos": (7, 1),
    "atan": (8, 1),
    "sinh": (9, 1),
    "cosh": (10, 1),
    "tanh": (11, 1),
    "asinh": (12, 1),
    "acosh": (13, 1),
    "atanh": (14, 1),
    "exp": (15, 1),
    "log": (16, 1),
    "log10": (17, 1),
    "sqrt": (18, 1),
    "cbrt": (19, 1),
    "sign": (20, 1),  # numpy's sign: sign(-0) = +0, sign(nan) = nan
    "floor": (21, 1),
    "ceil": (22, 1),
    "square": (23, 1),  # u*u (numpy's pow fast path for exponent 2)
    "recip": (24, 1),  # 1/u (exponent -1, cot = 1/tan, sec, csc)
    "usign": (25, 1),  # constituents.unit_sign: u/|u| with +1 at u = 0
    "powi": (26, 1),  # u^imm (no longer emitted: integer powers are pow with a constant)
    "series": (27, 1),  # the sum of eqs (2)-(4); consts[imm:imm+3] = r, p, exact_loop
    "segsum": (28, 1),  # 0.5 * sum of selector*line (fcc, fcc8); consts[imm] = kind, nseg, rows
    "add": (29, 2),
    "sub": (30, 2),
    "mul": (31, 2),
    "div": (32, 2),
    "pow": (33, 2),  # surfgen's pow with the x^c convention (elementary.power)
    "min": (34, 2),  # np.minimum: NaN propagates, equal operands give the second
    "max": (35, 2),
    "atan2": (36, 2),
    "ratio1": (37, 2),  # a/b with 0/0 read as 1 (rect3)
    # MathMod's comparisons, logic, if and % (logic.py): results 1.0 or 0.0.
    "lt": (38, 2),  # a < b - EPS
    "le": (39, 2),  # a <= b + EPS
    "eq": (40, 2),  # |a - b| <= EPS
    "ne": (41, 2),  # |a - b| > EPS
    "and": (42, 2),
    "or": (43, 2),
    "not": (44, 1),
    "pick": (45, 2),  # b where a is true, else 0 (if's taken branch)
    "pickn": (46, 2),  # 0 where a is true, else b (if's other branch)
    "fmod": (47, 2),  # C fmod (exact)
    "trunc": (48, 1),
    # The paper's round trips in closed form (elementary.roundtrip).
    "atantan": (49, 1),  # atan(tan u)
    "asinsin": (50, 1),  # asin(sin u)
    "acoscos": (51, 1),  # acos(cos u)
    "acotcot": (52, 1),  # acot(cot u) = pi/2 - atan(1/tan u)
    # 1/cos u, 1/sin u, 1/tan u in one row (the bits of the function, then recip): the
    # division overlaps the function's arithmetic instead of a pass of its own (_fuse_reciprocals)
    "sec": (53, 1),
    "csc": (54, 1),
    "cot": (55, 1),
}
OP = {name: num for name, (num, _) in OPCODES.items()}
ARITY = {name: n for name, (_, n) in OPCODES.items()}
OPNAMES = {num: name for name, (num, _) in OPCODES.items()}

# Operand modes of a code row.
M_V, M_VV, M_VS, M_SV, M_S = 0, 1, 2, 3, 4
MODE_NAMES = {M_V: "v", M_VV: "vv", M_VS: "vs", M_SV: "sv", M_S: "s"}

# Levels are bit masks of the variables a value depends on.
LEVEL_NAMES = {0: "const", 1: "x", 2: "y", 3: "xy", 4: "z", 5: "xz", 6: "yz", 7: "xyz"}
_VAR_BITS = {"x": 1, "y": 2, "z": 4}
# Order in which the blocks run (each reads only blocks before it).
LEVEL_ORDER = (1, 2, 4, 6, 3, 5, 7)
OUT = 7  # store kind of the xyz block: the output field

SEGSUM_FCC, SEGSUM_FCC8 = 0.0, 1.0
SERIES_SAFE = 1e300  # r*(p+1) above this: the series op loops over i like the reference


def _run_axis(level: int) -> int:
    """The bit of the axis a block of ``level`` runs along (z innermost)."""
    return 4 if level & 4 else 2 if level & 2 else 1


# ----------------------------------------------------------------------------- the program


@dataclass(frozen=True, eq=False)
class Program:
    """A compiled formula: the tape and everything the interpreter needs but the grid.

    - ``code``: int64 ``(n, 6)`` rows ``(op, mode, dst, a, b, imm)``;
    - ``consts``: float64 pool (folded constants and op parameters);
    - ``blocks``: int64 ``(8, 6)``: for each level mask ``[c0, c1, l0, l1, s0, s1]``, its
      code rows, loads and stores;
    - ``loads``: int64 ``(k, 4)`` rows ``(kind, row, slot, vector)``: kind is a level mask
      (0 = const pool) of the store read, ``vector`` 0 for an S slot, 1 for a W row, 2 for a
      W row of the per-point block that keeps its value for all j of one x index;
    - ``stores``: int64 ``(s, 3)`` rows ``(slot, kind, row)``; kind 7 is the output;
    - ``rows``: int64 ``(8,)`` rows of each level's store (x, y, z keep their axis in row 0);
    - ``n_vector``/``n_scalar``: W rows and S slots the blocks need.

    Arrays are read-only. Build with :func:`compile_tree`.
    """

    code: np.ndarray
    consts: np.ndarray
    blocks: np.ndarray
    loads: np.ndarray
    stores: np.ndarray
    rows: np.ndarray
    n_vector: int
    n_scalar: int
    tree: Expr  # what was compiled (printed by :attr:`formula` when asked for: printing costs)

    @property
    def formula(self) -> str:
        return to_string(self.tree)

    def __post_init__(self) -> None:
        for name in ("code", "consts", "blocks", "loads", "stores", "rows"):
            a = np.ascontiguousarray(getattr(self, name))
            a.flags.writeable = False
            object.__setattr__(self, name, a)

    @property
    def constant(self) -> float | None:
        """The value when the formula is a constant, else ``None``."""
        c0, c1 = self.blocks[OUT, 0], self.blocks[OUT, 1]
        if (
            c1 - c0 == 1
            and self.code[c0, 1] == M_S
            and self.blocks[OUT, 3] - self.blocks[OUT, 2] == 1
        ):
            load = self.loads[self.blocks[OUT, 2]]
            if load[0] == 0:
                return float(self.consts[load[1]])
        return None

    def counts(self) -> dict[str, int]:
        """Instructions per level, e.g. ``{"x": 4, "xyz": 9, ...}``."""
        return {LEVEL_NAMES[lv]: int(self.blocks[lv, 1] - self.blocks[lv, 0]) for lv in LEVEL_ORDER}

    def disassemble(self) -> str:
        """A readable listing of the tape, block by block."""
        lines = [f"# {self.formula}"]
        for lv in LEVEL_ORDER:
            c0, c1, l0, l1, s0, s1 = (int(v) for v in self.blocks[lv])
            if c0 == c1:
                continue
            lines.append(f"[{LEVEL_NAMES[lv]}]")
            for kind, row, slot, vec in self.loads[l0:l1]:
                src = "const" if kind == 0 else LEVEL_NAMES[int(kind)]
                where = f"{self.consts[row]!r}" if kind == 0 else f"{src}[{row}]"
                lines.append(f"  {'W' if vec else 'S'}{slot} <- {where}")
            for op, mode, d, a, b, imm in self.code[c0:c1]:
                ops = {M_V: f"W{a}", M_VV: f"W{a}, W{b}", M_VS: f"W{a}, S{b}"}.get(
                    int(mode), f"S{a}, W{b}" if mode == M_SV else f"S{a}"
                )
                tail = f" #{imm}" if OPNAMES[int(op)] in ("powi", "series", "segsum") else ""
                lines.append(f"  W{d} = {OPNAMES[int(op)]}({ops}){tail}")
            for slot, kind, row in self.stores[s0:s1]:
                lines.append(
                    f"  {LEVEL_NAMES[int(kind)] if kind != OUT else 'out'}[{row}] <- W{slot}"
                )
        return "\n".join(lines)


# ----------------------------------------------------------------------------- the DAG builder


@dataclass(frozen=True, slots=True)
class _Node:
    op: str  # "const", "var", or an opcode name
    args: tuple[int, ...]
    imm: int | tuple[float, ...] | None
    level: int
    value: float | None = None  # for const


def _const_key(v: float) -> tuple:
    return ("const", struct.pack("<d", v))


class _Dag:
    """Hash-consed primitive operations with constant folding."""

    def __init__(self) -> None:
        self.nodes: list[_Node] = []
        self.index: dict[tuple, int] = {}

    def _intern(self, key: tuple, node: _Node) -> int:
        hit = self.index.get(key)
        if hit is not None:
            return hit
        self.nodes.append(node)
        self.index[key] = len(self.nodes) - 1
        return len(self.nodes) - 1

    def const(self, value: float) -> int:
        v = float(value)
        return self._intern(_const_key(v), _Node("const", (), None, 0, v))

    def var(self, name: str) -> int:
        return self._intern(("var", name), _Node("var", (), None, _VAR_BITS[name]))

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
        return self._intern((name, args, imm), _Node(name, tuple(args), imm, level))


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


class _Lowerer:
    def __init__(self, params: Mapping[str, float]) -> None:
        self.dag = _Dag()
        self.params = params
        # Keyed by the tree itself (hash cached per node, equality iterative): equal sub-trees
        # built as separate objects (a sampled ornament's copies, each product's factors) are
        # lowered once, as the DAG's hash-consing would merge them anyway.
        self.memo: dict[Expr, int] = {}

    def lower(self, node: Expr) -> int:
        hit = self.memo.get(node)
        if hit is not None:
            return hit
        out = self._lower(node)
        self.memo[node] = out
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


# ----------------------------------------------------------------------------- scheduling


def compile_tree(tree: Expr, params: Mapping[str, float] | None = None) -> Program:
    """Compile ``tree`` with its parameters bound to ``params``.

    Raises :class:`FormulaError` for an unbound parameter, an unknown function, a non-constant
    or invalid constituent parameter (the same messages as the reference evaluator).
    """
    params = dict(params or {})
    missing = sorted(params_of(tree) - params.keys())
    if missing:
        raise FormulaError(
            f"parameter '{missing[0]}' has no value (give it with --param {missing[0]}=...)"
        )
    low = _Lowerer(params)
    for node in postorder(tree, by_value=True):  # children first: lower() recurses once
        low.lower(node)
    root = low.lower(tree)
    _fuse_reciprocals(low.dag, root)
    return _schedule(low.dag, root, tree)


_FUSED_RECIPROCALS = {"cos": "sec", "sin": "csc", "tan": "cot"}


def _fuse_reciprocals(dag: _Dag, root: int) -> None:
    """``recip(cos u)`` (or ``1/cos u``) becomes ``sec u`` (and ``sin``, ``tan`` likewise:
    ``csc``, ``cot``) where nothing else reads ``cos u``: one row computes the function and divides, so the
    divider (about 2 cycles a value, idle during cos's arithmetic) overlaps it; the same bits
    as the two operations, in a pass less. Rewrites ``dag.nodes`` in place (after lowering:
    the hash-consing index is not used any more)."""
    nodes = dag.nodes
    order = _postorder(nodes, root)
    readers: dict[int, int] = {}
    for n in order:
        for a in nodes[n].args:
            readers[a] = readers.get(a, 0) + 1
    for n in order:
        node = nodes[n]
        if node.op == "recip":
            u = node.args[0]
        elif node.op == "div" and dag.is_const(node.args[0]) and dag.value(node.args[0]) == 1.0:
            u = node.args[1]  # 1/u written out: the same IEEE division
        else:
            continue
        fused = _FUSED_RECIPROCALS.get(nodes[u].op)
        if fused and readers[u] == 1 and u != root:
            nodes[n] = _Node(fused, nodes[u].args, None, node.level)


def _schedule(dag: _Dag, root: int, tree: Expr) -> Program:
    nodes = dag.nodes
    order = _postorder(nodes, root)
    level = {n: nodes[n].level for n in order}

    # Every value read outside its own block, and the root, gets a row in its level's store.
    store_row: dict[int, int] = {}
    rows = [0] * 8
    for lv in (1, 2, 4):
        rows[lv] = 1  # row 0: the axis
    for n in order:
        if nodes[n].op == "var":
            store_row[n] = 0
    consumers_outside: set[int] = set()
    for n in order:
        nd = nodes[n]
        if nd.op in ("const", "var"):
            continue
        for a in nd.args:
            if nodes[a].op not in ("const", "var") and level[a] != nd.level:
                consumers_outside.add(a)
    if level[root] != OUT and nodes[root].op not in ("const", "var"):
        consumers_outside.add(root)  # the output block copies (broadcasts) it
    for n in order:
        if n in consumers_outside:
            store_row[n] = rows[level[n]]
            rows[level[n]] += 1

    pool = _Pool()

    code: list[tuple[int, ...]] = []
    loads: list[tuple[int, int, int, int]] = []
    stores: list[tuple[int, int, int]] = []
    blocks = np.zeros((8, 6), np.int64)
    n_vector = n_scalar = 1
    for lv in LEVEL_ORDER:
        members = [n for n in order if level[n] == lv and nodes[n].op not in ("const", "var")]
        copy_root = lv == OUT and (level[root] != OUT or nodes[root].op == "var")
        out_stores = [n for n in members if n in store_row]
        if lv == OUT and not copy_root:
            out_stores.append(root)
        block = _Block(lv, nodes, level, store_row, pool)
        c0, l0, s0 = len(code), len(loads), len(stores)
        block.emit(members, root if copy_root else None, out_stores)
        code += block.code
        loads += block.loads
        stores += block.stores_rows(out_stores, root if lv == OUT else None)
        blocks[lv] = (c0, len(code), l0, len(loads), s0, len(stores))
        n_vector = max(n_vector, block.n_vector)
        n_scalar = max(n_scalar, len(block.scalar_slot))

    return Program(
        code=np.array(code, np.int64).reshape(-1, 6),
        consts=np.array(pool.values or [0.0], np.float64),
        blocks=blocks,
        loads=np.array(loads, np.int64).reshape(-1, 4),
        stores=np.array(stores, np.int64).reshape(-1, 3),
        rows=np.array(rows, np.int64),
        n_vector=n_vector,
        n_scalar=n_scalar,
        tree=tree,
    )


def _postorder(nodes: list[_Node], root: int) -> list[int]:
    out: list[int] = []
    seen: set[int] = set()
    stack: list[tuple[int, bool]] = [(root, False)]
    while stack:
        n, done = stack.pop()
        if done:
            out.append(n)
            continue
        if n in seen:
            continue
        seen.add(n)
        stack.append((n, True))
        for a in reversed(nodes[n].args):
            if a not in seen:
                stack.append((a, False))
    return out


class _Block:
    """Code of one level: operand resolution, vector-slot allocation with reuse."""

    def __init__(self, lv, nodes, level, store_row, pool) -> None:
        self.lv = lv
        self.axis = _run_axis(lv)
        self.nodes = nodes
        self.level = level
        self.store_row = store_row
        self.pool = pool
        self.code: list[tuple[int, ...]] = []
        self.loads: list[tuple[int, int, int, int]] = []
        self.slot: dict[int, int] = {}  # node -> W row holding it
        self.scalar_slot: dict[tuple[int, int], int] = {}
        self.free: list[int] = []
        self.pinned: set[int] = set()
        self.n_vector = 0

    def _new_slot(self) -> int:
        if self.free:
            return self.free.pop()
        self.n_vector += 1
        return self.n_vector - 1

    def _is_vector(self, n: int) -> bool:
        return bool(self.level[n] & self.axis)

    def _source(self, n: int) -> tuple[int, int]:
        nd = self.nodes[n]
        if nd.op == "const":
            return 0, self.pool.get(nd.value)
        return self.level[n], self.store_row[n]

    def _scalar(self, n: int) -> int:
        src = self._source(n)
        if src not in self.scalar_slot:
            self.scalar_slot[src] = len(self.scalar_slot)
            self.loads.append((src[0], src[1], self.scalar_slot[src], 0))
        return self.scalar_slot[src]

    def emit(self, members: list[int], copy_of: int | None, out_stores: list[int]) -> None:
        nodes = self.nodes
        steps = list(members) + ([-1] if copy_of is not None else [])
        # Last use of every in-block or loaded vector, counting stores as used at the end.
        last: dict[int, int] = {}
        for t, n in enumerate(steps):
            args = nodes[n].args if n >= 0 else (copy_of,)
            for a in args:
                last[a] = t
        for n in out_stores:
            last[n] = len(steps)
        # Vector loads first: everything read from lower levels along the run axis.
        for n in steps:
            args = nodes[n].args if n >= 0 else (copy_of,)
            for a in args:
                inside = self.level[a] == self.lv and nodes[a].op != "var"
                if not inside and self._is_vector(a) and a not in self.slot:
                    self.slot[a] = self._new_slot()
                    kind, row = self._source(a)
                    # z and xz rows do not change with j: the per-point block loads them once
                    # per x index into rows that nothing else writes.
                    if self.lv == OUT and kind in (4, 5):
                        self.pinned.add(a)
                    self.loads.append((kind, row, self.slot[a], 2 if a in self.pinned else 1))
        for t, n in enumerate(steps):
            if n < 0:
                a = copy_of
                if self._is_vector(a):
                    d = self._new_slot()
                    self.code.append((OP["copy"], M_V, d, self.slot[a], 0, 0))
                else:
                    d = self._new_slot()
                    self.code.append((OP["copy"], M_S, d, self._scalar(a), 0, 0))
                self.slot[-1] = d
                continue
            nd = nodes[n]
            vec = [self._is_vector(a) for a in nd.args]
            if len(nd.args) == 1:
                mode = M_V
                a, b = self.slot[nd.args[0]], 0
            elif vec[0] and vec[1]:
                mode, a, b = M_VV, self.slot[nd.args[0]], self.slot[nd.args[1]]
            elif vec[0]:
                mode, a, b = M_VS, self.slot[nd.args[0]], self._scalar(nd.args[1])
            else:
                mode, a, b = M_SV, self._scalar(nd.args[0]), self.slot[nd.args[1]]
            # The result never shares a row with an operand: in place, the compiler's runtime
            # alias check fails and the loop runs scalar (and pow and the round trips read
            # their operands again in a second loop, after writing the result).
            # Operands that die here are freed for the next instructions.
            dying = [
                x
                for x in dict.fromkeys(nd.args)
                if x in self.slot and last.get(x) == t and x not in self.pinned
            ]
            d = self._new_slot()
            for x in dying:
                self.free.append(self.slot[x])
            self.slot[n] = d
            imm = nd.imm
            if isinstance(imm, tuple):  # op parameters: a contiguous run of the pool
                imm = self.pool.extend(imm)
            self.code.append((OP[nd.op], mode, d, a, b, int(imm or 0)))
            if n not in out_stores and last.get(n, -1) <= t:
                self.free.append(d)  # never read (cannot happen for reachable nodes)

    def stores_rows(self, out_stores: list[int], root: int | None) -> list[tuple[int, int, int]]:
        out = []
        for n in out_stores:
            if self.lv == OUT and n == root:
                continue
            out.append((self.slot[n], self.lv, self.store_row[n]))
        if root is not None:
            slot = self.slot[-1] if -1 in self.slot else self.slot[root]
            out.append((slot, OUT, 0))
        return out


class _Pool:
    """The constant pool: deduplicated scalars (for loads) and contiguous op parameters."""

    def __init__(self) -> None:
        self.values: list[float] = []
        self.index: dict[bytes, int] = {}

    def get(self, v: float) -> int:
        key = struct.pack("<d", v)
        if key not in self.index:
            self.index[key] = len(self.values)
            self.values.append(float(v))
        return self.index[key]

    def extend(self, vals) -> int:
        base = len(self.values)
        self.values.extend(float(v) for v in vals)
        return base


def describe(program: Program) -> str:
    """A one-line summary: instructions per level."""
    parts = [f"{k}={v}" for k, v in program.counts().items() if v]
    return f"{len(program.code)} ops ({', '.join(parts) or 'constant'})"


__all__ = [
    "OPCODES",
    "Program",
    "compile_tree",
    "describe",
    "LEVEL_NAMES",
]
