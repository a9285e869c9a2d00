"""Bounds of whole formulas over boxes (:func:`program_bounds`): sound against the fast
evaluator at the corners and random points of random boxes, for random formulas (hypothesis),
the 50 stored eq. (13) formulas and the sampler's draws of every family; the numba interpreter
within the numpy reference; poles, jumps, NaN and ±inf; the API's errors."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from surfgen.generator.errors import GridError
from surfgen.generator.eval import intervals
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.intervals import grid_point_bounds, program_bounds, tree_bounds
from surfgen.generator.eval.intervals_reference import reference_bounds
from surfgen.generator.formula.parser import parse
from surfgen.generator.model.families import family_choices
from surfgen.generator.model.presets import PRESETS
from surfgen.generator.model.sampler import SamplerConfig, draw_equation
from tests.support.interval_checks import assert_sound, random_boxes

FORMULAS = Path(__file__).parents[2] / "support" / "data" / "eq13_formulas.jsonl"
STORED = [json.loads(line) for line in FORMULAS.read_text().splitlines() if line.strip()]


def assert_within_reference(program, blo, bhi) -> None:
    """The numba bounds lie inside the reference's, and are finite wherever they are."""
    flo, fhi, fin = program_bounds(program, blo, bhi)
    rlo, rhi, rfin = reference_bounds(program, blo, bhi)
    empty = flo > fhi
    assert np.all(empty | ((flo >= rlo) & (fhi <= rhi))), (
        np.argwhere(~(empty | ((flo >= rlo) & (fhi <= rhi)))),
        program.formula,
    )
    assert not np.any(rfin & ~fin)


# ----------------------------------------------------------------------------- random formulas

UNARY = ["sin", "cos", "tan", "cot", "sec", "csc", "asin", "acos", "atan", "acot", "sinh"]
UNARY += ["cosh", "tanh", "asinh", "acosh", "atanh", "exp", "log", "log10", "sqrt", "cbrt"]
UNARY += ["abs", "sign", "floor", "ceil", "int", "trunc", "-", "!"]
WRAPS = ["atan(tan({}))", "asin(sin({}))", "acos(cos({}))", "acot(cot({}))", "({0})/abs({0})"]
WRAPS += ["saw1({},0.3,3)", "tri1({},0.4,2)", "stair1({},0.5,1.5,3)", "rect1({},0.3)"]
WRAPS += ["rect2({},0.7,0.2)", "rect3({},0.35)", "saw2({},0.6)", "tri2({},0.8)", "tri3({},0.45)"]
WRAPS += ["stair2({},0.7,2)", "fcc({},0,0,1,2,2,-1,3,0.5)", "fcc8(3*{}+4)", "({})^2", "({})^0.5"]
WRAPS += ["({})^-1", "({})^3", "({})^1.5", "({})^-2", "({})^0.31", "2^({})", "({})^0"]
BINARY = ["+", "-", "*", "/", "^", "%", "<", "<=", ">", ">=", "=", "!=", "&", "|"]
CALLS2 = ["min", "max", "atan2"]
LEAVES = ["x", "y", "z", "x", "y", "z", "0", "1", "2", "0.5", "-1", "1.5", "pi", "1e-3", "3"]


def formulas() -> st.SearchStrategy[str]:
    leaf = st.sampled_from(LEAVES)

    def grow(inner: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
        return st.one_of(
            st.tuples(inner, st.sampled_from(BINARY), inner).map(
                lambda t: f"({t[0]}){t[1]}({t[2]})"
            ),
            st.tuples(st.sampled_from(UNARY), inner).map(
                lambda t: f"{t[0]}({t[1]})" if t[0] not in "-!" else f"{t[0]}({t[1]})"
            ),
            st.tuples(st.sampled_from(WRAPS), inner).map(lambda t: t[0].format(t[1])),
            st.tuples(st.sampled_from(CALLS2), inner, inner).map(
                lambda t: f"{t[0]}({t[1]},{t[2]})"
            ),
            st.tuples(inner, inner, inner).map(lambda t: f"if({t[0]},{t[1]},{t[2]})"),
        )

    return st.recursive(leaf, grow, max_leaves=12)


PROPERTY = settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))


