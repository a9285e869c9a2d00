"""The paper's constituent functions (eqs 1-12), written as the paper writes them.

Every function takes an array ``x`` (any shape) and scalar parameters and returns a float64 array
of the same shape. They are the reference semantics of the formula built-ins of the same names.

Node convention (the paper's ``u/|u|`` is 0/0 at the nodes of its piecewise sums)
-----------------------------------------------------------------------------------
We read ``u/|u|`` as **+1 at u = 0** (:func:`unit_sign`). Then the paper's segment selector
``1 - (x-a)(x-b) / (|x-a| |x-b|)`` is exactly ``2`` on the half-open interval ``[a, b)`` and ``0``
elsewhere, so

- ``fcc`` interpolates its points on ``[x_1, x_{n+1})`` (value ``y_i`` at node ``x_i``; the
  segments are joined only where the points are shared) and is 0 outside, *including* at the
  last node ``x_{n+1}``,
- ``saw1`` is ``frac(x/r)``, ``tri1`` is ``|2 frac(x/r) - 1|`` and ``stair1`` is ``h floor(x/r)``
  on their domain ``[-(p+1) r, p r)``, with no NaN anywhere.

The quotients of ``rect3`` (``asin(sin u) / atan(tan u)`` and its inverse) are 0/0 where
``u`` is exactly 0; there we take their limit, 1.

The trigonometric forms use ``cot(u) = 1/tan(u)`` and Maple's ``arccot(u) = pi/2 - atan(u)``
(range (0, pi)), so ``arccot(cot(u)) = u mod pi`` and ``saw2`` is ``frac(x/r)`` on all of R.
The round trips ``arccot(cot u)``, ``arccos(cos u)``, ``arcsin(sin u)``, ``arctan(tan u)`` are
computed in closed form (:mod:`surfgen.generator.elementary.roundtrip`): ``arccot(cot u)`` is
``u mod pi`` in ``[0, pi)``, exact for the double ``u`` (0 at u = 0), so at a jump the value
only depends on how ``pi x / r`` rounds: at x = k r ``saw2``/``stair2``/``rect2`` take one of
their two one-sided limits, never NaN (``tri3`` is 1 and ``tri2`` is 0 at x = k r either way).

Where the alternative forms agree and differ (tested in ``tests/generator/test_constituents.py``):

======================  ===============================  ===========================================
function                domain                           relation
======================  ===============================  ===========================================
saw1 (eq 2)             [-(p+1)r, pr), 0 outside         = saw2 inside its domain (both frac(x/r))
saw2 (eq 9)             all of R                         period r, [0, 1) (0 or 1 at x = k r)
tri1 (eq 3)             [-(p+1)r, pr), 1 outside         = tri3 inside its domain, peaks at x = k r
tri2 (eq 10)            all of R                         = 1 - tri3 (upside down = shifted r/2)
tri3 (eq 11)            all of R                         range [0, 1], 1 at x = k r
stair1 (eq 4)           [-(p+1)r, pr), h x/r outside     = stair2 inside its domain (h floor(x/r))
stair2 (eq 12)          all of R                         steps of height h, width r
rect1 (eq 5)            all of R, |t| < 1                period 2, value 1 where sin(pi x) < -t
rect2 (eq 6)            all of R, t/r not an integer     period r, value floor(x/r + t/r) - floor(x/r)
rect3 (eq 7)            all of R, t not an integer       period 1, values {-1, 0} (rect1 has {0, 1})
======================  ===============================  ===========================================
"""

from __future__ import annotations

import math

import numpy as np

from surfgen.generator import elementary as E
from surfgen.generator.errors import FormulaError

ArrayLike = np.ndarray | float

# Figure 1.1: eight segments, each [a, b) with the line slope*x + intercept it carries.
# Transcribed from f_cc = 0.5 (f_cc1 + f_cc2). The printed f_cc2 contains "+ 6 - s(7,9) ...
# - 5 s(10,10.5)": that is Maple's expansion of (1 - s(7,9))*1 + (1 - s(10,10.5))*5 (the
# constants 1 + 5 were collected into 6), so the last-but-two and last segments are the
# constants 1 on [7, 9) and 5 on [10, 10.5), and the printed formula is 0 outside [1, 10.5).
# tests/generator/test_constituents.py evaluates the printed formula itself against this table.
FIGURE_1_1_SEGMENTS: tuple[tuple[float, float, float, float], ...] = (
    (1.0, 2.0, 1.0, -1.0),
    (2.0, 3.0, 2.0, -3.0),
    (3.0, 4.0, 3.0, -6.0),
    (4.0, 5.0, -4.0, 22.0),
    (5.0, 7.0, 0.5, 4.5),
    (7.0, 9.0, 0.0, 1.0),
    (9.0, 10.0, -1.0, 10.0),
    (10.0, 10.5, 0.0, 5.0),
)


