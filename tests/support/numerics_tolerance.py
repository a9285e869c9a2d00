"""How far numpy's own ufuncs may be from surfgen's functions on a formula: a first-order error
bound that follows the conditioning of the formula, point by point.

Each node gets its value (surfgen's maths, exactly as the reference computes it) and a bound
``e`` on the absolute difference a computation with other correctly-behaved elementary functions
(numpy's ufuncs: <= 4 ulp; surfgen's: <= 1-2 ulp) may show there: every transcendental adds
``T`` ulp of its result, and the differences of the arguments propagate through the derivative
(``sin``: ``|cos u| e``; ``tan``: ``(1 + tan^2) e``; ``asin``: ``e / sqrt(1 - u^2)`` ...). Where a
difference could cross a discontinuity (a pole of ``tan``, a jump of ``floor``/``sign``/a
constituent function, the edge of a domain such as ``asin``'s [-1, 1]) the bound is infinite:
the point is ill-conditioned and not compared. The round trips are bounded through their
direct forms, which is what numpy computes (``asin(sin u)`` near ``u = pi/2`` loses half the
digits there, and the bound says so).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from surfgen.generator import elementary as E
from surfgen.generator.eval.grid import Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.constituents import unit_sign
from surfgen.generator.formula.expr import Expr
from surfgen.generator.formula.functions import FUNCTIONS, match_rewrite

EPS = 2.0**-52
T = 8.0  # ulp a transcendental may differ between two good implementations
INF = np.inf
# Constituent functions built on trigonometric round trips: numpy's direct forms lose up to
# half the digits at their kinks (acos(cos w) near w = 0 is sqrt(2 eps) off).
_TRIG_CONSTITUENTS = {"rect2", "rect3", "saw2", "tri2", "tri3", "stair2"}


def _ulp(v: np.ndarray) -> np.ndarray:
    return np.spacing(np.abs(v))


def _clean(e: np.ndarray) -> np.ndarray:
    return np.where(np.isnan(e), INF, e)


def _fn(name: str, a: np.ndarray, ea: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A transcendental of the formula language: value and bound."""
    v = E.call(name, a)
    aa = np.abs(a)
    if name == "sin":
        d = np.abs(E.call("cos", a))
    elif name == "cos":
        d = np.abs(E.call("sin", a))
    elif name == "tan":
        d = 1.0 + v * v
        near_pole = np.abs(E.call("cos", a)) <= ea + T * EPS * np.maximum(1.0, aa)
        d = np.where(near_pole, INF, d)
    elif name in ("asin", "acos"):
        d = _domain(1.0 - aa, ea, 1.0 / np.sqrt(np.maximum(1.0 - a * a, 0.0)))
    elif name == "atan":
        d = 1.0 / (1.0 + a * a)
    elif name == "sinh":
        d = E.call("cosh", a)
    elif name == "cosh":
        d = np.abs(E.call("sinh", a))
    elif name == "tanh":
        d = 1.0 - v * v
    elif name == "asinh":
        d = 1.0 / np.sqrt(1.0 + a * a)
    elif name == "acosh":
        d = _domain(a - 1.0, ea, 1.0 / np.sqrt(np.maximum(a * a - 1.0, 0.0)))
    elif name == "atanh":
        d = _domain(1.0 - aa, ea, 1.0 / (1.0 - a * a))
    elif name == "exp":
        d = v
    elif name in ("log", "log10"):
        d = _domain(a, ea, 1.0 / (aa * (np.log(10.0) if name == "log10" else 1.0)))
    elif name == "cbrt":
        d = np.where(aa > ea, 1.0 / (3.0 * v * v), INF)
    else:  # pragma: no cover
        raise AssertionError(name)
    prop = np.where(ea == 0, 0.0, d * ea)
    return v, _clean(prop + _own_ulps(v))


def _own_ulps(v: np.ndarray) -> np.ndarray:
    """T ulp of a finite non-zero result (a NaN or an infinity is compared as such; a zero
    of sin, pow, ... is exact in any implementation)."""
    return np.where(np.isfinite(v) & (v != 0), T * _ulp(v), 0.0)