@PROPERTY
@given(formulas(), st.integers(0, 2**32 - 1), st.sampled_from([0.2, 2.0, 20.0]))
def test_random_formulas_are_bounded_soundly(text: str, seed: int, half: float) -> None:
    """Property: for random formulas over every function, operator and constituent, random
    boxes (flat ones, points, boxes from 0) and points in them plus their corners, the fast
    evaluator's value is NaN or inside the bounds, and finite wherever ``finite`` says so;
    the reference's bounds are sound too and hold the numba ones."""
    tree = parse(text)
    rng = np.random.default_rng(seed)
    blo, bhi = random_boxes(rng, [-half] * 3, [half] * 3, 24)
    assert_sound(tree, {}, blo, bhi, rng)
    program = compile_tree(tree)
    assert_sound(tree, {}, blo, bhi, rng, reference_bounds(program, blo, bhi))
    assert_within_reference(program, blo, bhi)


@pytest.mark.parametrize("start", range(0, len(STORED), 10))
def test_stored_formulas_are_bounded_soundly(start: int) -> None:
    """The 50 stored eq. (13) formulas, 60 random boxes each in their own box."""
    rng = np.random.default_rng(start)
    for row in STORED[start : start + 10]:
        tree = parse(row["formula"])
        blo, bhi = random_boxes(rng, row["lo"], row["hi"], 60)
        assert_sound(tree, {}, blo, bhi, rng)
        assert_within_reference(compile_tree(tree), blo, bhi)


@pytest.mark.parametrize("family", [f for f in family_choices() if f != "mix"])
def test_drawn_equations_of_every_family_are_bounded_soundly(family: str) -> None:
    cfg = SamplerConfig(family=family)
    rng = np.random.default_rng(7)
    for index in range(6):
        draw = draw_equation(11, index, cfg)
        tree = draw.equation.to_tree()
        blo, bhi = random_boxes(rng, draw.box.lo, draw.box.hi, 40)
        assert_sound(tree, {}, blo, bhi, rng)
        assert_within_reference(compile_tree(tree), blo, bhi)


# ----------------------------------------------------------------------------- poles, jumps, NaN


def bounds1(text: str, lo: float, hi: float, axis: int = 0):
    """Bounds of ``text`` over one box whose ``axis`` range is ``[lo, hi]`` (others [0, 1])."""
    blo = np.array([[0.0, 0.0, 0.0]])
    bhi = np.array([[1.0, 1.0, 1.0]])
    blo[0, axis], bhi[0, axis] = lo, hi
    flo, fhi, fin = tree_bounds(parse(text), {}, blo, bhi)
    return float(flo[0]), float(fhi[0]), bool(fin[0])


@pytest.mark.parametrize(
    ("text", "lo", "hi"),
    [
        ("tan(x)", 1.5, 1.6),  # pi/2
        ("cot(x)", -0.1, 0.1),  # 0
        ("sec(x)", 4.7, 4.75),  # 3 pi/2
        ("csc(x)", 3.1, 3.2),  # pi
        ("1/x", -1.0, 1.0),
        ("1/x", 0.0, 1.0),
        ("log(x)", 0.0, 1.0),
        ("atanh(x)", 0.5, 1.0),
        ("x^-2", -1.0, 1.0),
        ("x^-3", 0.0, 1.0),
    ],
)
def test_a_pole_in_the_box_is_not_finite(text: str, lo: float, hi: float) -> None:
    flo, fhi, fin = bounds1(text, lo, hi)
    assert not fin and (flo == -math.inf or fhi == math.inf)


@pytest.mark.parametrize(
    ("text", "lo", "hi", "expect"),
    [
        ("tan(x)", 1.3, 1.5, (math.tan(1.3), math.tan(1.5))),
        ("cot(x)", 0.1, 3.0, (1 / math.tan(3.0), 1 / math.tan(0.1))),
        ("sec(x)", -1.0, 1.0, (1.0, 1 / math.cos(1.0))),
        ("log(x)", 0.5, 2.0, (math.log(0.5), math.log(2.0))),
        ("1/x", 0.5, 2.0, (0.5, 2.0)),
        ("x^-2", -2.0, -0.5, (0.25, 4.0)),
    ],
)
def test_away_from_its_poles_a_function_is_bounded_tightly(text, lo, hi, expect) -> None:
    flo, fhi, fin = bounds1(text, lo, hi)
    assert fin
    assert flo <= expect[0] and fhi >= expect[1]
    assert flo == pytest.approx(expect[0], rel=1e-13, abs=1e-300)
    assert fhi == pytest.approx(expect[1], rel=1e-13, abs=1e-300)


