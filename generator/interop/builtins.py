"""Write surfgen's built-ins with functions MathMod and K3DSurf know (for exported scripts).

fparser has no ``acot``, no ``sign`` and none of the paper's constituent functions; we write
them out exactly as :mod:`surfgen.generator.formula.constituents` computes them, operation for
operation, so that importing an exported script gives the same field bit for bit:

- the step ``H(u) = 1 + min(floor(max(u, -1)), 0)`` is 1 for ``u >= 0`` (and ``-0``), 0 below,
  NaN for NaN, with exact arithmetic only; ``u/|u|`` read as +1 at 0 is ``2 H(u) - 1``,
  ``sign(u) = H(u) - H(-u)``, and "u is 0" is ``H(u) + H(-u) - 1``;
- ``acot(u) = pi/2 - atan(u)``; rect3's quotient with 0/0 read as 1 is
  ``(a + Z)/(b + Z)`` with ``Z`` = 1 exactly when both are 0;
- the series of eqs (2)-(4) and the segment sums of eq. (1) are written as the sums the
  reference adds up, in the same order, starting from 0.

(MathMod's own ``max`` returns its second operand for NaN, so at NaN samples MathMod may see
-1 where surfgen sees NaN; elsewhere the values agree.)
"""

from __future__ import annotations

from collections.abc import Mapping

from surfgen.generator.eval.reference import evaluate_points
from surfgen.generator.formula import constituents as cf
from surfgen.generator.formula.expr import Expr

_PI = Expr("pi")


def _c(value: float) -> Expr:
    """A constant as a tree: negative numbers are neg nodes."""
    v = float(value)
    return Expr("neg", (Expr("num", (), -v),)) if v < 0 else Expr("num", (), v)


def _b(op: str, a: Expr, b: Expr) -> Expr:
    return Expr(op, (a, b))


def _f(name: str, *args: Expr) -> Expr:
    return Expr(name, tuple(args))


def step(u: Expr) -> Expr:
    """1 for u >= 0, 0 for u < 0 (exact)."""
    inner = _f("min", _f("floor", _f("max", u, _c(-1.0))), _c(0.0))
    return _b("+", _c(1.0), inner)


def unit_sign(u: Expr) -> Expr:
    """u/|u| with +1 at 0, i.e. ``2 H(u) - 1``, written ``1 + 2 min(floor(max(u, -1)), 0)``."""
    inner = _f("min", _f("floor", _f("max", u, _c(-1.0))), _c(0.0))
    return _b("+", _c(1.0), _b("*", _c(2.0), inner))


def is_zero(u: Expr) -> Expr:
    return _b("-", _b("+", step(u), step(Expr("neg", (u,)))), _c(1.0))


def _acot(u: Expr) -> Expr:
    return _b("-", _b("/", _PI, _c(2.0)), _f("atan", u))


def _acot_cot(u: Expr) -> Expr:
    return _acot(_f("cot", u))


def _pi_x_over_r(x: Expr, r: float) -> Expr:
    return _b("/", _b("*", _PI, x), _c(r))


def _selector(x: Expr, a: float, b: float) -> Expr:
    us = _b("*", unit_sign(_b("-", x, _c(a))), unit_sign(_b("-", x, _c(b))))
    return _b("-", _c(1.0), us)


def _series(x: Expr, r: float, p: int) -> Expr:
    total = _c(0.0)
    for i in range(-p, p + 1):
        a = r * (i - 1)
        total = _b("+", total, _b("*", _selector(x, a, r * i), _b("-", x, _c(a))))
    return total


def _ratio1(a: Expr, b: Expr) -> Expr:
    both = _b("*", is_zero(a), is_zero(b))
    return _b("/", _b("+", a, both), _b("+", b, both))


