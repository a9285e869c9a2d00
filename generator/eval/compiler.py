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

from surfgen.generator.errors import FormulaError
from surfgen.generator.eval.lowering import Dag, Lowerer, Node
from surfgen.generator.eval.opcodes import (
    LEVEL_NAMES,
    LEVEL_ORDER,
    M_S,
    M_SV,
    M_V,
    M_VS,
    M_VV,
    OP,
    OPNAMES,
    OUT,
    run_axis,
)
from surfgen.generator.formula.expr import Expr, params_of, postorder, to_string

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


# ----------------------------------------------------------------------------- scheduling


def compile_tree(tree: Expr, params: Mapping[str, float] | None = None) -> Program:
    """Compile ``tree`` with its parameters bound to ``params``.

    Raises :class:`FormulaError` for an unbound parameter, an unknown function, a non-constant
    or invalid constituent parameter (the same messages as the reference evaluator).
    """
    params = dict(params or {})
    low = Lowerer(params)
    try:
        for node in postorder(tree, by_value=True):  # children first: lower() recurses once
            low.lower(node)
        root = low.lower(tree)
    except Exception:  # an unbound parameter (every node is lowered) is the error to give
        _check_params(tree, params)
        raise
    _fuse_reciprocals(low.dag, root)
    return _schedule(low.dag, root, tree)


def _check_params(tree: Expr, params: Mapping[str, float]) -> None:
    """Raise :class:`FormulaError` for the first (by name) parameter of ``tree`` without a
    value in ``params``: looked for only when lowering failed, where an unbound parameter fails
    (one walk of the tree less for every program compiled)."""
    missing = sorted(params_of(tree) - params.keys())
    if missing:
        raise FormulaError(
            f"parameter '{missing[0]}' has no value (give it with --param {missing[0]}=...)"
        )


_FUSED_RECIPROCALS = {"cos": "sec", "sin": "csc", "tan": "cot"}


def _fuse_reciprocals(dag: Dag, root: int) -> None:
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
            nodes[n] = Node(fused, nodes[u].args, None, node.level)


def _schedule(dag: Dag, root: int, tree: Expr) -> Program:
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


def _postorder(nodes: list[Node], root: int) -> list[int]:
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
        self.axis = run_axis(lv)
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


__all__ = ["Program", "compile_tree", "describe"]