@pytest.mark.parametrize(
    ("text", "lo", "hi", "expect"),
    [
        ("saw2(x,1)", 0.9, 1.1, (0.0, 1.0)),  # a jump: the whole range
        ("saw2(x,1)", 0.2, 0.4, (0.2, 0.4)),  # between jumps: tight
        # x / r - frac(x / r): x twice, so interval arithmetic loses their dependency (the
        # range is [0, 2]; known looseness of stair2 and rect2)
        ("stair2(x,1,2)", 0.5, 1.5, (-1.0, 3.0)),
        ("stair1(x,1,2,5)", 1.2, 1.7, (1.0, 3.0)),  # x - (x - floor x): the same looseness
        ("atan(tan(x))", 1.0, 2.0, (-math.pi / 2, math.pi / 2)),
        ("atan(tan(x))", 2.0, 3.0, (2.0 - math.pi, 3.0 - math.pi)),
        ("floor(x)", 0.5, 2.5, (0.0, 2.0)),
        ("sign(x)", -1.0, 0.0, (-1.0, 0.0)),
        ("rect1(x,0.3)", 0.1, 0.9, (0.0, 0.0)),
        ("fcc8(x)", 4.5, 6.0, (2.0, 7.5)),  # -4x + 22 on [4, 5), x/2 + 4.5 on [5, 7)
        ("x%1", 2.2, 2.7, (0.2, 0.7)),
        ("x%1", 2.2, 3.7, (0.0, 1.0)),
    ],
)
def test_jumps_give_the_hull_and_pieces_their_range(text, lo, hi, expect) -> None:
    flo, fhi, fin = bounds1(text, lo, hi)
    assert fin
    assert flo == pytest.approx(expect[0], abs=1e-12)
    assert fhi == pytest.approx(expect[1], abs=1e-12)


def test_where_the_formula_is_nan_everywhere_the_box_is_empty_and_outside() -> None:
    for text, lo, hi in (("sqrt(x)", -2.0, -1.0), ("log(x)", -2.0, -1.0), ("asin(x)", 2, 3)):
        flo, fhi, fin = bounds1(text, lo, hi)
        assert flo == math.inf and fhi == -math.inf and not fin
    flo, fhi, fin = bounds1("sqrt(x)", -1.0, 4.0)  # part NaN: the rest is bounded
    assert (flo, fhi, fin) == (0.0, 2.0, False)
    assert bounds1("0/0+x", 0.0, 1.0) == (math.inf, -math.inf, False)


def test_nan_operands_propagate_except_where_the_evaluator_drops_them() -> None:
    # comparisons and if's condition read NaN as false; pow(NaN, 0) = 1 (the x^c convention)
    assert bounds1("sqrt(x) < 1", -2.0, -1.0) == (0.0, 0.0, True)
    assert bounds1("if(sqrt(x), 1, 2)", -2.0, -1.0) == (2.0, 2.0, True)
    assert bounds1("sqrt(x)^0", -2.0, -1.0) == (1.0, 1.0, True)
    assert bounds1("!sqrt(x)", -2.0, -1.0) == (1.0, 1.0, True)
    flo, fhi, fin = bounds1("min(sqrt(x), 1)", -2.0, 1.0)
    assert not fin and fhi <= 1.0


def test_infinite_values_and_boxes() -> None:
    assert bounds1("exp(x)", 700.0, 800.0)[1:] == (math.inf, False)
    assert bounds1("atan(x)", -math.inf, math.inf)[2]  # finite over the whole line
    flo, fhi, fin = bounds1("sin(x)", 0.0, math.inf)  # sin(inf) is NaN
    assert not fin and flo <= -1.0 and fhi >= 1.0
    flo, fhi, fin = bounds1("x*0", 0.0, math.inf)  # inf * 0 is NaN
    assert not fin and flo <= 0.0 <= fhi