def _constituent(op: str, x: Expr, c: list[float]) -> Expr:
    if op in ("saw1", "tri1", "stair1"):
        r, p = c[0], int(c[-1])
        s = _series(x, r, p)
        if op == "saw1":
            return _b("/", s, _c(2.0 * r))
        if op == "tri1":
            return _f("abs", _b("-", _b("/", s, _c(r)), _c(1.0)))
        return _b("*", _c(c[1] / r), _b("-", x, _b("*", _c(0.5), s)))
    if op == "rect1":
        u = _b("+", _f("sin", _b("*", _PI, x)), _c(c[0]))
        return _b("-", _c(0.5), _b("*", _c(0.5), unit_sign(u)))
    if op == "rect2":
        r, t = c
        a = _b("/", _acot_cot(_b("/", _b("*", _PI, _b("+", x, _c(t))), _c(r))), _PI)
        b = _b("/", _acot_cot(_pi_x_over_r(x, r)), _PI)
        return _b("+", _b("-", _c(t / r), a), b)
    if op == "rect3":
        (t,) = c
        u = _b("*", _PI, x)
        v = _b("*", _PI, _b("+", x, _c(t)))
        first = _ratio1(_f("asin", _f("sin", u)), _f("atan", _f("tan", u)))
        second = _ratio1(_f("atan", _f("tan", v)), _f("asin", _f("sin", v)))
        return _b("*", _c(0.5), _b("-", _b("*", first, second), _c(1.0)))
    if op == "saw2":
        return _b("/", _acot_cot(_pi_x_over_r(x, c[0])), _PI)
    if op == "tri2":
        w = _b("/", _b("*", _b("*", _c(2.0), _PI), x), _c(c[0]))
        return _b("/", _f("acos", _f("cos", w)), _PI)
    if op == "tri3":
        a = _acot_cot(_pi_x_over_r(x, c[0]))
        return _f("abs", _b("-", _b("*", _b("/", _c(2.0), _PI), a), _c(1.0)))
    if op == "stair2":
        r, h = c
        a = _b("/", _acot_cot(_pi_x_over_r(x, r)), _PI)
        return _b("*", _c(h), _b("-", _b("/", x, _c(r)), a))
    if op in ("fcc", "fcc8"):
        if op == "fcc":
            pts = list(zip(c[0::2], c[1::2], strict=True))
            lines = [
                (
                    x0,
                    x1,
                    _b(
                        "/",
                        _b("-", _b("+", _b("*", _c(y1 - y0), x), _c(y0 * x1)), _c(y1 * x0)),
                        _c(x1 - x0),
                    ),
                )
                for (x0, y0), (x1, y1) in zip(pts, pts[1:], strict=False)
            ]
        else:
            lines = [
                (a, b, _b("+", _b("*", _c(slope), x), _c(icept)))
                for a, b, slope, icept in cf.FIGURE_1_1_SEGMENTS
            ]
        total = _c(0.0)
        for a, b, line in lines:
            total = _b("+", total, _b("*", _selector(x, a, b), line))
        return _b("*", _c(0.5), total)
    raise AssertionError(f"no expansion for {op}")  # pragma: no cover


_CONSTITUENTS = ("saw1", "tri1", "stair1", "rect1", "rect2", "rect3", "saw2", "tri2", "tri3")
_CONSTITUENTS += ("stair2", "fcc", "fcc8")


def expand_builtins(tree: Expr, params: Mapping[str, float] | None = None) -> Expr:
    """``tree`` with acot, sign and the constituent functions written in standard functions
    (constituent parameters that are named parameters take their values from ``params``).

    Raises :class:`~surfgen.generator.errors.FormulaError` (from the constituents' own checks)
    when a constituent's parameters are not numbers.
    """
    memo: dict[Expr, Expr] = {}

    def go(node: Expr) -> Expr:
        hit = memo.get(node)
        if hit is not None:
            return hit
        args = tuple(go(a) for a in node.args)
        op = node.op
        if op == "acot":
            out = _acot(args[0])
        elif op == "sign":
            out = _b("-", step(args[0]), step(Expr("neg", (args[0],))))
        elif op in _CONSTITUENTS:
            out = _constituent(op, args[0], [_number(a, params or {}) for a in args[1:]])
        else:
            out = Expr(op, args, node.value) if args else node
        memo[node] = out
        return out

    return go(tree)


def _number(node: Expr, params: Mapping[str, float]) -> float:
    """The value of a constituent's constant parameter (raises FormulaError if unbound)."""
    return float(evaluate_points(node, 0.0, 0.0, 0.0, params))
