"""The plain-numpy reference evaluator: slow, obvious, and the truth the fast path is tested against.

It evaluates the tree recursively on an open (broadcast) grid, so a sub-expression of x alone
costs Nx operations, and sub-trees shared by identity are computed once. Transcendental
functions are surfgen's own numpy twins (:mod:`surfgen.generator.elementary`), so the result is
the same on every CPU and equals the fast evaluator's bit for bit; the rewrites of
:func:`surfgen.generator.formula.functions.match_rewrite` (closed-form round trips, ``u/|u|``) apply
here as in the compiler. ``maths="numpy"`` evaluates with numpy's own ufuncs instead (the
accuracy cross-check and the benchmark's baseline; CPU-dependent).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Mapping

import numpy as np

from surfgen.generator import elementary as E
from surfgen.generator.errors import FormulaError
from surfgen.generator.eval.grid import Field, Grid
from surfgen.generator.formula import constituents as cf
from surfgen.generator.formula import logic
from surfgen.generator.formula.expr import Expr, params_of, postorder
from surfgen.generator.formula.functions import FUNCTIONS, match_rewrite

_BINARY = {
    "+": np.add,
    "-": np.subtract,
    "*": np.multiply,
    "/": np.divide,
    "^": E.power,
    **logic.BINARY,
}
MATHS = ("surfgen", "numpy")


def evaluate_points(
    tree: Expr,
    x: np.ndarray | float,
    y: np.ndarray | float,
    z: np.ndarray | float,
    params: Mapping[str, float] | None = None,
    maths: str = "surfgen",
) -> np.ndarray:
    """Evaluate ``tree`` at points ``(x, y, z)`` (broadcast together); float64 result.

    ``maths="numpy"``: numpy's own ufuncs for the transcendental functions (see the module
    docstring). Raises :class:`FormulaError` for an unbound parameter or a bad constituent
    parameter, :class:`ValueError` for an unknown ``maths``.
    """
    if maths not in MATHS:
        raise ValueError(f"maths must be one of {MATHS}, got {maths!r}")
    params = dict(params or {})
    missing = sorted(params_of(tree) - params.keys())
    if missing:
        raise FormulaError(
            f"parameter '{missing[0]}' has no value (give it with --param {missing[0]}=...)"
        )
    env = {
        "x": np.asarray(x, np.float64),
        "y": np.asarray(y, np.float64),
        "z": np.asarray(z, np.float64),
    }
    memo: dict[Expr, np.ndarray] = {}
    backend = E.numpy_ufuncs() if maths == "numpy" else contextlib.nullcontext()
    with np.errstate(all="ignore"), backend:
        for node in postorder(tree):  # children first: _eval never recurses more than once
            _eval(node, env, params, memo)
        out = _eval(tree, env, params, memo)
    shape = np.broadcast_shapes(env["x"].shape, env["y"].shape, env["z"].shape)
    return np.array(np.broadcast_to(np.asarray(out, np.float64), shape), dtype=np.float64)


def evaluate_reference(
    tree: Expr, grid: Grid, params: Mapping[str, float] | None = None, maths: str = "surfgen"
) -> Field:
    """Sample ``tree`` on ``grid``; returns a :class:`Field` of shape ``grid.shape``."""
    x, y, z = grid.open_axes()
    return Field(grid, evaluate_points(tree, x, y, z, params, maths))


def _eval(node: Expr, env: dict, params: Mapping[str, float], memo: dict) -> np.ndarray:
    hit = memo.get(node)
    if hit is not None:
        return hit
    out = apply_node(node, lambda n: _eval(n, env, params, memo), env, params)
    memo[node] = out
    return out


def apply_node(
    node: Expr,
    value_of: Callable[[Expr], np.ndarray],
    env: Mapping[str, np.ndarray],
    params: Mapping[str, float],
) -> np.ndarray:
    """The value of one node, its sub-trees' values given by ``value_of`` (the one place that
    decides what each node means; other node-by-node evaluators call it too)."""
    op = node.op
    if op == "num":
        out = np.float64(node.value)
    elif op == "var":
        out = env[node.value]
    elif op == "param":
        out = np.float64(params[node.value])
    elif op == "pi":
        out = np.float64(np.pi)
    elif op == "neg":
        out = np.negative(value_of(node.args[0]))
    elif (rewrite := match_rewrite(node)) is not None:  # the same rewrite the compiler applies
        name, inner = rewrite
        u = value_of(inner)
        out = cf.unit_sign(u) if name == "usign" else E.round_trip(name, u)
    elif op == "not":
        out = logic.not_(np.asarray(value_of(node.args[0]), np.float64))
    elif op in _BINARY:
        a = value_of(node.args[0])
        b = value_of(node.args[1])
        out = _BINARY[op](np.asarray(a, np.float64), np.asarray(b, np.float64))
    else:
        fdef = FUNCTIONS.get(op)
        if fdef is None:
            raise FormulaError(f"unknown function '{op}'")
        args = [value_of(a) for a in node.args]
        if fdef.const_from is not None:
            consts = [
                float(np.asarray(a).reshape(-1)[0]) if np.ndim(a) == 0 or np.size(a) == 1 else None
                for a in args[fdef.const_from :]
            ]
            if any(c is None for c in consts):
                raise FormulaError(f"{op}: parameters must be constant")
            args = args[: fdef.const_from] + consts
        out = fdef.reference(*args)
    return np.asarray(out, dtype=np.float64)