def test_a_value_of_one_variable_depends_on_its_range_only() -> None:
    """A level-x value is bounded over the box's x range: y and z do not change it."""
    rng = np.random.default_rng(3)
    blo, bhi = random_boxes(rng, [-2] * 3, [2] * 3, 50)
    tree = parse("sin(3*x)^2 + atan(x)")
    flo, fhi, _ = tree_bounds(tree, {}, blo, bhi)
    blo2, bhi2 = blo.copy(), bhi.copy()
    blo2[:, 1:], bhi2[:, 1:] = -7.0, 9.0
    assert np.array_equal(tree_bounds(tree, {}, blo2, bhi2)[0], flo)
    flo3, fhi3, _ = tree_bounds(parse("x*y*z"), {}, blo, bhi)
    p = np.stack([blo, bhi])  # the 8 corners give the exact range of a product
    corners = np.array(
        [p[i, :, 0] * p[j, :, 1] * p[k, :, 2] for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    )
    assert np.all(flo3 <= corners.min(0)) and np.all(fhi3 >= corners.max(0))


def grid_boxes(lo, hi, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The n^3 cells of a grid over ``[lo, hi]`` as boxes (they share their axis ranges)."""
    edges = [np.linspace(lo[a], hi[a], n + 1) for a in range(3)]
    i, j, k = np.meshgrid(*[np.arange(n)] * 3, indexing="ij")
    blo = np.stack([edges[0][i], edges[1][j], edges[2][k]], axis=-1).reshape(-1, 3)
    bhi = np.stack([edges[0][i + 1], edges[1][j + 1], edges[2][k + 1]], axis=-1).reshape(-1, 3)
    return blo, bhi


@pytest.mark.parametrize("row", STORED[::7], ids=lambda r: r["formula"][:30])
def test_levels_shared_between_boxes_give_the_same_bounds(row) -> None:
    """Bounding each level once per distinct range (a grid of boxes) gives the bounds of
    bounding every level once per box, bit for bit; and they are sound."""
    program = compile_tree(parse(row["formula"]))
    blo, bhi = grid_boxes(row["lo"], row["hi"], 6)
    rng = np.random.default_rng(2)
    extra_lo, extra_hi = random_boxes(rng, row["lo"], row["hi"], 40)
    blo, bhi = np.concatenate([blo, extra_lo]), np.concatenate([bhi, extra_hi])
    shared = program_bounds(program, blo, bhi)
    plain = program_bounds(program, blo, bhi, share=False)
    for a, b in zip(shared, plain, strict=True):
        assert np.array_equal(a, b)
    assert_sound(program.tree, {}, blo, bhi, rng, shared)


def test_boxes_run_in_chunks_give_the_same_bounds(monkeypatch) -> None:
    program = compile_tree(parse(STORED[3]["formula"]))
    blo, bhi = grid_boxes(STORED[3]["lo"], STORED[3]["hi"], 4)
    whole = program_bounds(program, blo, bhi)
    monkeypatch.setattr(intervals, "BOXES_CHUNK", 7)
    for a, b in zip(whole, program_bounds(program, blo, bhi), strict=True):
        assert np.array_equal(a, b)
    # on threads, each a run of the chunks (three runs of four chunks, two of five)
    monkeypatch.setattr(intervals, "THREAD_BOXES", 20)
    calls = []
    real = intervals._run_chunk
    monkeypatch.setattr(intervals, "_run_chunk", lambda *a: calls.append(len(a[2])) or real(*a))
    for threads in (3, 2):
        calls.clear()
        for a, b in zip(whole, program_bounds(program, blo, bhi, threads=threads), strict=True):
            assert np.array_equal(a, b)
        assert sum(calls) == len(blo) and max(calls) <= 7 and len(calls) % threads == 0


def test_params_constants_and_many_boxes() -> None:
    tree = parse("a*x + b", ["a", "b"])
    blo = np.zeros((1000, 3))
    bhi = np.ones((1000, 3))
    bhi[:, 0] = np.linspace(0, 1, 1000)
    flo, fhi, fin = tree_bounds(tree, {"a": 2.0, "b": -1.0}, blo, bhi)
    assert np.all(flo == -1.0) and np.allclose(fhi, 2 * bhi[:, 0] - 1) and fin.all()
    flo, fhi, fin = tree_bounds(parse("3"), {}, blo[:5], bhi[:5])
    assert np.all(flo == 3.0) and np.all(fhi == 3.0) and fin.all()
    empty = tree_bounds(parse("x"), {}, np.zeros((0, 3)), np.zeros((0, 3)))
    assert [a.shape for a in empty] == [(0,), (0,), (0,)]


def test_bad_boxes_and_programs_are_refused() -> None:
    program = compile_tree(parse("x"))
    with pytest.raises(GridError, match=r"shape \(K, 3\)"):
        program_bounds(program, np.zeros((2, 2)), np.zeros((2, 2)))
    with pytest.raises(GridError, match="NaN"):
        program_bounds(program, np.full((1, 3), np.nan), np.zeros((1, 3)))
    with pytest.raises(GridError, match="lo > hi"):
        program_bounds(program, np.ones((1, 3)), np.zeros((1, 3)))
    with pytest.raises(TypeError, match="Program"):
        program_bounds("x", np.zeros((1, 3)), np.ones((1, 3)))  # type: ignore[arg-type]


# ----------------------------------------------------------------------------- grid points


def assert_grid_points_bounded(tree, params, grid: Grid, blocks: int, rng) -> None:
    """The grid-point bounds of boxes of grid points (blocks of the grid, and random ones)
    hold every sample's value (dense grid evaluator) or it is NaN; finite means finite."""
    axes = grid.axes()
    values = evaluate(tree, grid, params).values
    n = grid.shape[0]
    cuts = np.linspace(0, n - 1, blocks + 1).round().astype(int)
    spans = [(cuts[i], cuts[i + 1]) for i in range(blocks)]
    spans += [tuple(sorted(rng.integers(0, n, 2))) for _ in range(6)]
    boxes = [(a, b, c) for a in spans for b in spans[:4] for c in spans[-4:]]
    blo = np.array([[axes[k][s[0]] for k, s in enumerate(box)] for box in boxes])
    bhi = np.array([[axes[k][s[1]] for k, s in enumerate(box)] for box in boxes])
    program = compile_tree(tree, dict(params))
    flo, fhi, finite = grid_point_bounds(axes)(program, blo, bhi)
    for k, box in enumerate(boxes):
        part = values[tuple(slice(s[0], s[1] + 1) for s in box)]
        real = part[~np.isnan(part)]
        assert np.all(real >= flo[k]) and np.all(real <= fhi[k]), f"box {k} {box}"
        if finite[k]:
            assert np.isfinite(part).all(), f"box {k} {box}"


def test_the_axis_points_are_made_once_for_the_same_axes(monkeypatch) -> None:
    """Bounding several sets of boxes on one grid (a classification's levels) makes the axes'
    one-axis bounds once per program; the bounds keep their own copy of the axes (changing
    the caller's arrays changes nothing), and bounds made on other axes make them again."""
    from surfgen.generator.eval import intervals

    made = []
    real = intervals._axis_points
    monkeypatch.setattr(intervals, "_axis_points", lambda *a: made.append(1) or real(*a))
    grid = Grid(Box.cube(2.0), (9,) * 3)
    axes = tuple(np.array(a, dtype=np.float64) for a in grid.axes())
    program = compile_tree(parse("abs(tan(0.9*x)) + y^2 + z - 1"), {})
    blo, bhi = np.array([[-2.0, -2.0, -2.0]]), np.array([[2.0, 2.0, 2.0]])
    bounds = grid_point_bounds(axes)
    first = bounds(program, blo, bhi)
    assert bounds(program, blo * 0.5, bhi * 0.5) and len(made) == 1
    axes[0][:] *= 0.5  # the caller's arrays, other coordinates
    again = bounds(program, blo, bhi)
    assert len(made) == 1 and all(np.array_equal(a, b) for a, b in zip(again, first, strict=True))
    changed = grid_point_bounds(axes)(program, blo, bhi)
    assert len(made) == 2 and changed[1][0] < first[1][0]  # tan at 1 is below tan at 2
    bounds(compile_tree(parse("x + y + z"), {}), blo, bhi)
    assert len(made) == 3


def test_a_pole_between_samples_leaves_grid_point_bounds_finite() -> None:
    """tan(m x) has poles on planes x = const: over a block's box its bounds are infinite,
    over the block's grid points they are the values there (and hold them all)."""
    tree = parse("abs(tan(0.861*x))^0.9 + y^2 + z^2 - 30")
    grid = Grid(Box.cube(20.0), (64,) * 3)
    axes = grid.axes()
    program = compile_tree(tree)
    blo, bhi = grid_boxes([-20.0] * 3, [20.0] * 3, 1)  # the whole box, then blocks of 9 cells
    for lo, hi in (
        (blo, bhi),
        *[
            (
                np.array([[axes[0][i], axes[1][0], axes[2][0]]]),
                np.array([[axes[0][i + 9], axes[1][9], axes[2][9]]]),
            )
            for i in range(0, 54, 9)
        ],
    ):
        whole = program_bounds(program, lo, hi)
        points = grid_point_bounds(axes)(program, lo, hi)
        assert not whole[2][0] and whole[1][0] == np.inf  # a pole in every such block
        assert points[2][0] and points[1][0] < 1e6
    assert_grid_points_bounded(tree, {}, grid, 7, np.random.default_rng(0))


@PROPERTY
@given(formulas(), st.integers(0, 2**32 - 1), st.sampled_from([0.2, 2.0, 20.0]))
def test_random_formulas_are_bounded_at_grid_points(text: str, seed: int, half: float) -> None:
    """Property: every grid point's value lies in its box's grid-point bounds."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(5, 19))
    lo = -half * rng.uniform(0.2, 1.0, 3)
    grid = Grid(Box(tuple(lo), tuple(lo + 2 * half * rng.uniform(0.3, 1.0, 3))), (n,) * 3)
    assert_grid_points_bounded(parse(text), {}, grid, 3, rng)


@pytest.mark.parametrize("name", ["eqA", "eqB", "eqC"])
def test_the_paper_s_equations_are_bounded_at_grid_points(name: str) -> None:
    spec = PRESETS[name].spec()
    grid = Grid(Box.from_bounds(spec.box), (33,) * 3)
    assert_grid_points_bounded(spec.tree(), spec.params, grid, 4, np.random.default_rng(1))


def test_grid_point_bounds_fail_when_a_sample_is_left_out(monkeypatch) -> None:
    """The check above can fail: ranges that drop their last coordinate miss samples."""
    searchsorted = np.searchsorted

    def short(a, v, side="left"):
        out = searchsorted(a, v, side=side)
        return out - 1 if side == "right" else out

    monkeypatch.setattr(intervals.np, "searchsorted", short)
    with pytest.raises(AssertionError, match="box"):
        assert_grid_points_bounded(
            parse("x + 2*y^3 + sin(3*z)"),
            {},
            Grid(Box.cube(2.0), (17,) * 3),
            4,
            np.random.default_rng(3),
        )


def _plan_reference(blo, bhi, share):
    """The levels' items as the planning's docstring describes them (ranges told apart by their
    bits), with Python dicts."""
    K = len(blo)
    inverse, firsts = {0: list(range(K)), 7: list(range(K))}, {0: list(range(K)), 7: list(range(K))}
    for lv in range(1, 7):
        seen: dict = {}
        inv = []
        for k in range(K):
            key = [(blo[k, a].tobytes(), bhi[k, a].tobytes()) for a in range(3) if lv >> a & 1]
            key = tuple(key) if share else k
            inv.append(seen.setdefault(key, len(seen)))
        inverse[lv] = inv
        firsts[lv] = [inv.index(i) for i in range(len(seen))]
    counts = [0] + [len(firsts[lv]) for lv in range(1, 8)]
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
    item_map = np.zeros((8, sum(counts)), dtype=np.int64)
    for lv in range(1, 8):
        for i, box in enumerate(firsts[lv]):
            for sub in range(1, 8):
                if sub & ~lv == 0:
                    item_map[sub, offsets[lv] + i] = offsets[sub] + inverse[sub][box]
    return counts, offsets, item_map, firsts


@pytest.mark.parametrize("share", [True, False])
def test_the_levels_items_are_the_distinct_ranges_in_order_of_first_appearance(share) -> None:
    rng = np.random.default_rng(8)
    for size in (1, 2, 50, 400):
        values = rng.normal(size=5)
        blo = rng.choice(values, size=(size, 3))
        bhi = blo + rng.choice([0.0, 0.25, 1.0], size=(size, 3))
        if size > 1:  # -0 told apart from +0 by its bits: another item, never a wrong one
            blo[:2, 1], bhi[:2, 1] = (-0.0, 0.0), 1.0
        counts, offsets, item_map, firsts = intervals.plan_levels(blo, bhi, share)
        want = _plan_reference(blo, bhi, share)
        assert counts.tolist() == list(want[0]) and offsets.tolist() == want[1].tolist()
        assert np.array_equal(item_map, want[2])
        for lv in range(1, 8):
            assert firsts[lv].tolist() == want[3][lv]