def unit_sign(u: ArrayLike) -> np.ndarray:
    """``u/|u|`` with the value +1 at ``u = 0`` (NaN stays NaN)."""
    u = np.asarray(u, dtype=np.float64)
    return np.sign(u) + (u == 0)


def segment_selector(x: ArrayLike, a: float, b: float) -> np.ndarray:
    """The paper's ``1 - (x-a)(x-b)/(|x-a||x-b|)``: 2 on ``[a, b)``, 0 elsewhere (a < b)."""
    return 1.0 - unit_sign(np.asarray(x, dtype=np.float64) - a) * unit_sign(
        np.asarray(x, dtype=np.float64) - b
    )


def cot(u: ArrayLike) -> np.ndarray:
    with np.errstate(divide="ignore", over="ignore"):  # 1/0 and 1/subnormal are +-inf
        return 1.0 / E.call("tan", u)


def sec(u: ArrayLike) -> np.ndarray:
    with np.errstate(divide="ignore", over="ignore"):
        return 1.0 / E.call("cos", u)


def csc(u: ArrayLike) -> np.ndarray:
    with np.errstate(divide="ignore", over="ignore"):
        return 1.0 / E.call("sin", u)


def acot(u: ArrayLike) -> np.ndarray:
    """Maple's principal arccot, range (0, pi): ``pi/2 - atan(u)``."""
    return np.pi / 2 - E.call("atan", u)


def acot_cot(u: ArrayLike) -> np.ndarray:
    """``acot(cot(u)) = u mod pi`` in ``[0, pi)``, in closed form."""
    return E.round_trip("acotcot", u)


def _check(cond: bool, message: str) -> None:
    if not cond:
        raise FormulaError(message)


def _check_r_p(name: str, r: float, p: float) -> int:
    _check(math.isfinite(r) and r > 0, f"{name}: r must be a finite number > 0, got {r}")
    _check(
        float(p).is_integer() and 0 <= p <= 10_000,
        f"{name}: p must be a whole number from 0 to 10000, got {p}",
    )
    return int(p)


# ----------------------------------------------------------------------------- eq. (1)


def fcc(x: ArrayLike, points: list[tuple[float, float]] | tuple) -> np.ndarray:
    """Eq. (1): the piecewise-segment curve through ``points`` [(x1, y1), ..., (xn+1, yn+1)]."""
    _check(len(points) >= 2, f"fcc needs at least 2 points, got {len(points)}")
    xs = [float(p[0]) for p in points]
    _check(
        all(b > a for a, b in zip(xs, xs[1:], strict=False)),
        "fcc: the x of the points must be strictly increasing",
    )
    x = np.asarray(x, dtype=np.float64)
    total = np.zeros(np.shape(x))
    for (x0, y0), (x1, y1) in zip(points, points[1:], strict=False):
        line = ((y1 - y0) * x + y0 * x1 - y1 * x0) / (x1 - x0)
        total = total + segment_selector(x, x0, x1) * line
    return 0.5 * total


def fcc_segments(x: ArrayLike, segments=FIGURE_1_1_SEGMENTS) -> np.ndarray:
    """A curve of segments ``(a, b, slope, intercept)``; the default is Figure 1.1."""
    x = np.asarray(x, dtype=np.float64)
    total = np.zeros(np.shape(x))
    for a, b, slope, intercept in segments:
        total = total + segment_selector(x, a, b) * (slope * x + intercept)
    return 0.5 * total


def fcc8(x: ArrayLike) -> np.ndarray:
    """The eight-segment curve of Figure 1.1."""
    return fcc_segments(x, FIGURE_1_1_SEGMENTS)


# ----------------------------------------------------------------------------- series (2)-(4)


def _series_sum(x: np.ndarray, r: float, p: int) -> np.ndarray:
    """``sum_{i=-p}^{p} (1 - s_i(x)) (x - r(i-1))``, the common core of eqs (2)-(4)."""
    total = np.zeros(np.shape(x))
    for i in range(-p, p + 1):
        a = r * (i - 1)
        total = total + segment_selector(x, a, r * i) * (x - a)
    return total


def saw1(x: ArrayLike, r: float, p: float) -> np.ndarray:
    """Eq. (2): saw-tooth series of base r on ``[-(p+1)r, pr)``."""
    p = _check_r_p("saw1", r, p)
    x = np.asarray(x, dtype=np.float64)
    return _series_sum(x, r, p) / (2.0 * r)


def tri1(x: ArrayLike, r: float, p: float) -> np.ndarray:
    """Eq. (3): triangular series of base r on ``[-(p+1)r, pr)``."""
    p = _check_r_p("tri1", r, p)
    x = np.asarray(x, dtype=np.float64)
    return np.abs(_series_sum(x, r, p) / r - 1.0)


