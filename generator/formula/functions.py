"""The functions a formula may call: names, arities, and their reference (numpy) meaning.

Numeric semantics, decided once (see docs/reference/numerics.md):

- float64 everywhere, IEEE rules: ``1/0 = inf``, ``0/0 = NaN``; no error is raised for them.
- every transcendental function is surfgen's own (:mod:`surfgen.generator.elementary`), the same
  bits on every CPU;
- ``u^l`` follows C's ``pow``: a negative ``u`` with a non-integer ``l`` gives NaN (the paper
  writes ``|x|^0.31`` to avoid this; eq. (13)'s sampler wraps such bases in ``abs``); exponents
  2, 0.5, -1, 1, 0 give ``u*u``, ``sqrt(u)``, ``1/u``, ``u``, ``1`` (numpy's fast path, kept);
- the round trips ``atan(tan u)``, ``asin(sin u)``, ``acos(cos u)``, ``acot(cot u)`` are computed
  in closed form (:mod:`surfgen.generator.elementary.roundtrip`) and ``u/|u|`` as
  ``constituents.unit_sign`` (+1 at u = 0): :func:`match_rewrite`, applied by both evaluators.
- ``cot = 1/tan``, ``sec = 1/cos``, ``csc = 1/sin`` (so ``cot(0) = inf``), ``acot(u) = pi/2 - atan(u)``
  (Maple's branch, range (0, pi)); ``sign(0) = 0``; ``min``/``max`` propagate NaN.
- Inverse functions outside their domain (``asin(2)``, ``log(-1)``) give NaN.
- Non-finite samples are *outside* when meshing (see :mod:`surfgen.generator.mesh.mesh`).

Constituent functions (eqs 1-12) are built-ins whose first argument is an expression and whose
other arguments are parameters that must be constant (numbers, ``pi`` and named parameters).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from surfgen.generator import elementary as E
from surfgen.generator.errors import FormulaError
from surfgen.generator.formula import constituents as cf
from surfgen.generator.formula import logic
from surfgen.generator.formula.expr import Expr


@dataclass(frozen=True)
class FunctionDef:
    """A callable name of the formula language.

    ``min_args``/``max_args`` bound the arity (``max_args=None``: variadic);
    ``const_from``: index of the first argument that must be constant (``None``: none must).
    ``reference`` takes the evaluated arguments (arrays for expressions, floats for constants).
    """

    name: str
    min_args: int
    max_args: int | None
    reference: Callable[..., np.ndarray]
    const_from: int | None = None
    doc: str = ""

    def arity_text(self) -> str:
        if self.max_args == self.min_args:
            n = self.min_args
            return f"{n} argument{'s' if n != 1 else ''}"
        if self.max_args is None:
            return f"at least {self.min_args} arguments"
        return f"{self.min_args} to {self.max_args} arguments"


def _math(name: str, fn: Callable[..., np.ndarray], n: int = 1, doc: str = "") -> FunctionDef:
    return FunctionDef(name, n, n, fn, None, doc)


def _own(name: str, n: int = 1) -> FunctionDef:
    """A transcendental function: surfgen's own (elementary)."""
    return _math(name, functools.partial(E.call, name), n)


def _fcc_reference(x: np.ndarray, *coords: float) -> np.ndarray:
    if len(coords) % 2:
        raise FormulaError(
            "fcc takes x then pairs x1,y1,x2,y2,...: got an odd number of coordinates"
        )
    pts = list(zip(coords[0::2], coords[1::2], strict=True))
    return cf.fcc(x, pts)


