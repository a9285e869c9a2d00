"""Benchmark: what classifying walls adds to the mesh stage (issue 11), at 64³.

Two sets of shapes, each field evaluated once on ``--grid``³ (64 by default, as in the sampler):

- *named*: analytic shapes with walls (poles of tan and 1/u, the resets of ``atan(tan u)``,
  ``stair1``, ``stair2``, ``saw1``) and without (sphere, torus, gyroid);
- *sampled*: the first ``--n`` draws of ``--seed`` whose coarse field passes the sampler's screen.

On each, in the same run, best of ``--repeats``:

- ``placement``: ``extract_mesh`` with the merge-robust vertex placement switched off (the mesh
  stage as it was before issue 11);
- ``old mesh``: the numpy mesh stage before issue 13 (``tests/support/mesh_reference.py``);
- ``mesh``: ``extract_with_edges`` (robust placement, numba around marching cubes: the mesh
  stage now; capped, as the sampler);
- ``walls``: what ``extract_labelled(..., walls="mark")`` adds to it: ``label_walls`` on the
  mesh and edges (the root/pole/jump classification of every crossing: secant point and
  bisections, one numba call; the faces' kinds and the wall fraction), timed by itself right
  after the mesh stage that made them, as in the pipeline (so with the caches as it leaves
  them), given the faces' areas as the sampler gives them (its filters need them too: it
  computes them once);
- ``main``: the same with main's classification before the second cost work
  (``tests/support/walls_main.py``: the secant point, then bisections over the whole formula
  at every point);
- ``previous``: the same with the classification before any cost work
  (``tests/support/walls_reference.py``: secant point and two rounds of three points over
  the whole edge).

Prints per shape the extra time of each classification over the mesh stage (the target: at
most +20 %), the suspects and points evaluated (now and main's), and where the classification
now differs from main's (share of the area whose kind changed, wall_fraction of both); then the
median, 90th percentile and maximum per set, over the shapes with walls too.
Shared machines are noisy: ratios measured in one run are what to quote.

    python -m benchmarks.walls_cost [--n 24] [--seed 7] [--grid 64] [--repeats 5] [--json PATH]
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import numpy as np

import surfgen.generator.mesh.marching as marching
import surfgen.generator.mesh.mesh as mesh_module
import surfgen.generator.mesh.walls as walls_module
from benchmarks import harness
from benchmarks.workloads import NAMED, sampled_shapes
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.walls import extract_labelled, label_walls
from tests.support.mesh_reference import reference_extract_with_edges
from tests.support.walls_main import main_classify
from tests.support.walls_reference import reference_classify_edges


def best(fn: Callable[[], object], repeat: int) -> float:
    """Least wall time of ``fn()`` over ``repeat`` calls."""
    return harness.best_of(fn, repeat, warmup=0).best


def old_placement(field, level):
    keep = marching._separate
    marching._separate = lambda offset, p=0: None  # crossings where marching cubes puts them
    try:
        return mesh_module.extract_mesh(field, level, cap=True)
    finally:
        marching._separate = keep


def previous(field, tree, params, level, edges):
    """``walls._classify`` with the previous classification (points not counted)."""
    kinds, refined = reference_classify_edges(field, tree, params, level, edges)
    return kinds, refined, 0


def labelled_with(classify, field, tree):
    """``extract_labelled`` (mark, capped) with ``classify`` as ``walls._classify``."""
    keep = walls_module._classify
    walls_module._classify = classify
    try:
        return extract_labelled(field, tree, {}, 0.0, cap=True, walls="mark")
    finally:
        walls_module._classify = keep


def measure(run: harness.Run, name, tree, field, repeat):
    """One row: times, ratios, points, and the change from main's classification."""
    mesh, report = extract_labelled(field, tree, {}, 0.0, cap=True, walls="mark")
    before, before_report = labelled_with(main_classify, field, tree)
    areas = mesh_module.face_areas(mesh)
    changed = float(areas[mesh.face_kinds != before.face_kinds].sum() / areas.sum())
    t_old = best(lambda: old_placement(field, 0.0), repeat)
    t_old_mesh = best(lambda: reference_extract_with_edges(field, 0.0, True), repeat)

    def label(classify=None):
        """Mesh, then classify its crossings (``label_walls``, mark): timed apart, in the
        state the pipeline classifies in, right after its field's mesh stage."""
        start = time.perf_counter()
        capped, edges = mesh_module.extract_with_edges(field, 0.0, True)
        middle = time.perf_counter()
        # the faces' areas: the filters need them too, and the sampler computes them once
        areas = mesh_module.face_areas(capped)
        keep = walls_module._classify
        walls_module._classify = classify or keep
        try:
            begin = time.perf_counter()
            label_walls(capped, edges, field, tree, {}, 0.0, True, "mark", areas)
        finally:
            walls_module._classify = keep
        return middle - start, time.perf_counter() - begin

    # extract_labelled is extract_with_edges then label_walls: time the two parts (a
    # difference of two noisy totals would be noisier), each classification right after a
    # mesh stage of its own (the pipeline's state: the mesh stage's data in the caches, the
    # field's samples mostly out of them), the three in turns, so a busy moment hits all alike
    t_mesh = float("inf")
    times = [float("inf")] * 3
    runs = [label, lambda: label(main_classify), lambda: label(previous)]
    for r in range(repeat):
        for q in range(3):
            k = (q + r) % 3
            mesh_time, label_time = runs[k]()
            t_mesh = min(t_mesh, mesh_time)
            times[k] = min(times[k], label_time)
    t_walls, t_main, t_prev = times
    run.say(
        f"{name:>10} {mesh.n_faces:>7} {100 * report.wall_fraction:>6.1f} "
        f"{100 * before_report.wall_fraction:>6.1f} {100 * changed:>6.2f} {report.refined:>7} "
        f"{report.points:>7} {before_report.points:>7} {1000 * t_mesh:>7.1f} "
        f"{1000 * t_walls:>7.1f} {1000 * t_main:>7.1f} {1000 * t_prev:>7.1f} "
        f"{t_walls / t_mesh:>+7.0%} {t_main / t_mesh:>+7.0%} {t_prev / t_mesh:>+7.0%} "
        f"{t_walls / t_old_mesh:>+7.0%}"
    )
    return {
        "placement": t_mesh / t_old,
        "extra": t_walls / t_mesh,
        "main": t_main / t_mesh,
        "previous": t_prev / t_mesh,
        "speedup": t_main / t_walls,
        "walls": report.wall_fraction > 0.0 or before_report.wall_fraction > 0.0,
        "changed": changed,
        "wf_change": abs(report.wall_fraction - before_report.wall_fraction),
        "over_old": t_walls / t_old_mesh,
    }


