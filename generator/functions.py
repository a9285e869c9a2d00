"""The functions a formula may call: names, arities, and their reference (numpy) meaning.

Numeric semantics, decided once (see README, "Numeric semantics"):

- float64 everywhere, IEEE rules: ``1/0 = inf``, ``0/0 = NaN``; no error is raised for them.
- ``u^l`` is C's ``pow``: a negative ``u`` with a non-integer ``l`` gives NaN (the paper writes
  ``|x|^0.31`` to avoid this; eq. (13)'s sampler wraps such bases in ``abs``).
- ``cot = 1/tan``, ``sec = 1/cos``, ``csc = 1/sin`` (so ``cot(0) = inf``), ``acot(u) = pi/2 - atan(u)``
  (Maple's branch, range (0, pi)); ``sign(0) = 0``; ``min``/``max`` propagate NaN.
- Inverse functions outside their domain (``asin(2)``, ``log(-1)``) give NaN.
- Non-finite samples are *outside* when meshing (see :mod:`surfgen.generator.mesh`).

Constituent functions (eqs 1-12) are built-ins whose first argument is an expression and whose
other arguments are parameters that must be constant (numbers, ``pi`` and named parameters).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from surfgen.generator import constituents as cf
from surfgen.generator import logic


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


def _fcc_reference(x: np.ndarray, *coords: float) -> np.ndarray:
    if len(coords) % 2:
        from surfgen.generator.errors import FormulaError

        raise FormulaError(
            "fcc takes x then pairs x1,y1,x2,y2,...: got an odd number of coordinates"
        )
    pts = list(zip(coords[0::2], coords[1::2], strict=True))
    return cf.fcc(x, pts)


_TABLE: list[FunctionDef] = [
    _math("sin", np.sin),
    _math("cos", np.cos),
    _math("tan", np.tan),
    _math("cot", cf.cot, doc="1/tan(u)"),
    _math("sec", lambda u: 1.0 / np.cos(u), doc="1/cos(u)"),
    _math("csc", lambda u: 1.0 / np.sin(u), doc="1/sin(u)"),
    _math("asin", np.arcsin),
    _math("acos", np.arccos),
    _math("atan", np.arctan),
    _math("acot", cf.acot, doc="pi/2 - atan(u), range (0, pi)"),
    _math("atan2", np.arctan2, 2),
    _math("sinh", np.sinh),
    _math("cosh", np.cosh),
    _math("tanh", np.tanh),
    _math("asinh", np.arcsinh),
    _math("acosh", np.arccosh),
    _math("atanh", np.arctanh),
    _math("exp", np.exp),
    _math("log", np.log),
    _math("log10", np.log10),
    _math("sqrt", np.sqrt),
    _math("cbrt", np.cbrt),
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