_TABLE: list[FunctionDef] = [
    _own("sin"),
    _own("cos"),
    _own("tan"),
    _math("cot", cf.cot, doc="1/tan(u)"),
    _math("sec", cf.sec, doc="1/cos(u)"),
    _math("csc", cf.csc, doc="1/sin(u)"),
    _own("asin"),
    _own("acos"),
    _own("atan"),
    _math("acot", cf.acot, doc="pi/2 - atan(u), range (0, pi)"),
    _own("atan2", 2),
    _own("sinh"),
    _own("cosh"),
    _own("tanh"),
    _own("asinh"),
    _own("acosh"),
    _own("atanh"),
    _own("exp"),
    _own("log"),
    _own("log10"),
    _math("sqrt", np.sqrt),
    _own("cbrt"),
    _math("abs", np.abs),
    _math("sign", np.sign),
    _math("floor", np.floor),
    _math("ceil", np.ceil),
    _math("min", np.minimum, 2),
    _math("max", np.maximum, 2),
    # MathMod's (fparser's) conditional and rounding, see logic.py.
    _math("if", logic.if_, 3, doc="if(c, a, b): a where |c| >= 0.5, else b"),
    _math("int", logic.round_half_up, doc="floor(u + 0.5)"),
    _math("trunc", logic.trunc, doc="rounds towards 0"),
    # Constituent functions, eqs (1)-(12).
    FunctionDef("fcc", 5, None, _fcc_reference, 1, "eq. (1): fcc(x, x1,y1, x2,y2, ...)"),
    FunctionDef("fcc8", 1, 1, cf.fcc8, None, "Figure 1.1: the eight-segment curve"),
    FunctionDef("saw1", 3, 3, cf.saw1, 1, "eq. (2): saw1(x, r, p)"),
    FunctionDef("tri1", 3, 3, cf.tri1, 1, "eq. (3): tri1(x, r, p)"),
    FunctionDef("stair1", 4, 4, cf.stair1, 1, "eq. (4): stair1(x, r, h, p)"),
    FunctionDef("rect1", 2, 2, cf.rect1, 1, "eq. (5): rect1(x, t), |t| < 1"),
    FunctionDef("rect2", 3, 3, cf.rect2, 1, "eq. (6): rect2(x, r, t)"),
    FunctionDef("rect3", 2, 2, cf.rect3, 1, "eq. (7): rect3(x, t)"),
    FunctionDef("saw2", 2, 2, cf.saw2, 1, "eq. (9): saw2(x, r)"),
    FunctionDef("tri2", 2, 2, cf.tri2, 1, "eq. (10): tri2(x, r)"),
    FunctionDef("tri3", 2, 2, cf.tri3, 1, "eq. (11): tri3(x, r)"),
    FunctionDef("stair2", 3, 3, cf.stair2, 1, "eq. (12): stair2(x, r, h)"),
]

FUNCTIONS: dict[str, FunctionDef] = {f.name: f for f in _TABLE}

# Names the parser expands in place rather than keeping as a node (see parser.py).
MACROS = {
    "powf": "eq. (8): powf(a1,b1,c1,d1, a2,b2,c2,d2, ...) = sum a x^b y^c z^d",
    "pow": "pow(a, b) = a^b (fparser's name for ^)",
}

CONSTITUENT_NAMES = tuple(f.name for f in _TABLE if f.const_from is not None or f.name == "fcc8")

# ----------------------------------------------------------------------------- rewrites

# f(g(u)) computed in closed form (elementary.roundtrip), the name of the one operation.
ROUND_TRIPS: dict[tuple[str, str], str] = {
    ("atan", "tan"): "atantan",
    ("asin", "sin"): "asinsin",
    ("acos", "cos"): "acoscos",
    ("acot", "cot"): "acotcot",
}


def match_rewrite(node: Expr) -> tuple[str, Expr] | None:
    """The tree-level rewrite that both evaluators apply to ``node``, or ``None``.

    Returns ``(name, u)``: ``name`` is a round trip of :data:`ROUND_TRIPS` (``atan(tan(u))``
    -> ``"atantan"``) or ``"usign"`` for ``u/abs(u)`` (the paper's sign, +1 at u = 0 as in the
    constituent functions, +-1 at +-inf instead of NaN)."""
    if len(node.args) == 1 and len(node.args[0].args) == 1:
        name = ROUND_TRIPS.get((node.op, node.args[0].op))
        if name is not None:
            return name, node.args[0].args[0]
    if node.op == "/" and node.args[1].op == "abs" and node.args[1].args[0] == node.args[0]:
        return "usign", node.args[0]
    # acot written out as fparser has to (pi/2 - atan(v), its definition here): acot(cot(u)).
    if node.op == "-" and node.args[0] == _HALF_PI and node.args[1].op == "atan":
        inner = node.args[1].args[0]
        if inner.op == "cot":
            return "acotcot", inner.args[0]
    return None


_HALF_PI = Expr("/", (Expr("pi"), Expr("num", (), 2.0)))
