"""The points kernel (``fast.PointsEvaluator``) equals the reference bit for bit: at the points
of a grid (against the grid interpreter's field, itself tested against the reference) and at
scattered points (against ``reference.evaluate_points``), for every opcode and operand mode,
the constituent functions, the presets and random eq. (13)-shaped formulas."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from test_tape import (
    ARGS,
    BINARY,
    CONSTITUENTS,
    EQ13_GRID,
    GRID,
    NODE_GRID,
    PAIRS,
    UNARY,
    assert_identical,
    eq13_trees,
)

from surfgen.generator.errors import FormulaError
from surfgen.generator.eval.grid import Grid
from surfgen.generator.eval.reference import evaluate_points, evaluate_reference
from surfgen.generator.eval.tape import PointsEvaluator, compile_program, points_evaluator
from surfgen.generator.formula.expr import Expr
from surfgen.generator.formula.parser import parse
from surfgen.generator.model.presets import PRESETS

RNG_POINTS = np.random.default_rng(5).uniform(-3.0, 3.0, size=(3, 700))


def check(tree: Expr, grid: Grid = GRID, params=None) -> None:
    points = points_evaluator(tree, params)
    x, y, z = (a.reshape(-1) for a in np.meshgrid(*grid.axes(), indexing="ij"))
    want = evaluate_reference(tree, grid, params).values.reshape(-1)
    assert_identical(points(x, y, z), want, f"{tree} on the grid")  # shared levels
    assert_identical(points.plain(x, y, z), want, f"{tree} on the grid, unshared")
    x, y, z = RNG_POINTS
    want = evaluate_points(tree, x, y, z, params)
    assert_identical(points(x, y, z), want, f"{tree} scattered")
    assert_identical(points.plain(x, y, z), want, f"{tree} scattered, unshared")


@pytest.mark.parametrize("fn", UNARY)
def test_unary_functions_at_every_level(fn):
    for arg in ARGS:
        check(parse(f"{fn}({arg})*(y+3)"))


@pytest.mark.parametrize("op", BINARY)
def test_binary_operations_in_every_mode(op):
    # On a grid these give vv, vs and sv rows; along points all become vv.
    for a, b in PAIRS:
        check(parse(f"({a}){op}({b})" if op in "+-*/^" else f"{op}({a},{b})"))


def test_constants_broadcasts_and_one_variable():
    for text in ("2*pi-1", "x", "sin(y)", "z^2", "x*y", "cos(y*z)", "exp(x*z)", "y-z"):
        check(parse(text))


@pytest.mark.parametrize("template", CONSTITUENTS)
def test_constituent_functions(template):
    for u in ["x*y+z", "x", "y*z*1.25"]:
        check(parse(template.format(u=u)), NODE_GRID)


def test_presets():
    for name in sorted(PRESETS):
        spec = PRESETS[name].spec()
        grid = Grid(spec.to_grid().box, (9, 8, 7))
        check(spec.tree(), grid, spec.params)


@settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(eq13_trees())
def test_random_eq13_formulas(tree):
    check(tree, EQ13_GRID)


def test_points_on_grid_lines_share_levels_exactly():
    # The walls' refinement: points on edges of a grid, coordinates shared along lines, with
    # -0.0 and +0.0 (told apart: 1/x and atan2 see the sign) and repeated points.
    tree = parse("1/x+atan2(y,z)*cos(x*y)^2.5+abs(z)^0.31*tan(y*z)-sinh(x)*y")
    axis = np.array([-1.0, -0.0, 0.0, 0.5, 1.25])
    x, y, z = (a.reshape(-1) for a in np.meshgrid(axis, axis, axis, indexing="ij"))
    t = np.linspace(0.01, 0.99, x.size)
    x = np.concatenate([x, x + 0.0 * t, x + t * 0.25, x])
    y = np.concatenate([y, y + t * 0.25, y + 0.0 * t, y])
    z = np.concatenate([z, z, z + t * 0.25, z])
    points = points_evaluator(tree)
    want = evaluate_points(tree, x, y, z)
    assert_identical(points(x, y, z), want, "grid lines")
    assert_identical(points.plain(x, y, z), want, "grid lines, unshared")


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_points_on_grid_edges_are_the_reference(axis):
    # points.eval_edges (the walls' refinement): the levels that do not vary along the edges
    # computed once per edge (points.edge_lattice), the others over the points of each call;
    # dyadic fractions repeat coordinates, a grid axis holds -0.0 and +0.0, more points than
    # edges and than a tile.
    from surfgen.generator.eval import point_driver as points

    tree = parse("1/x+atan2(y,z)*cos(x*y)^2.5+abs(z)^0.31*tan(y*z)-sinh(x)*y+x*z^3")
    axes = (
        np.array([-1.0, -0.0, 0.0, 0.5, 1.25, 2.0]),
        np.array([-2.0, -0.5, -0.0, 0.0, 0.75]),
        np.array([-0.0, 0.0, 0.3, 0.9, 1.7, 2.2, 3.0]),
    )
    rng = np.random.default_rng(axis)
    ijk = np.stack([rng.integers(0, a.size - 1, 40) for a in axes], axis=1)
    prog, tile, active, rows = points_evaluator(tree).kernel_args()
    ctx = points.edge_lattice(prog, tile, active, rows, axis, ijk, axes)
    for n in (0, 7, 600):
        sel = rng.integers(0, ijk.shape[0], n)
        t = rng.integers(0, 17, n) / 16
        h = axes[axis][ijk[sel, axis] + 1] - axes[axis][ijk[sel, axis]]
        u = axes[axis][ijk[sel, axis]] + t * h
        got = np.full(n, 7.0)
        points.eval_edges(prog, tile, active, rows, ctx, sel, u, got)
        p = np.stack([axes[k][ijk[sel, k]] for k in range(3)], axis=1)
        p[:, axis] = u
        assert_identical(got, evaluate_points(tree, p[:, 0], p[:, 1], p[:, 2]), f"axis {axis}")


def test_more_points_than_a_tile_and_none():
    tree = parse("atan(tan(2*x))*stair1(y,0.5,1,4)+abs(z)^0.3/sec(x*y)-rect2(z,1,0.4)")
    x, y, z = np.random.default_rng(3).uniform(-3, 3, size=(3, 1000))  # 3 tiles and a bit
    got = points_evaluator(tree)(x, y, z)
    assert_identical(got, evaluate_points(tree, x, y, z), "tiles")
    assert points_evaluator(tree)(x[:0], y[:0], z[:0]).shape == (0,)


def test_bad_input():
    with pytest.raises(ValueError, match="differ in length"):
        points_evaluator(parse("x"))(np.zeros(3), np.zeros(2), np.zeros(3))
    with pytest.raises(TypeError):
        PointsEvaluator("x")  # type: ignore[arg-type]
    with pytest.raises(FormulaError, match="parameter 'm'"):
        points_evaluator(parse("m*x", ["m"]))
    program = compile_program(parse("m*x+y", ["m"]), {"m": 2.0})
    assert PointsEvaluator(program)(np.array([1.0]), np.array([0.5]), np.array([0.0]))[0] == 2.5


def _first_appearance(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """numpy's account of :func:`point_driver.dedupe`: each key's rank among the distinct
    keys in order of first appearance, and where each first appears."""
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[inverse.ravel()], first[order]


@pytest.mark.parametrize(
    "n, distinct",
    [(1, 1), (8, 8), (9, 2), (17, 5), (1000, 3), (16384, 64), (20000, 4000), (5000, 5000)],
)
def test_dedupe_numbers_keys_in_order_of_first_appearance(n, distinct):
    # few distinct keys among many (the boxes' ranges of a level), and as many as keys:
    # the table grows past every power of two on the way, its ids and firsts unchanged
    from surfgen.generator.eval import point_driver as points

    rng = np.random.default_rng(n + distinct)
    pool = rng.integers(-(2**62), 2**62, size=distinct, dtype=np.int64)
    keys = pool[rng.integers(0, distinct, size=n)]
    ids, first = points.dedupe(keys)
    want_ids, want_first = _first_appearance(keys)
    np.testing.assert_array_equal(ids, want_ids)
    np.testing.assert_array_equal(first, want_first)
    assert np.array_equal(keys[first][ids], keys)
    empty_ids, empty_first = points.dedupe(np.empty(0, dtype=np.int64))
    assert empty_ids.size == 0 and empty_first.size == 0
