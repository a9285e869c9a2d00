"""The constituent functions (eqs 1-12) against independent closed forms.

Each function of :mod:`surfgen.generator.formula.constituents` is written as the paper writes it (sums of
``u/|u|`` selectors, ``arccot(cot(.))``, ...). Here each is compared with a closed form written
with ``floor`` only: on dense samples, at random points (hypothesis), and exactly at the nodes,
where the paper's form is 0/0 or depends on the rounding of ``tan`` (never NaN: the value
documented in the module docstring).

Where the paper's alternative forms agree and where they differ (``frac(u) = u - floor(u)``,
``k`` an integer, ``D = [-(p+1) r, p r)`` the domain of the series forms, ``a = asin(t)/pi``):

==============================  =================================  ==============================================
forms                           agree                              differ
==============================  =================================  ==============================================
saw1 (2) / saw2 (9)             frac(x/r) on D; period r           saw1 = 0 outside D; at x = k r saw1 = 0,
                                                                   saw2 = 0 or 1 (rounding of tan)
tri1 (3) / tri3 (11)            |2 frac(x/r) - 1| on D; 1 at x=kr  tri1 = 1 outside D
tri2 (10) / tri3 (11)           tri2 = 1 - tri3 = tri3(x + r/2)    phase r/2: tri2 is 0 at x = k r, tri3 is 1
                                everywhere, nodes included
stair1 (4) / stair2 (12)        h floor(x/r) on D                  stair1 = h x/r (a ramp) outside D; at x = k r
                                                                   stair1 = h k, stair2 = h k or h (k-1)
rect1 (5)                       values {0, 1}, period 2            open pulses x mod 2 in (1+a, 2-a), duty 1/2-a;
                                = rect2(x + a; r=2, t=1-2a)        t = 0 gives the square wave rect2(x; 2, 1)
rect2 (6)                       floor((x+t)/r) - floor(x/r)        values {floor(t/r), floor(t/r)+1}, period r,
                                                                   duty frac(t/r)
rect3 (7)                       = -rect2(x + 1/2; r=1, t)          values {-1, 0} (inverted), period 1 (not 2),
                                for 0 < t < 1                      duty |t - 2 round(t/2)|; t -> t+1 complements
==============================  =================================  ==============================================

fcc (1) interpolates its points on [x_1, x_{n+1}) (np.interp) and is 0 outside, including at
x_{n+1}; fcc8 is the eight segments of Figure 1.1 as the paper prints them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from surfgen.generator.errors import FormulaError
from surfgen.generator.eval.reference import evaluate_points
from surfgen.generator.formula import constituents as cf
from surfgen.generator.formula.parser import parse

SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

DENSE = np.linspace(-20.0, 20.0, 40_001)  # step 1e-3: hits k r exactly for r in {0.5, 1, 2}
EXACT_R = (0.25, 0.5, 1.0, 2.0, 4.0)  # k r is exact, so nodes are exact


def frac(u: np.ndarray) -> np.ndarray:
    return u - np.floor(u)


def away(u: np.ndarray, eps: float = 1e-9) -> np.ndarray:
    """True where ``u`` is not within a relative ``eps`` of an integer (a node)."""
    u = np.asarray(u, dtype=np.float64)
    return np.abs(u - np.round(u)) > eps * np.maximum(1.0, np.abs(u))


def inside(x: np.ndarray, r: float, p: int) -> np.ndarray:
    return (x >= -(p + 1) * r) & (x < p * r)


def close(a, b, scale=1.0, tol: float = 1e-9) -> None:
    np.testing.assert_allclose(a, b, rtol=0, atol=tol * np.max(np.abs(scale) + 1.0))


# ----------------------------------------------------------------------------- closed forms


def saw1_closed(x, r, p):
    return np.where(inside(x, r, p), frac(x / r), 0.0)


def tri1_closed(x, r, p):
    return np.where(inside(x, r, p), np.abs(2 * frac(x / r) - 1), 1.0)


def stair1_closed(x, r, h, p):
    return np.where(inside(x, r, p), h * np.floor(x / r), h * x / r)


def tri3_closed(x, r):
    return np.abs(2 * frac(x / r) - 1)


def tri2_closed(x, r):
    return 2 * np.abs(x / r - np.round(x / r))  # twice the distance to the nearest node


def rect1_closed(x, t):
    a = math.asin(t) / math.pi
    c = np.mod(x - 1 - a, 2.0)  # the pulse is x in (1 + a, 2 - a) mod 2, width 1 - 2a
    return ((c > 0) & (c < 1 - 2 * a)).astype(float)


def rect2_closed(x, r, t):
    return np.floor((x + t) / r) - np.floor(x / r)


def rect3_closed(x, t):
    flips = np.floor(x + t + 0.5) - np.floor(x + 0.5)  # sign changes of cos(pi u) in (x, x+t]
    return -np.mod(flips, 2.0)


# ----------------------------------------------------------------------------- series (2)-(4)


@pytest.mark.parametrize("r", [0.3, 1.0, 2.0, 1.7])
@pytest.mark.parametrize("p", [0, 1, 3])
def test_series_forms_on_dense_samples(r: float, p: int) -> None:
    x, ok = DENSE, away(DENSE / r)
    saw, tri, stair = cf.saw1(x, r, p), cf.tri1(x, r, p), cf.stair1(x, r, 0.7, p)
    for got in (saw, tri, stair):
        assert np.isfinite(got).all()
    close(saw[ok], saw1_closed(x, r, p)[ok], x / r)
    close(tri[ok], tri1_closed(x, r, p)[ok], x / r)
    close(stair[ok], stair1_closed(x, r, 0.7, p)[ok], x / r)
    assert np.all(saw[x < -(p + 1) * r] == 0) and np.all(saw[x >= p * r] == 0)
    assert np.all(tri[x < -(p + 1) * r] == 1) and np.all(tri[x >= p * r] == 1)


@pytest.mark.parametrize("r", EXACT_R + (0.3, 1.7))
@pytest.mark.parametrize("p", [0, 2])
def test_series_forms_at_nodes(r: float, p: int) -> None:
    """At x = k r (the 0/0 of the paper's selectors) saw1 = 0, tri1 = 1, stair1 = h k."""
    k = np.arange(-(p + 4), p + 5, dtype=float)
    x = r * k
    np.testing.assert_array_equal(cf.saw1(x, r, p), 0.0)
    np.testing.assert_array_equal(cf.tri1(x, r, p), 1.0)
    np.testing.assert_allclose(cf.stair1(x, r, 0.7, p), 0.7 * k, rtol=1e-14, atol=1e-14)
    # Right-continuous at every node inside the domain: the value of the segment that starts there.
    right = x + 1e-9 * r
    np.testing.assert_allclose(cf.saw1(right, r, p), saw1_closed(right, r, p), atol=1e-8)


@SETTINGS
@given(
    st.lists(st.floats(-60, 60), min_size=1, max_size=30),
    st.floats(0.05, 8.0),
    st.integers(0, 6),
    st.floats(-5.0, 5.0),
)
def test_series_forms_at_random_points(xs: list[float], r: float, p: int, h: float) -> None:
    x = np.array(xs + [r * k for k in range(-(p + 2), p + 3)])  # random points and nodes
    saw, tri, stair = cf.saw1(x, r, p), cf.tri1(x, r, p), cf.stair1(x, r, h, p)
    assert np.isfinite(saw).all() and np.isfinite(tri).all() and np.isfinite(stair).all()
    ok = away(x / r)
    close(saw[ok], saw1_closed(x, r, p)[ok], x / r)
    close(tri[ok], tri1_closed(x, r, p)[ok], x / r)
    close(stair[ok], stair1_closed(x, r, h, p)[ok], h * x / r)
    # [0, 1): 1 only by rounding just below a node (x = -1e-300 gives (r - 1e-300)/r = 1)
    assert np.all((saw >= 0) & (saw <= 1)) and np.all((tri >= 0) & (tri <= 1))


# ----------------------------------------------------------------------------- trig forms (9)-(12)


@pytest.mark.parametrize("r", [0.3, 0.5, 1.0, 2.5])
def test_trigonometric_forms_on_dense_samples(r: float) -> None:
    x, ok = DENSE, away(DENSE / r)
    saw, tri2, tri3, stair = cf.saw2(x, r), cf.tri2(x, r), cf.tri3(x, r), cf.stair2(x, r, 1.5)
    for got in (saw, tri2, tri3, stair):
        assert np.isfinite(got).all()
    close(saw[ok], frac(x / r)[ok], x / r)
    close(stair[ok], 1.5 * np.floor(x / r)[ok], x / r)
    close(tri3, tri3_closed(x, r), x / r)  # continuous: nodes included
    close(tri2, tri2_closed(x, r), tol=1e-7)  # arccos near 1 loses half the digits
    assert np.all((saw >= 0) & (saw <= 1)) and np.all((tri2 >= 0) & (tri2 <= 1))


@pytest.mark.parametrize("r", EXACT_R + (0.3, 0.7))
def test_trigonometric_forms_at_nodes(r: float) -> None:
    """At x = k r saw2 is 0 or 1 and stair2 one of its two steps (rounding of tan); never NaN."""
    k = np.arange(-12, 13, dtype=float)
    x, h = r * k, 1.5
    saw, stair = cf.saw2(x, r), cf.stair2(x, r, h)
    assert np.all(np.isclose(saw, 0, atol=1e-12) | np.isclose(saw, 1, atol=1e-12))
    at_step = np.isclose(stair, h * k, atol=1e-12) | np.isclose(stair, h * (k - 1), atol=1e-12)
    assert np.all(at_step)
    np.testing.assert_allclose(cf.tri3(x, r), 1.0, atol=1e-12)
    np.testing.assert_allclose(cf.tri2(x, r), 0.0, atol=1e-7)
    np.testing.assert_allclose(cf.tri2(x + r / 2, r), 1.0, atol=1e-12)  # peaks between nodes
    np.testing.assert_allclose(cf.tri3(x + r / 2, r), 0.0, atol=1e-12)


@SETTINGS
@given(st.lists(st.floats(-200, 200), min_size=1, max_size=30), st.floats(0.05, 8.0))
def test_trigonometric_forms_at_random_points(xs: list[float], r: float) -> None:
    x = np.array(xs + [r * k for k in range(-3, 4)])
    ok = away(x / r)
    saw, stair = cf.saw2(x, r), cf.stair2(x, r, 2.0)
    assert np.isfinite(saw).all() and np.isfinite(stair).all()
    close(saw[ok], frac(x / r)[ok], x / r)
    close(stair[ok], 2.0 * np.floor(x / r)[ok], x / r)
    close(cf.tri3(x, r), tri3_closed(x, r), x / r)
    close(cf.tri2(x, r), tri2_closed(x, r), tol=1e-7)


# ----------------------------------------------------------------------------- rectangular (5)-(7)


@pytest.mark.parametrize("t", [0.0, 0.3, -0.3, 0.9, -0.99])
def test_rect1(t: float) -> None:
    x = DENSE
    got = cf.rect1(x, t)
    np.testing.assert_array_equal(got, (np.sin(np.pi * x) < -t).astype(float))  # eq. (5) exactly
    a = math.asin(t) / math.pi
    ok = away(x - a) & away(x + a)  # the pulse edges x = 1 + a, 2 - a (mod 2)
    np.testing.assert_array_equal(got[ok], rect1_closed(x, t)[ok])
    assert set(np.unique(got)) <= {0.0, 1.0}
    np.testing.assert_allclose(got.mean(), 0.5 - a, atol=1e-3)  # duty cycle


def test_rect1_is_zero_on_its_edges() -> None:
    """Where sin(pi x) + t is exactly 0 the paper's u/|u| is 0/0; we read +1, so rect1 = 0."""
    assert cf.rect1(0.0, 0.0) == 0.0
    for x0 in (1 / 6, 0.3, 1.25):
        t = -float(np.sin(np.pi * x0))
        assert cf.rect1(x0, t) == 0.0
        assert np.isfinite(cf.rect1(np.array([x0]), t)).all()


@pytest.mark.parametrize(
    ("r", "t"), [(1.0, 0.25), (2.0, 0.5), (0.7, 0.3), (1.0, 1.5), (1.0, -0.25)]
)
def test_rect2(r: float, t: float) -> None:
    x = DENSE
    got = cf.rect2(x, r, t)
    ok = away(x / r) & away((x + t) / r)
    close(got[ok], rect2_closed(x, r, t)[ok], tol=1e-12)
    lo = math.floor(t / r)
    assert np.all(np.isclose(got, lo, atol=1e-9) | np.isclose(got, lo + 1, atol=1e-9))
    np.testing.assert_allclose(got.mean(), t / r, atol=2e-3)  # duty cycle frac(t/r), plus floor


@pytest.mark.parametrize(("r", "t"), [(1.0, 0.25), (0.5, 0.2), (2.0, 0.5), (0.7, 0.3)])
def test_rect2_at_nodes_takes_a_one_sided_limit(r: float, t: float) -> None:
    k = np.arange(-10, 11, dtype=float)
    for x in (r * k, r * k - t):  # the two families of jumps
        got = cf.rect2(x, r, t)
        left, right = rect2_closed(x - 1e-7 * r, r, t), rect2_closed(x + 1e-7 * r, r, t)
        assert np.all(np.isclose(got, left, atol=1e-9) | np.isclose(got, right, atol=1e-9))


@pytest.mark.parametrize("t", [0.25, 0.5, 0.75, 1.3, -0.4, 2.6])
def test_rect3(t: float) -> None:
    x = DENSE
    got = cf.rect3(x, t)
    assert np.isfinite(got).all()
    ok = away(x + 0.5) & away(x + t + 0.5)
    close(got[ok], rect3_closed(x, t)[ok], tol=1e-9)
    assert np.all(np.isclose(got, 0, atol=1e-9) | np.isclose(got, -1, atol=1e-9))
    close(got[ok], np.where(np.cos(np.pi * x) * np.cos(np.pi * (x + t)) < 0, -1.0, 0.0)[ok])
    duty = abs(t - 2 * round(t / 2))
    np.testing.assert_allclose(got.mean(), -duty, atol=2e-3)


def test_rect3_at_nodes_and_at_its_removable_zeros() -> None:
    t = 0.25
    k = np.arange(-10, 11, dtype=float)
    for x in (k + 0.5, k + 0.5 - t):  # jumps: cos(pi x) = 0 or cos(pi (x+t)) = 0
        got = cf.rect3(x, t)
        left, right = rect3_closed(x - 1e-7, t), rect3_closed(x + 1e-7, t)
        assert np.all(np.isclose(got, left, atol=1e-9) | np.isclose(got, right, atol=1e-9))
    # asin(sin u)/atan(tan u) is 0/0 at u = 0 exactly: the limit 1 is used (no NaN, no jump).
    np.testing.assert_allclose(cf.rect3(np.array([0.0, -0.25]), 0.25), 0.0, atol=1e-12)
    np.testing.assert_allclose(cf.rect3(np.array([0.0, -0.75]), 0.75), -1.0, atol=1e-12)


@SETTINGS
@given(
    st.lists(st.floats(-30, 30), min_size=1, max_size=30),
    st.floats(0.1, 5.0),
    st.floats(-3.0, 3.0).filter(lambda t: abs(t - round(t)) > 1e-3),
)
def test_rect_forms_at_random_points(xs: list[float], r: float, t: float) -> None:
    x = np.array(xs)
    if abs(t / r - round(t / r)) > 1e-3:
        ok = away(x / r, 1e-7) & away((x + t) / r, 1e-7)
        close(cf.rect2(x, r, t)[ok], rect2_closed(x, r, t)[ok], tol=1e-9)
    ok = away(x + 0.5, 1e-7) & away(x + t + 0.5, 1e-7)
    close(cf.rect3(x, t)[ok], rect3_closed(x, t)[ok], tol=1e-9)
    s = t / 3.0  # |s| < 1
    got = cf.rect1(x, s)
    np.testing.assert_array_equal(got, (np.sin(np.pi * x) < -s).astype(float))
    a = math.asin(s) / math.pi
    ok = away(x - a, 1e-7) & away(x + a, 1e-7)
    np.testing.assert_array_equal(got[ok], rect1_closed(x, s)[ok])


# ----------------------------------------------------------------------------- relations (table)


def test_saw1_equals_saw2_on_its_domain_only() -> None:
    r, p, x = 0.5, 3, DENSE
    ok, dom = away(x / r), inside(x, r, p)
    close(cf.saw1(x, r, p)[ok & dom], cf.saw2(x, r)[ok & dom], x / r)
    outside = ok & ~dom
    assert np.all(cf.saw1(x, r, p)[outside] == 0) and np.any(cf.saw2(x, r)[outside] > 0.5)


def test_tri1_tri2_tri3() -> None:
    r, p, x = 0.5, 3, DENSE
    ok, dom = away(x / r), inside(x, r, p)
    close(cf.tri1(x, r, p)[ok & dom], cf.tri3(x, r)[ok & dom], x / r)
    close(cf.tri2(x, r), 1.0 - cf.tri3(x, r), tol=1e-7)
    close(cf.tri2(x, r), cf.tri3(x + r / 2, r), tol=1e-7)  # the same wave shifted by r/2
    assert np.all(cf.tri1(x, r, p)[~dom] == 1)


def test_stair1_equals_stair2_on_its_domain_and_ramps_outside() -> None:
    r, h, p, x = 0.5, 0.3, 3, DENSE
    ok, dom = away(x / r), inside(x, r, p)
    close(cf.stair1(x, r, h, p)[ok & dom], cf.stair2(x, r, h)[ok & dom], x / r)
    close(cf.stair1(x, r, h, p)[~dom], (h * x / r)[~dom], x / r)


def test_rect1_is_a_shifted_rect2_and_rect3_an_inverted_rect2() -> None:
    x = DENSE
    for t in (0.0, 0.4, -0.7):
        a = math.asin(t) / math.pi
        ok = away(x - a) & away(x + a)
        close(cf.rect1(x, t)[ok], cf.rect2(x + a, 2.0, 1 - 2 * a)[ok], tol=1e-9)
    for t in (0.25, 0.6):
        ok = away(x + 0.5) & away(x + t + 0.5)
        close(cf.rect3(x, t)[ok], -cf.rect2(x + 0.5, 1.0, t)[ok], tol=1e-9)
        close(cf.rect3(x, t + 1)[ok], -1.0 - cf.rect3(x, t)[ok], tol=1e-9)  # complement


def test_periods() -> None:
    x = np.linspace(-3.0, 3.0, 6001) + 1e-4  # off the nodes of all the parameters used below
    close(cf.rect1(x + 2, 0.3), cf.rect1(x, 0.3), tol=0)
    close(cf.rect2(x + 0.7, 0.7, 0.2), cf.rect2(x, 0.7, 0.2), tol=1e-9)
    close(cf.rect3(x + 1, 0.25), cf.rect3(x, 0.25), tol=1e-9)  # period 1, not 2
    assert not np.allclose(cf.rect1(x + 1, 0.3), cf.rect1(x, 0.3))
    close(cf.saw2(x + 0.6, 0.6), cf.saw2(x, 0.6), tol=1e-9)
    close(cf.tri2(x + 0.6, 0.6), cf.tri2(x, 0.6), tol=1e-7)


# ----------------------------------------------------------------------------- fcc (1) and fcc8


def test_fcc_interpolates_its_points() -> None:
    pts = [(0.0, 1.0), (1.0, 3.0), (2.5, -1.0), (4.0, 0.5)]
    xs, ys = np.array(pts).T
    x = np.linspace(-1.0, 5.0, 6001)
    got = cf.fcc(x, pts)
    dom = (x >= xs[0]) & (x < xs[-1])
    close(got[dom], np.interp(x, xs, ys)[dom], tol=1e-12)
    assert np.all(got[~dom] == 0)
    # Nodes: y_i at x_1..x_n (continuous there), 0 at the last node x_{n+1} (half-open domain).
    np.testing.assert_allclose(cf.fcc(xs, pts), [*ys[:-1], 0.0], atol=1e-15)


@SETTINGS
@given(
    st.lists(st.floats(-10, 10), min_size=2, max_size=8, unique=True),
    st.lists(st.floats(-10, 10), min_size=8, max_size=8),
    st.lists(st.floats(-12, 12), min_size=1, max_size=30),
)
def test_fcc_at_random_points(xs: list[float], ys: list[float], x: list[float]) -> None:
    xs = sorted(xs)
    if min(np.diff(xs)) < 1e-2:
        return
    pts = list(zip(xs, ys[: len(xs)], strict=False))
    px, py = np.array(pts).T
    x_all = np.array(x + xs)
    got = cf.fcc(x_all, pts)
    dom = (x_all >= px[0]) & (x_all < px[-1])
    close(got[dom], np.interp(x_all, px, py)[dom], tol=1e-11, scale=10.0)
    assert np.all(got[~dom] == 0)


FIGURE_1_1_NODES = [  # (x, value at x) with the [a, b) convention
    (0.0, 0.0),
    (1.0, 0.0),
    (2.0, 1.0),
    (3.0, 3.0),
    (4.0, 6.0),
    (5.0, 7.0),  # jump: 2 from the left (-4x+22), 7 from the right (x/2+9/2)
    (7.0, 1.0),  # jump: 8 from the left
    (9.0, 1.0),  # continuous: constant 1 meets -x+10
    (10.0, 5.0),  # jump: 0 from the left
    (10.5, 0.0),  # the last node is outside
    (11.0, 0.0),
]


def test_fcc8_is_its_eight_segments() -> None:
    assert len(cf.FIGURE_1_1_SEGMENTS) == 8
    x = np.linspace(0.0, 11.0, 11_001)
    expected = np.zeros_like(x)
    for a, b, slope, intercept in cf.FIGURE_1_1_SEGMENTS:
        seg = (x >= a) & (x < b)
        expected[seg] = slope * x[seg] + intercept
    close(cf.fcc8(x), expected, tol=1e-13)
    nodes, values = np.array(FIGURE_1_1_NODES).T
    np.testing.assert_allclose(cf.fcc8(nodes), values, atol=1e-14)


def test_fcc8_equals_the_formula_printed_in_the_paper() -> None:
    """f_cc = 0.5 (f_cc1 + f_cc2) exactly as printed under eq. (1), read away from its nodes."""

    def s(a: float, b: float) -> str:
        return f"(x-{a})*(x-{b})/(abs(x-{a})*abs(x-{b}))"

    fcc1 = (
        f"(1-{s(1, 2)})*(x-1) + (1-{s(2, 3)})*(2*x-3) + (1-{s(3, 4)})*(3*x-6)"
        f" + (1-{s(4, 5)})*(-4*x+22)"
    )
    fcc2 = f"(1-{s(5, 7)})*(1/2*x+9/2) + 6 - {s(7, 9)} + (1-{s(9, 10)})*(-x+10) - 5*{s(10, 10.5)}"
    printed = parse(f"0.5*(({fcc1}) + ({fcc2}))")
    x = np.linspace(0.0, 11.0, 11_001)
    ok = away(2 * x)  # the nodes 1, 2, ..., 10, 10.5 are multiples of 1/2
    close(evaluate_points(printed, x, 0.0, 0.0)[ok], cf.fcc8(x)[ok], tol=1e-12)


def test_fcc_through_the_formula_language() -> None:
    tree = parse("fcc(x, 0,1, 1,3, 2.5,-1)")
    x = np.array([-1.0, 0.0, 0.5, 1.0, 2.0, 2.5, 3.0])
    expected = np.where((x >= 0) & (x < 2.5), np.interp(x, [0, 1, 2.5], [1, 3, -1]), 0.0)
    close(evaluate_points(tree, x, 0.0, 0.0), expected, tol=1e-14)


# ----------------------------------------------------------------------------- power function (8)


def test_power_function_against_a_direct_sum() -> None:
    terms = [(2.0, 1.0, 0.0, 3.0), (-0.5, 2.0, 2.0, -1.0), (1.5, 0.5, 1.0, 0.0)]
    x = np.array([0.5, 1.0, 2.0, 3.0])
    y = np.array([1.5, -2.0, 0.25, 1.0])
    z = np.array([2.0, 1.0, -0.5, 4.0])
    expected = [
        sum(a * xi**b * yi**c * zi**d for a, b, c, d in terms)
        for xi, yi, zi in zip(x, y, z, strict=True)
    ]
    close(cf.power_function(x, y, z, terms), expected, tol=1e-14, scale=100.0)
    text = "powf(" + ",".join(str(v) for term in terms for v in term) + ")"
    close(evaluate_points(parse(text), x, y, z), expected, tol=1e-14, scale=100.0)
    # A negative base with a non-integer exponent is NaN (C pow), not an error.
    assert np.isnan(cf.power_function(-1.0, 1.0, 1.0, [(1.0, 0.5, 0.0, 0.0)]))


# ----------------------------------------------------------------------------- validation


BAD_PARAMETERS = [
    (lambda: cf.saw1(0.0, 0.0, 2), r"saw1: r must be a finite number > 0, got 0"),
    (lambda: cf.saw1(0.0, -1.0, 2), r"saw1: r must be a finite number > 0, got -1"),
    (lambda: cf.tri1(0.0, math.inf, 2), r"tri1: r must be a finite number > 0, got inf"),
    (lambda: cf.tri1(0.0, math.nan, 2), r"tri1: r must be a finite number > 0, got nan"),
    (lambda: cf.saw1(0.0, 1.0, 1.5), r"saw1: p must be a whole number from 0 to 10000, got 1.5"),
    (lambda: cf.tri1(0.0, 1.0, -1), r"tri1: p must be a whole number from 0 to 10000, got -1"),
    (lambda: cf.stair1(0.0, 1.0, 1.0, 1e6), r"stair1: p must be a whole number"),
    (lambda: cf.stair1(0.0, 1.0, math.inf, 2), r"stair1: h must be a finite number, got inf"),
    (lambda: cf.rect1(0.0, 1.0), r"rect1: t must satisfy \|t\| < 1, got 1.0"),
    (lambda: cf.rect1(0.0, -1.5), r"rect1: t must satisfy \|t\| < 1, got -1.5"),
    (lambda: cf.rect1(0.0, math.nan), r"rect1: t must satisfy \|t\| < 1, got nan"),
    (lambda: cf.rect2(0.0, 0.0, 0.5), r"rect2: r must be a finite number > 0, got 0"),
    (lambda: cf.rect2(0.0, 0.5, 1.0), r"rect2: t/r must not be a whole number, got 2.0"),
    (lambda: cf.rect2(0.0, 1.0, 0.0), r"rect2: t/r must not be a whole number, got 0.0"),
    (lambda: cf.rect2(0.0, 1.0, -3.0), r"rect2: t/r must not be a whole number, got -3.0"),
    (lambda: cf.rect2(0.0, 1.0, math.inf), r"rect2: t must be a finite number, got inf"),
    (lambda: cf.rect3(0.0, 1.0), r"rect3: t must not be a whole number, got 1.0"),
    (lambda: cf.rect3(0.0, -2.0), r"rect3: t must not be a whole number, got -2.0"),
    (lambda: cf.rect3(0.0, math.nan), r"rect3: t must be a finite number, got nan"),
    (lambda: cf.saw2(0.0, 0.0), r"saw2: r must be a finite number > 0, got 0"),
    (lambda: cf.tri2(0.0, -2.0), r"tri2: r must be a finite number > 0, got -2"),
    (lambda: cf.tri3(0.0, 0.0), r"tri3: r must be a finite number > 0, got 0"),
    (lambda: cf.stair2(0.0, -1.0, 1.0), r"stair2: r must be a finite number > 0, got -1"),
    (lambda: cf.stair2(0.0, 1.0, math.nan), r"stair2: h must be a finite number, got nan"),
    (lambda: cf.fcc(0.0, [(0.0, 1.0)]), r"fcc needs at least 2 points, got 1"),
    (lambda: cf.fcc(0.0, [(1.0, 0.0), (1.0, 2.0)]), r"fcc: the x of the points must be strictly"),
    (lambda: cf.power_function(0.0, 0.0, 0.0, []), r"power function needs at least one term"),
]


@pytest.mark.parametrize(("make", "message"), BAD_PARAMETERS)
def test_bad_parameters_raise_formula_error(make, message: str) -> None:
    with pytest.raises(FormulaError, match=message) as info:
        make()
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("text", "params", "message"),
    [
        ("saw1(x, r, 2)", {"r": 0.0}, "saw1: r must be a finite number > 0"),
        ("tri1(x, 1, p)", {"p": 2.5}, "tri1: p must be a whole number"),
        ("rect1(x, t)", {"t": 1.0}, r"rect1: t must satisfy \|t\| < 1"),
        ("rect2(x, 0.5, 1)", {}, "rect2: t/r must not be a whole number"),
        ("rect3(x, 2*t)", {"t": 0.5}, "rect3: t must not be a whole number"),
        ("fcc(x, 1,0, 0,1)", {}, "fcc: the x of the points must be strictly increasing"),
    ],
)
def test_bad_parameters_through_the_formula_language(text: str, params: dict, message: str) -> None:
    tree = parse(text, params)
    with pytest.raises(FormulaError, match=message):
        evaluate_points(tree, np.linspace(-1, 1, 5), 0.0, 0.0, params)