def _domain(margin: np.ndarray, ea: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The derivative inside a domain (``margin > 0``), inf where the difference may cross its
    edge, 0 outside (the value is NaN either way)."""
    return np.where(margin > ea, d, np.where(margin < -ea, 0.0, INF))


def _times(x: np.ndarray, e: np.ndarray) -> np.ndarray:
    """x * e with 0 for e = 0 whatever x (an exact operand adds no difference, even times inf)."""
    return np.where(e == 0, 0.0, x * e)


def _jump(a: np.ndarray, ea: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """0 where the difference cannot reach a discontinuity ``dist`` away, else inf."""
    return np.where((ea > 0) & (dist <= ea), INF, 0.0)


def _round(v: np.ndarray, e: np.ndarray) -> np.ndarray:
    """A correctly rounded operation of inexact operands may round the other way too."""
    return _clean(np.where(e > 0, e + np.where(np.isfinite(v), _ulp(v), 0.0), e))


class _Bound:
    def __init__(self, env: dict, params: Mapping[str, float]) -> None:
        self.env = env
        self.params = params
        self.memo: dict[Expr, tuple[np.ndarray, np.ndarray]] = {}

    def __call__(self, node: Expr) -> tuple[np.ndarray, np.ndarray]:
        hit = self.memo.get(node)
        if hit is None:
            v, e = self._node(node)
            v, e = np.asarray(v, np.float64), np.asarray(e, np.float64)
            # A NaN made from a NaN operand that both compute is a NaN in both.
            for a in node.args:
                if a in self.memo:
                    av, ae = self.memo[a]
                    e = np.where(np.isnan(v) & np.isnan(av) & np.isfinite(ae), 0.0, e)
            hit = v, e
            self.memo[node] = hit
        return hit

    def _node(self, node: Expr) -> tuple[np.ndarray, np.ndarray]:
        op = node.op
        zero = np.zeros(())
        if op == "num":
            return np.float64(node.value), zero
        if op == "pi":
            return np.float64(np.pi), zero
        if op == "param":
            return np.float64(self.params[node.value]), zero
        if op == "var":
            return self.env[node.value], zero
        if op == "neg":
            a, ea = self(node.args[0])
            return -a, ea
        rewrite = match_rewrite(node)
        if rewrite is not None:
            name, inner = rewrite
            a, ea = self(inner)
            if name == "usign":
                return unit_sign(a), _jump(a, ea, np.abs(a))
            v = E.round_trip(name, a)
            return v, self._direct(name, a, ea)
        if op in ("+", "-", "*", "/", "^"):
            a, ea = self(node.args[0])
            b, eb = self(node.args[1])
            return self._binary(op, a, ea, b, eb)
        fdef = FUNCTIONS[op]
        if fdef.const_from is not None or op == "fcc8":
            return self._constituent(node)
        args = [self(x) for x in node.args]
        a, ea = args[0]
        if op in E.UNARY:
            return _fn(op, a, ea)
        if op in ("cot", "sec", "csc"):
            t, et = _fn({"cot": "tan", "sec": "cos", "csc": "sin"}[op], a, ea)
            return self._binary("/", np.float64(1.0), zero, t, et)
        if op == "acot":
            t, et = _fn("atan", a, ea)
            return np.pi / 2 - t, _round(np.pi / 2 - t, et)
        if op == "sqrt":
            v = np.sqrt(a)
            d = _domain(a, ea, ea / (2.0 * np.sqrt(np.abs(a))))
            return v, _round(v, np.where(ea == 0, 0.0, d))
        if op == "abs":
            return np.abs(a), ea
        if op == "sign":
            return np.sign(a), _jump(a, ea, np.abs(a))
        if op in ("floor", "ceil"):
            v = np.floor(a) if op == "floor" else np.ceil(a)
            return v, _jump(a, ea, np.abs(a - np.rint(a)))
        if op in ("min", "max"):
            b, eb = args[1]
            v = np.minimum(a, b) if op == "min" else np.maximum(a, b)
            return v, np.maximum(ea, eb)
        if op == "atan2":
            (y, ey), (x, ex) = args
            v = E.call("atan2", y, x)
            r2 = x * x + y * y
            cut = (x < 0) & (np.abs(y) <= ey)
            tiny = np.sqrt(r2) <= ex + ey
            d = np.where(cut | tiny, INF, (np.abs(x) * ey + np.abs(y) * ex) / r2)
            prop = np.where((ex == 0) & (ey == 0), 0.0, d)
            return v, _clean(prop + _own_ulps(v))
        raise AssertionError(f"no bound for {op}")  # pragma: no cover

    def _binary(self, op, a, ea, b, eb):
        with np.errstate(all="ignore"):
            if op == "+":
                v = a + b
                return v, _round(v, ea + eb)
            if op == "-":
                v = a - b
                return v, _round(v, ea + eb)
            if op == "*":
                v = a * b
                return v, _round(v, _times(np.abs(b), ea) + _times(np.abs(a), eb) + ea * eb)
            if op == "/":
                v = a / b
                den = np.abs(b) - eb
                e = np.where(den > 0, (ea + _times(np.abs(v), eb)) / den, INF)
                e = np.where((ea == 0) & (eb == 0), 0.0, e)
                # an exact zero divisor: +-inf in both when the sign of a is certain
                e = np.where((b == 0) & (eb == 0), np.where(np.abs(a) > ea, 0.0, INF), e)
                e = np.where((ea == 0) & (eb == 0), 0.0, e)
                return v, _round(v, e)
            v = E.power(a, b)  # "^"
            exact = (ea == 0) & (eb == 0)
            la = np.abs(a)
            da = np.where(ea == 0, 0.0, np.abs(b) * ea / la)
            db = np.where(eb == 0, 0.0, np.abs(np.log(la)) * eb)
            prop = np.abs(v) * (da + db)
            # a could change sign: NaN for a real exponent, a pole for a negative one
            sign_flip = (la <= ea) & (ea > 0)
            prop = np.where(sign_flip, INF, prop)
            shortcut = np.isin(b, E.POW_SHORTCUTS) & (eb == 0)
            e = np.where(exact, 0.0, prop) + np.where(shortcut, 0.0, _own_ulps(v))
            return v, _round(v, _clean(e))

    def _direct(self, name: str, a, ea):
        """Bound of the direct form numpy computes for a round trip."""
        if name == "atantan":
            t, et = _fn("tan", a, ea)
            return _fn("atan", t, et)[1]
        if name == "asinsin":
            s, es = _fn("sin", a, ea)
            return _fn("asin", s, es)[1]
        if name == "acoscos":
            c, ec = _fn("cos", a, ea)
            return _fn("acos", c, ec)[1]
        t, et = _fn("tan", a, ea)
        q, eq = self._binary("/", np.float64(1.0), np.zeros(()), t, et)
        w, ew = _fn("atan", q, eq)
        return _round(np.pi / 2 - w, ew)

    def _constituent(self, node: Expr):
        """Value and bound by perturbing the argument by its bound (plus a few ulp for those
        that call transcendental functions): a jump in between shows as a large difference.
        The others (series, fcc) are exact operations, the same in both."""
        fdef = FUNCTIONS[node.op]
        a, ea = self(node.args[0])
        k = fdef.const_from if fdef.const_from is not None else 1
        consts = [float(self(x)[0]) for x in node.args[k:]]
        with np.errstate(all="ignore"):
            v = fdef.reference(a, *consts)
            wiggle = ea
            if node.op in _TRIG_CONSTITUENTS or node.op == "rect1":  # ulps of sin, tan ... inside
                wiggle = ea + 64 * EPS * np.maximum(1.0, np.abs(a))
            lo = fdef.reference(a - wiggle, *consts)
            hi = fdef.reference(a + wiggle, *consts)
            e = np.maximum(np.abs(lo - v), np.abs(hi - v))
            if node.op in _TRIG_CONSTITUENTS:
                e = e + 1e-7 * max([1.0] + [abs(c) for c in consts])
        return v, _clean(e)


def error_bound(
    tree: Expr, grid: Grid, params: Mapping[str, float] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Values (surfgen's maths) and the bound of their difference to numpy's ufuncs."""
    x, y, z = grid.open_axes()
    env = {"x": x, "y": y, "z": z}
    with np.errstate(all="ignore"):
        v, e = _Bound(env, dict(params or {}))(tree)
    shape = grid.shape
    return np.broadcast_to(v, shape), np.broadcast_to(e, shape)


def compare_with_numpy_ufuncs(
    tree: Expr, grid: Grid, params: Mapping[str, float] | None = None
) -> tuple[int, int]:
    """Assert that the reference with numpy's ufuncs is within :func:`error_bound` of surfgen's
    at every well-conditioned point; returns (points compared, points on the grid)."""
    ours = evaluate_reference(tree, grid, params).values
    theirs = evaluate_reference(tree, grid, params, maths="numpy").values
    v, e = error_bound(tree, grid, params)
    same = (ours.view(np.int64) == v.view(np.int64)) | (np.isnan(ours) & np.isnan(v))
    assert same.all(), f"{tree}: the bound's values are not the reference's"
    ok = np.isfinite(e)
    nan_o, nan_t = np.isnan(ours), np.isnan(theirs)
    bad_nan = ok & (nan_o != nan_t)
    assert not bad_nan.any(), f"{tree}: NaN at {bad_nan.sum()} well-conditioned points"
    inf_o = np.isinf(ours)
    bad_inf = ok & inf_o & (ours != theirs)
    assert not bad_inf.any(), f"{tree}: infinities differ at {bad_inf.sum()} points"
    fin = ok & np.isfinite(ours)
    with np.errstate(invalid="ignore"):
        diff = np.abs(ours[fin] - theirs[fin])
    over = ~(diff <= e[fin])
    assert not over.any(), (
        f"{tree}: {over.sum()} points beyond the bound, e.g. diff {diff[over][:3]}"
        f" bound {e[fin][over][:3]}"
    )
    return int(ok.sum()), int(ok.size)