def stair1(x: ArrayLike, r: float, h: float, p: float) -> np.ndarray:
    """Eq. (4): staircase of step width r and height h on ``[-(p+1)r, pr)``."""
    p = _check_r_p("stair1", r, p)
    _check(math.isfinite(h), f"stair1: h must be a finite number, got {h}")
    x = np.asarray(x, dtype=np.float64)
    return h / r * (x - 0.5 * _series_sum(x, r, p))


# ----------------------------------------------------------------------------- rectangular pulses


def rect1(x: ArrayLike, t: float) -> np.ndarray:
    """Eq. (5): ``1/2 - 1/2 (sin(pi x) + t)/|sin(pi x) + t|``, |t| < 1."""
    _check(abs(t) < 1, f"rect1: t must satisfy |t| < 1, got {t}")
    return 0.5 - 0.5 * unit_sign(E.call("sin", np.pi * np.asarray(x, dtype=np.float64)) + t)


def rect2(x: ArrayLike, r: float, t: float) -> np.ndarray:
    """Eq. (6): ``t/r - arccot(cot(pi (x+t)/r))/pi + arccot(cot(pi x/r))/pi``, t/r not whole."""
    _check(math.isfinite(r) and r > 0, f"rect2: r must be a finite number > 0, got {r}")
    _check(math.isfinite(t), f"rect2: t must be a finite number, got {t}")
    _check(not float(t / r).is_integer(), f"rect2: t/r must not be a whole number, got {t / r}")
    x = np.asarray(x, dtype=np.float64)
    return t / r - acot_cot(np.pi * (x + t) / r) / np.pi + acot_cot(np.pi * x / r) / np.pi


def _ratio(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a/b`` with 0/0 read as its limit 1 (both sides are the same angle to first order)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        q = a / b
    return np.where((a == 0) & (b == 0), 1.0, q)


def rect3(x: ArrayLike, t: float) -> np.ndarray:
    """Eq. (7): ``1/2 (asin(sin u)/atan(tan u) * atan(tan v)/asin(sin v) - 1)``, u=pi x, v=pi(x+t)."""
    _check(math.isfinite(t), f"rect3: t must be a finite number, got {t}")
    _check(not float(t).is_integer(), f"rect3: t must not be a whole number, got {t}")
    u = np.pi * np.asarray(x, dtype=np.float64)
    v = np.pi * (np.asarray(x, dtype=np.float64) + t)
    first = _ratio(E.round_trip("asinsin", u), E.round_trip("atantan", u))
    second = _ratio(E.round_trip("atantan", v), E.round_trip("asinsin", v))
    return 0.5 * (first * second - 1.0)


# ----------------------------------------------------------------------------- trigonometric forms


def _check_r(name: str, r: float) -> None:
    _check(math.isfinite(r) and r > 0, f"{name}: r must be a finite number > 0, got {r}")


def saw2(x: ArrayLike, r: float) -> np.ndarray:
    """Eq. (9): ``arccot(cot(pi x/r))/pi``."""
    _check_r("saw2", r)
    return acot_cot(np.pi * np.asarray(x, dtype=np.float64) / r) / np.pi


def tri2(x: ArrayLike, r: float) -> np.ndarray:
    """Eq. (10): ``arccos(cos(2 pi x/r))/pi``."""
    _check_r("tri2", r)
    return E.round_trip("acoscos", 2.0 * np.pi * np.asarray(x, dtype=np.float64) / r) / np.pi


def tri3(x: ArrayLike, r: float) -> np.ndarray:
    """Eq. (11): ``|2/pi arccot(cot(pi x/r)) - 1|``."""
    _check_r("tri3", r)
    return np.abs(2.0 / np.pi * acot_cot(np.pi * np.asarray(x, dtype=np.float64) / r) - 1.0)


def stair2(x: ArrayLike, r: float, h: float) -> np.ndarray:
    """Eq. (12): ``h (x/r - arccot(cot(pi x/r))/pi)``."""
    _check_r("stair2", r)
    _check(math.isfinite(h), f"stair2: h must be a finite number, got {h}")
    x = np.asarray(x, dtype=np.float64)
    return h * (x / r - acot_cot(np.pi * x / r) / np.pi)


# ----------------------------------------------------------------------------- eq. (8)


def power_function(
    x: ArrayLike, y: ArrayLike, z: ArrayLike, terms: list[tuple[float, float, float, float]]
) -> np.ndarray:
    """Eq. (8): ``sum a x^b y^c z^d`` over ``terms`` [(a, b, c, d), ...] (broadcasting)."""
    _check(len(terms) >= 1, "power function needs at least one term")
    x, y, z = (np.asarray(v, dtype=np.float64) for v in (x, y, z))
    with np.errstate(all="ignore"):
        return sum(  # type: ignore[return-value]
            a * E.power(x, b) * E.power(y, c) * E.power(z, d) for a, b, c, d in terms
        )
