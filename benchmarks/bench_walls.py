"""Benchmark: what classifying walls adds to the mesh stage (issue 11), at 64³.

Two sets of shapes, each field evaluated once on ``--grid``³ (64 by default, as in the sampler):

- *named*: analytic shapes with walls (poles of tan and 1/u, the resets of ``atan(tan u)``,
  ``stair1``, ``stair2``, ``saw1``) and without (sphere, torus, gyroid);
- *sampled*: the first ``--n`` draws of ``--seed`` whose coarse field passes the sampler's screen.

On each, in the same run, best of ``--repeat``:

- ``placement``: ``extract_mesh`` with the merge-robust vertex placement switched off (the mesh
  stage as it was before issue 11);
- ``old mesh``: the numpy mesh stage before issue 13 (``tests/generator/mesh_reference.py``);
- ``mesh``: ``extract_mesh`` (robust placement, numba around marching cubes: the mesh stage
  now; capped, as the sampler);
- ``walls``: ``extract_labelled(..., walls="mark")``: the mesh plus the root/pole/jump
  classification of every crossing, in one numba call (secant, rounds and the formula);
- ``stepwise``: the same with the classification as it was before issue 13 (:class:`Stepwise`:
  each step called from Python, the formula through ``PointsEvaluator.__call__``), which also
  counts the points evaluated;
- ``numpy`` (with ``--numpy``): the stepwise classification with the points evaluated by the
  reference's numpy functions node by node (the evaluator before the points kernel).

Prints per shape the extra time of the classification over the mesh stage now (the target: at
most +20 %) and over the old mesh stage, the stepwise one's, the points evaluated, then the
median, 90th percentile and maximum per set, and how many shapes stay within +20 %.  Shared
machines are noisy: ratios measured in one run are what to quote.

    python benchmarks/bench_walls.py [--n 24] [--seed 7] [--grid 64] [--repeat 3] [--numpy]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import surfgen.generator.mesh as mesh_module
import surfgen.generator.walls as walls_module
from surfgen.filters.verdict import screen_field
from surfgen.generator.errors import EmptySurface
from surfgen.generator.evaluate import evaluate
from surfgen.generator.expr import postorder
from surfgen.generator.grid import Box, Grid
from surfgen.generator.parser import parse
from surfgen.generator.reference import apply_node
from surfgen.generator.sampler import choose_d, draw_equation
from surfgen.generator.walls import ROOT, extract_labelled
from surfgen.pipelines.config import load_config

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "generator"))
from mesh_reference import reference_extract_with_edges  # noqa: E402

NAMED = [
    # (name, formula, half side of the box); walls first
    ("tan", "tan(x)+0.3*y", 3.0),
    ("tan*tan", "tan(x)*tan(y)-z", 3.0),
    ("1/x", "1/x+y+z", 2.0),
    ("atan(tan)", "atan(tan(2*x))+0.5-0.3*y*z", 3.0),
    ("stair1", "stair1(x,0.5,1,4)+stair1(y,0.5,1,4)-z", 2.0),
    ("stair2", "stair2(x*y,0.7,1)-z", 2.0),
    ("saw1", "saw1(x+y,0.6,4)-0.3*z^2", 2.0),
    ("sphere", "x^2+y^2+z^2-1", 1.3),
    ("torus", "(sqrt(x^2+y^2)-1)^2+z^2-0.16", 1.5),
    ("gyroid", "sin(3*x)*cos(3*y)+sin(3*y)*cos(3*z)+sin(3*z)*cos(3*x)", 2.0),
]


class NumpyPoints:
    """The formula at points with the reference's numpy functions, node by node (the walls'
    points evaluator before the numba kernel)."""

    def __init__(self, tree, params):
        self.order = postorder(tree)
        self.slot = {id(node): i for i, node in enumerate(self.order)}
        self.params = dict(params or {})

    def __call__(self, x, y, z):
        env = {"x": np.asarray(x, np.float64), "y": np.asarray(y, np.float64)}
        env["z"] = np.asarray(z, np.float64)
        values = []
        with np.errstate(all="ignore"):
            for node in self.order:
                values.append(
                    apply_node(node, lambda n: values[self.slot[id(n)]], env, self.params)
                )
        return np.array(np.broadcast_to(values[-1], env["x"].shape), dtype=np.float64)


class Stepwise:
    """``walls._classify_suspects`` as it was before issue 13: the per-edge steps are numba
    kernels, but each is called from Python, and the formula through ``points(x, y, z)``
    (:meth:`PointsEvaluator.__call__`) three times; counts the points it evaluates."""

    def __init__(self, make_points=None):
        self.make_points = make_points
        self.points = 0

    def __call__(self, points, level, field, ijk, axis, a_inside, fa, fb):
        w = walls_module
        if self.make_points is not None:
            points = self.make_points(points.program)

        def run(x, y, z):
            self.points += np.size(x)
            return points(x, y, z)

        axes = field.grid.axes()
        spacing = np.asarray(field.grid.spacing, dtype=np.float64)
        origin = np.ascontiguousarray(np.stack([axes[k][ijk[:, k]] for k in range(3)], axis=1))
        step = np.ascontiguousarray(np.eye(3)[axis] * spacing[axis][:, None])
        fa = np.ascontiguousarray(fa, dtype=np.float64)
        fb = np.ascontiguousarray(fb, dtype=np.float64)
        xyz, finite = w._secant_points(origin, step, fa, fb, w.SEPARATION_T)
        f = run(xyz[:, 0], xyz[:, 1], xyz[:, 2]) - level
        rest = np.flatnonzero(~w._secant_roots(f, finite, fa, fb, w.SECANT_ROOT))
        out = np.full(len(fa), ROOT, dtype=np.uint8)
        if rest.size == 0:
            return out
        origin, step, fa, fb = origin[rest], step[rest], fa[rest], fb[rest]
        n = rest.size
        now = np.empty((n, 5))
        now[:, 0], now[:, 1], now[:, 2], now[:, 3] = 0.0, 1.0, fa, fb
        now[:, 4] = a_inside[rest]
        mid = now
        frac = np.arange(1, w.POINTS + 1) / (w.POINTS + 1)
        for rnd in range(w.ROUNDS):
            xyz, s = w._round_points(origin, step, now, frac)
            flat = xyz.reshape(-1, 3)
            vals = run(flat[:, 0], flat[:, 1], flat[:, 2]).reshape(n, w.POINTS) - level
            now = w._round_update(now, s, vals)
            if rnd == 0:
                mid = now
        out[rest] = w._decide(mid, now, fa, fb)
        return out


def best(fn: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def old_placement(field, level):
    keep = mesh_module._separate
    mesh_module._separate = lambda offset, inside: None  # crossings where marching cubes puts them
    try:
        return mesh_module.extract_mesh(field, level, cap=True)
    finally:
        mesh_module._separate = keep


def labelled_with(classify, field, tree):
    """``extract_labelled`` (mark, capped) with ``classify`` as ``walls._classify_suspects``."""
    keep = walls_module._classify_suspects
    walls_module._classify_suspects = classify
    try:
        return extract_labelled(field, tree, {}, 0.0, cap=True, walls="mark")
    finally:
        walls_module._classify_suspects = keep


def measure(name, tree, field, repeat, numpy_too):
    """One row: times, ratios, and the classification's point count."""
    mesh, report = extract_labelled(field, tree, {}, 0.0, cap=True, walls="mark")
    stepwise = Stepwise()
    stepped, _ = labelled_with(stepwise, field, tree)
    if not np.array_equal(stepped.face_kinds, mesh.face_kinds):
        raise AssertionError(f"{name}: the classification differs from the stepwise one")
    n_points = stepwise.points
    t_old = best(lambda: old_placement(field, 0.0), repeat)
    t_old_mesh = best(lambda: reference_extract_with_edges(field, 0.0, True), repeat)
    t_mesh = best(lambda: mesh_module.extract_mesh(field, 0.0, cap=True), repeat)
    t_walls = best(lambda: extract_labelled(field, tree, {}, 0.0, cap=True, walls="mark"), repeat)
    t_step = best(lambda: labelled_with(Stepwise(), field, tree), repeat)
    t_numpy = float("nan")
    if numpy_too:
        numpy_points = Stepwise(lambda _program: NumpyPoints(tree, {}))
        t_numpy = best(lambda: labelled_with(numpy_points, field, tree), repeat)
    extra = t_walls - t_mesh
    print(
        f"{name:>10} {mesh.n_faces:>7} {100 * report.wall_fraction:>6.1f} {report.refined:>7} "
        f"{n_points:>7} {1000 * t_old_mesh:>7.1f} {1000 * t_mesh:>7.1f} {1000 * extra:>7.1f} "
        f"{1000 * (t_step - t_mesh):>7.1f} {1000 * (t_numpy - t_mesh):>7.1f} "
        f"{extra / t_mesh:>+7.0%} {extra / t_old_mesh:>+7.0%} {(t_step - t_mesh) / t_mesh:>+7.0%}",
        flush=True,
    )
    return (
        t_mesh / t_old,
        extra / t_mesh,
        report.wall_fraction,
        extra / t_old_mesh,
        (t_step - t_mesh) / t_mesh,
        t_old_mesh / t_mesh,
    )