def _stats(values: np.ndarray) -> str:
    return (
        f"median {statistics.median(values):+.0%}, p90 {np.percentile(values, 90):+.0%}, "
        f"max {values.max():+.0%}"
    )


def summary(run: harness.Run, title, rows):
    if not rows:
        return
    pad = " " * len(title)
    extra = np.array([r["extra"] for r in rows])
    main_ = np.array([r["main"] for r in rows])
    prev = np.array([r["previous"] for r in rows])
    speedup = np.array([r["speedup"] for r in rows])
    walls = np.array([r["walls"] for r in rows])
    run.say(
        f"{title}: {len(rows)} shapes; classification over the mesh stage: {_stats(extra)}; "
        f"within +20 %: {np.count_nonzero(extra <= 0.2)} of {len(rows)}"
    )
    for label, mask in (("with walls", walls), ("without walls", ~walls)):
        if mask.any():
            run.say(
                f"{pad}  {label} ({np.count_nonzero(mask)}): now {_stats(extra[mask])}, within "
                f"+20 %: {np.count_nonzero(extra[mask] <= 0.2)}; main's: {_stats(main_[mask])}; "
                f"before the cost work: {_stats(prev[mask])}; main's time / now: median "
                f"x{statistics.median(speedup[mask]):.2f}"
            )
    changed = np.array([r["changed"] for r in rows])
    wf = np.array([r["wf_change"] for r in rows])
    over_old = np.array([r["over_old"] for r in rows])
    run.say(
        f"{pad}  area whose kind changed from main's: median {statistics.median(changed):.2%}, "
        f"p90 {np.percentile(changed, 90):.2%}, max {changed.max():.2%}; |wall_fraction "
        f"change| median {statistics.median(wf):.4f}, p90 {np.percentile(wf, 90):.4f}, max "
        f"{wf.max():.4f}; over the numpy mesh stage before issue 13: median "
        f"{statistics.median(over_old):+.0%}"
    )


def main(argv: list[str] | None = None) -> None:
    parser = harness.parser(__doc__, repeats=5)
    parser.add_argument("--n", type=int, default=24)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--grid", type=int, default=64)
    parser.add_argument("--no-named", action="store_true")
    args = parser.parse_args(argv)
    run = harness.Run("walls_cost", args)
    run.say(
        f"{'shape':>10} {'faces':>7} {'walls%':>6} {'main%':>6} {'chg%':>6} {'suspect':>7} "
        f"{'points':>7} {'p.main':>7} {'mesh ms':>7} {'walls':>7} {'main':>7} {'prev.':>7} "
        f"{'+walls':>7} {'+main':>7} {'+prev':>7} {'/oldm':>7}"
    )
    named = []
    if not args.no_named:
        for name, formula, half in NAMED:
            tree = parse(formula)
            field = evaluate(tree, Grid(Box.cube(half), (args.grid,) * 3), threads=1)
            named.append(measure(run, name, tree, field, args.repeats))
    rows = [
        measure(run, name, tree, field, args.repeats)
        for name, tree, field in sampled_shapes(args.n, args.seed, args.grid)
    ]
    run.say(f"\nat {args.grid}^3, best of {args.repeats}")
    summary(run, "named", named)
    summary(run, f"sampled (seed {args.seed})", rows)
    placement = np.array([r["placement"] for r in named + rows])
    run.say(
        f"robust placement / the same without separation: median {statistics.median(placement):.2f}, "
        f"p90 {np.percentile(placement, 90):.2f}, max {placement.max():.2f}"
    )
    run.record(named=named, sampled=rows)
    run.save()


if __name__ == "__main__":
    main()
