"""Benchmark: what classifying walls adds to the mesh stage (issue 11), on sampled shapes.

For the first ``--n`` draws of ``--seed`` whose coarse field passes the sampler's screen, the
field is evaluated once on ``--grid``³ (64 by default, as in the sampler) and three things are
timed on it, in the same run, best of ``--repeat``:

- ``placement``: ``extract_mesh`` with the merge-robust vertex placement switched off (the mesh
  stage as it was);
- ``mesh``: ``extract_mesh`` (robust placement: the mesh stage now);
- ``walls``: ``extract_labelled(..., walls="mark")``: the mesh plus the root/pole/jump
  classification of every crossing.

Prints per shape the ratios mesh/placement and walls/mesh, then their median, 90th percentile
and maximum, and how many shapes stay within +20 %.  Shared machines are noisy: ratios measured
in one run are what to quote.

    python benchmarks/bench_walls.py [--n 40] [--seed 7] [--grid 64] [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np

import surfgen.generator.mesh as mesh_module
from surfgen.filters.verdict import screen_field
from surfgen.generator.errors import EmptySurface
from surfgen.generator.evaluate import evaluate
from surfgen.generator.grid import Grid
from surfgen.generator.sampler import choose_d, draw_equation
from surfgen.generator.walls import extract_labelled
from surfgen.pipelines.config import load_config


def best(fn: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def old_placement(field, level):
    keep = mesh_module._separate
    mesh_module._separate = lambda offset: offset  # the crossings where marching cubes put them
    try:
        return mesh_module.extract_mesh(field, level, cap=True)
    finally:
        mesh_module._separate = keep


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=40)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--grid", type=int, default=64)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    config = load_config()
    rows = []
    index = 0
    print(f"{'index':>5} {'faces':>7} {'walls%':>6} {'refined':>8} "
          f"{'placement':>9} {'mesh':>7} {'walls':>7} {'mesh/old':>8} {'+walls':>7}")  # fmt: skip
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
            mesh, report = extract_labelled(field, tree, {}, 0.0, cap=True, walls="mark")
        except EmptySurface:
            continue
        t_old = best(lambda: old_placement(field, 0.0), args.repeat)  # noqa: B023
        t_mesh = best(lambda: mesh_module.extract_mesh(field, 0.0, cap=True), args.repeat)  # noqa: B023
        t_walls = best(
            lambda: extract_labelled(field, tree, {}, 0.0, cap=True, walls="mark"),  # noqa: B023
            args.repeat,
        )
        rows.append((t_mesh / t_old, t_walls / t_mesh, report.wall_fraction))
        print(
            f"{index - 1:>5} {mesh.n_faces:>7} {100 * report.wall_fraction:>6.1f} "
            f"{report.refined:>8} {1000 * t_old:>7.1f}ms {1000 * t_mesh:>5.1f}ms "
            f"{1000 * t_walls:>5.1f}ms {t_mesh / t_old:>8.2f} {t_walls / t_mesh - 1:>+7.0%}",
            flush=True,
        )
    placement = np.array([r[0] for r in rows])
    walls = np.array([r[1] for r in rows]) - 1.0
    no_walls = np.array([r[2] == 0.0 for r in rows])
    print(f"\n{len(rows)} shapes of seed {args.seed} at {args.grid}^3 (best of {args.repeat})")
    for name, values in (("robust placement / old", placement), ("walls: extra", walls)):
        print(
            f"{name:>24}: median {statistics.median(values):.2f}, "
            f"p90 {np.percentile(values, 90):.2f}, max {values.max():.2f}"
        )
    print(
        f"within +20 %: {np.count_nonzero(walls <= 0.2)} of {len(rows)} shapes "
        f"({np.count_nonzero(walls[no_walls] <= 0.2)} of {np.count_nonzero(no_walls)} without "
        f"walls, {np.count_nonzero(walls[~no_walls] <= 0.2)} of {np.count_nonzero(~no_walls)} "
        "with walls)"
    )


if __name__ == "__main__":
    main()