def summary(title, rows):
    if not rows:
        return
    extra = np.array([r[1] for r in rows])
    walls = np.array([r[2] > 0.0 for r in rows])
    print(
        f"{title}: {len(rows)} shapes; walls extra over the mesh stage: median "
        f"{statistics.median(extra):+.0%}, p90 {np.percentile(extra, 90):+.0%}, max "
        f"{extra.max():+.0%}; within +20 %: {np.count_nonzero(extra <= 0.2)} of {len(rows)} "
        f"({np.count_nonzero(extra[~walls] <= 0.2)} of {np.count_nonzero(~walls)} without walls, "
        f"{np.count_nonzero(extra[walls] <= 0.2)} of {np.count_nonzero(walls)} with walls)"
    )
    if walls.any():
        print(f"{'':>{len(title)}}  with walls: median {statistics.median(extra[walls]):+.0%}")
    over_old = np.array([r[3] for r in rows])
    stepped = np.array([r[4] for r in rows])
    speed = np.array([r[5] for r in rows])
    print(
        f"{'':>{len(title)}}  over the old mesh stage: median {statistics.median(over_old):+.0%}"
        f", max {over_old.max():+.0%}, within +20 %: {np.count_nonzero(over_old <= 0.2)}; "
        f"stepwise classification over the mesh now: median {statistics.median(stepped):+.0%}, "
        f"max {stepped.max():+.0%}; old mesh / mesh now: median {statistics.median(speed):.2f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=24)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--grid", type=int, default=64)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--numpy", action="store_true", help="also time the numpy points path")
    parser.add_argument("--no-named", action="store_true")
    args = parser.parse_args()
    print(f"{'shape':>10} {'faces':>7} {'walls%':>6} {'refined':>7} {'points':>7} "
          f"{'oldmesh':>7} {'mesh ms':>7} {'walls':>7} {'stepw.':>7} {'numpy':>7} "
          f"{'+walls':>7} {'/oldm':>7} {'+stepw':>7}")  # fmt: skip
    named = []
    if not args.no_named:
        for name, formula, half in NAMED:
            tree = parse(formula)
            field = evaluate(tree, Grid(Box.cube(half), (args.grid,) * 3), threads=1)
            named.append(measure(name, tree, field, args.repeat, args.numpy))
    config = load_config()
    rows = []
    index = 0
    while len(rows) < args.n and index < 50 * args.n:
        draw = draw_equation(args.seed, index, config.sampler)
        index += 1
        d = choose_d(draw, config.sampler, threads=1)
        if d is None:
            continue
        tree = draw.equation.with_d(d).to_tree()
        coarse = evaluate(tree, Grid(draw.box, (config.filters.coarse_grid,) * 3), threads=1)
        if not screen_field(coarse.values, 0.0, config.filters, coarse=True).accepted:
            continue
        field = evaluate(tree, Grid(draw.box, (args.grid,) * 3), threads=1)
        try:
            mesh_module.extract_mesh(field, 0.0, cap=True)
        except EmptySurface:
            continue
        rows.append(measure(f"#{index - 1}", tree, field, args.repeat, args.numpy))
    print(f"\nat {args.grid}^3, best of {args.repeat}")
    summary("named", named)
    summary(f"sampled (seed {args.seed})", rows)
    placement = np.array([r[0] for r in named + rows])
    print(
        f"robust placement / the same without separation: median {statistics.median(placement):.2f}, "
        f"p90 {np.percentile(placement, 90):.2f}, max {placement.max():.2f}"
    )


if __name__ == "__main__":
    main()
