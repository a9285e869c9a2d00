"""Checks of interval bounds shared by the tests of :mod:`surfgen.generator.eval.intervals`,
:mod:`~surfgen.generator.eval.interval_regroup`, :mod:`~surfgen.generator.eval.interval_extrema`
and :mod:`~surfgen.generator.eval.interval_poly`: random boxes, points in them, and the
soundness of bounds against the fast evaluator at those points, a formula's regrouped or
structured bounds and spread, and the sparse path's leaves and mesh with tightened bounds."""

from __future__ import annotations

import numpy as np

from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.interval_poly import polynomial_bounds, polynomial_structure
from surfgen.generator.eval.interval_regroup import Regrouped, regroup, regrouped_bounds
from surfgen.generator.eval.intervals import grid_point_bounds, program_bounds, tree_bounds
from surfgen.generator.eval.sparse import SparseField, evaluate_sparse
from surfgen.generator.eval.tape import points_evaluator
from surfgen.generator.formula.expr import Expr
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.realise import realise
from surfgen.generator.model.sampler import SamplerConfig, choose_d, draw_equation
from surfgen.generator.model.spec import SurfaceSpec


def random_boxes(rng: np.random.Generator, lo, hi, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Boxes of every size inside ``[lo, hi]`` (some flat, some a point, some from 0)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c = rng.uniform(lo, hi, (k, 3))
    w = (hi - lo) * rng.uniform(0, 1, (k, 3)) ** 3 * 0.4
    w[rng.random((k, 3)) < 0.08] = 0.0
    blo, bhi = c - w, c + w
    zero = rng.random((k, 3)) < 0.05
    blo[zero] = np.minimum(blo[zero], 0.0)
    bhi[zero] = np.maximum(bhi[zero], 0.0)
    return blo, bhi


def box_points(rng: np.random.Generator, blo, bhi, m: int = 12) -> np.ndarray:
    """The 8 corners, the centre and ``m`` random points of each box: ``(K, 9 + m, 3)``."""
    corners = np.array([[(i >> a) & 1 for a in range(3)] for i in range(8)], float)
    u = np.concatenate([corners, np.full((1, 3), 0.5)])[None].repeat(len(blo), 0)
    u = np.concatenate([u, rng.uniform(0, 1, (len(blo), m, 3))], axis=1)
    pts = blo[:, None] + u * (bhi - blo)[:, None]
    return np.clip(pts, blo[:, None], bhi[:, None])  # blo + (bhi - blo) may round past bhi


def assert_sound(tree, params, blo, bhi, rng, bounds=None) -> np.ndarray:
    """Every value of the fast evaluator at the boxes' points is NaN or inside the bounds, and
    finite where the bounds say so; returns the values."""
    flo, fhi, finite = bounds if bounds is not None else tree_bounds(tree, params, blo, bhi)
    pts = box_points(rng, blo, bhi)
    v = points_evaluator(tree, params)(*(pts[..., a].ravel() for a in range(3)))
    v = v.reshape(pts.shape[:2])
    out = ~np.isnan(v) & ((v < flo[:, None]) | (v > fhi[:, None]))
    nonfinite = finite[:, None] & ~np.isfinite(v)
    for bad, what in ((out, "outside its bounds"), (nonfinite, "not finite in a finite box")):
        if bad.any():
            k, j = np.argwhere(bad)[0]
            raise AssertionError(
                f"F{tuple(pts[k, j])} = {v[k, j]!r} {what}: box {blo[k].tolist()}.."
                f"{bhi[k].tolist()}, bounds [{flo[k]!r}, {fhi[k]!r}], finite {finite[k]}"
            )
    return v


def regrouped(text: str):
    """``text``'s tree, program and bounds: the regrouped ones where :func:`regroup` finds
    something, else the program's own (:func:`program_bounds` over whole boxes)."""
    tree = parse(text)
    program = compile_tree(tree)

    def base(prog, lo, hi):
        return program_bounds(prog, lo, hi)

    found = regroup(tree)
    return tree, program, base if found is None else regrouped_bounds(base, program, found)


def assert_margin_needed(text: str, module, monkeypatch, seed: int = 3) -> None:
    """``text``'s regrouped bounds hold at 200 random boxes' points, and no longer once
    ``module``'s unit roundoff (its ``_UNIT``: the rounding margins) is zeroed."""
    rng = np.random.default_rng(seed)
    blo, bhi = random_boxes(rng, [-2.0] * 3, [2.0] * 3, 200)
    tree, program, bounds = regrouped(text)
    assert_sound(tree, {}, blo, bhi, rng, bounds(program, blo, bhi))
    monkeypatch.setattr(module, "_UNIT", 0.0)
    tree, program, bounds = regrouped(text)
    try:
        assert_sound(tree, {}, blo, bhi, rng, bounds(program, blo, bhi))
    except AssertionError as e:
        assert "outside its bounds" in str(e)
    else:
        raise AssertionError(f"{text}: sound without {module.__name__}'s margins")


def assert_within_spread(text: str, found: Regrouped, rng: np.random.Generator) -> None:
    """At random points of ``[-1.5, 1.5]^3``, ``|F - compact| <= spread`` wherever both are
    finite (at least half of them)."""
    pts = rng.uniform(-1.5, 1.5, (4000, 3))
    f, g, s = (points_evaluator(t, {})(*pts.T) for t in (parse(text), found.compact, found.spread))
    ok = np.isfinite(g) & np.isfinite(s)
    assert ok.mean() > 0.5
    assert np.all(np.abs(f[ok] - g[ok]) <= s[ok]), text


def structure_bounds(text: str, level: float | None = None):
    """``text``'s tree, program and bounds: through its polynomial structure where it has one
    (:func:`polynomial_bounds`), else the program's own (:func:`program_bounds`)."""
    tree = parse(text)
    program = compile_tree(tree)

    def base(prog, lo, hi):
        return program_bounds(prog, lo, hi)

    found = polynomial_structure(tree)
    if found is None:
        return tree, program, base
    return tree, program, polynomial_bounds(base, program, found, level)


def twist_case() -> tuple[Expr, Box, tuple[int, int, int]]:
    """The first twist draw of seed 5 (its lobes ``P/D cos + P/D sin``, D a polynomial), its
    box shifted and stretched, and an odd grid."""
    cfg = SamplerConfig(family="twist")
    draw = draw_equation(5, 0, cfg)
    tree = draw.equation.with_d(choose_d(draw, cfg, threads=1)).to_tree()
    lo, hi = np.array(draw.box.lo), np.array(draw.box.hi)
    return tree, Box(tuple(lo * 1.03 + 0.02), tuple(hi * 0.98 + 0.02)), (121, 113, 127)


def assert_fewer_leaves_than_without(tree: Expr, box: Box, shape, monkeypatch, module, name,
                                     off) -> None:  # fmt: skip
    """Fewer leaves of ``tree`` sampled on this grid than with ``module.name`` replaced by
    ``off`` (a bounding step switched off) and than with the plain grid-point bounds, the
    same kept, and the capped mesh the dense path's, bit for bit."""
    grid = Grid(box, shape)
    polynomial_structure.cache_clear()
    with monkeypatch.context() as m:
        m.setattr(module, name, off)
        loose = evaluate_sparse(tree, grid, faces=True)
    polynomial_structure.cache_clear()
    tight = _fewer_leaves_than_plain(tree, grid)
    assert tight.stats["sampled_leaves"] < loose.stats["sampled_leaves"]
    assert tight.n_bricks == loose.n_bricks
    assert_same_mesh(tree, box, shape)


def assert_fewer_leaves_same_mesh(tree: Expr, box: Box, shape: tuple[int, int, int]) -> None:
    """The sparse path's default bounds sample fewer leaves of ``tree`` on this grid than the
    plain grid-point bounds, keep the same, and the capped mesh is the dense path's, bit for
    bit."""
    _fewer_leaves_than_plain(tree, Grid(box, shape))
    assert_same_mesh(tree, box, shape)


def _fewer_leaves_than_plain(tree: Expr, grid: Grid) -> SparseField:
    """The default bounds sample fewer leaves than the plain grid-point bounds and keep the
    same; returns their field."""
    plain = evaluate_sparse(tree, grid, bounds=grid_point_bounds(grid.axes(), 1), faces=True)
    tight = evaluate_sparse(tree, grid, faces=True)
    assert tight.stats["sampled_leaves"] < plain.stats["sampled_leaves"]
    assert tight.n_bricks == plain.n_bricks
    return tight


def assert_same_mesh(tree: Expr, box: Box, shape: tuple[int, int, int]) -> None:
    """The capped sparse mesh of ``tree`` is the dense path's, bit for bit (and not small)."""
    bounds = (box.lo[0], box.hi[0], box.lo[1], box.hi[1], box.lo[2], box.hi[2])
    spec = SurfaceSpec.from_tree(tree, bounds, shape)
    meshes = [realise(spec, evaluator=e, cap=True).mesh for e in ("fast", "sparse")]
    assert meshes[0].faces.shape[0] > 1000
    for a in ("vertices", "faces"):
        assert np.array_equal(getattr(meshes[0], a), getattr(meshes[1], a))


def grid_blocks(grid: Grid, step: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The grid's blocks of ``step`` cells a side (the last ones cut at the grid's end): their
    first and last grid indices and their boxes, ``(idx, top, lo, hi)``."""
    axes = grid.axes()
    idx = np.stack(np.meshgrid(*[np.arange(0, n - 1, step) for n in grid.shape], indexing="ij"), -1)
    idx = idx.reshape(-1, 3)
    top = np.minimum(idx + step, np.array(grid.shape) - 1)
    lo = np.stack([axes[a][idx[:, a]] for a in range(3)], 1)
    hi = np.stack([axes[a][top[:, a]] for a in range(3)], 1)
    return idx, top, lo, hi


def assert_grid_points_within(tree: Expr, grid: Grid, idx, top, flo, fhi, every: int = 1) -> None:
    """Every grid point of every ``every``-th block (:func:`grid_blocks`) has its value within
    the block's bounds."""
    axes, f = grid.axes(), points_evaluator(tree, {})
    for k in range(0, len(idx), every):
        pts = np.stack(np.meshgrid(*[axes[a][idx[k, a] : top[k, a] + 1] for a in range(3)],
                                   indexing="ij"), -1).reshape(-1, 3)  # fmt: skip
        v = f(*pts.T)
        assert np.all((v >= flo[k]) & (v <= fhi[k])), k
