"""Throughput of `surfgen sample`: accepted shapes per minute, time by stage, acceptance rate.

    python -m benchmarks.sample_throughput [--n 200] [--seed 7] [--workers 2] [--grid 64]
        [--compare-free] [--json PATH]

With ``--compare-free`` the same job is also run with ``--family free`` (the first sampler's
draws) right after, and the wall times are printed as a ratio: the default mix of families
against the free draw, measured in one run.

The machine is shared and noisy, so the figure is also printed as a ratio against a baseline
measured in the same run: the time to evaluate, mesh and measure the `gyroid` preset at the
same grid (one shape's full path through a known formula), in shapes per minute.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import harness
from surfgen.filters.metrics import measure_mesh
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Grid
from surfgen.generator.mesh.mesh import extract_mesh
from surfgen.generator.model.presets import get_preset
from surfgen.generator.model.sampler import choose_d, draw_equation
from surfgen.pipelines.run.config import load_config
from surfgen.pipelines.run.sampling import run_sample


def baseline_per_minute(grid: int, repeats: int = 5) -> float:
    """Shapes per minute of the gyroid preset's evaluate + mesh + measure (best of ``repeats``)."""
    spec = get_preset("gyroid").spec().replace(grid=(grid,) * 3)
    tree = spec.tree()

    def one_shape() -> None:
        measure_mesh(extract_mesh(evaluate(tree, spec.to_grid()), cap=True))

    return 60.0 / harness.best_of(one_shape, repeats, warmup=0).best


def crossing_rates(seed: int, draws: int, config) -> dict[str, float]:
    """How often the surface F = 0 crosses the box (coarse grid), for three ways to pick d."""
    cfg = config.sampler
    rng = np.random.default_rng(seed)
    hits = {"d = 0": 0, "d uniform in [-10, 10]": 0, "d at a quantile (surfgen)": 0}
    for i in range(draws):
        draw = draw_equation(seed, i, cfg)
        body = evaluate(draw.equation.body(), Grid(draw.box, (cfg.d_grid,) * 3), threads=1).values
        q = choose_d(draw, cfg, threads=1)
        for name, d in (
            ("d = 0", 0.0),
            ("d uniform in [-10, 10]", rng.uniform(-10, 10)),
            ("d at a quantile (surfgen)", q),
        ):
            if d is None:
                continue
            v = body - d
            fin = np.isfinite(v)
            hits[name] += bool((v[fin] < 0).any() and (v[fin] >= 0).any())
    return {k: v / draws for k, v in hits.items()}


def timed_run(args, config):
    """One sampling job in a fresh catalogue: its summary and wall time in seconds."""
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        s = run_sample(
            n=args.n,
            seed=args.seed,
            config=config,
            catalogue=Path(tmp) / "cat",
            workers=args.workers,
        )
        return s, time.perf_counter() - t


def main(argv: list[str] | None = None) -> None:
    ap = harness.parser(__doc__)
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--grid", type=int, default=None)
    ap.add_argument(
        "--compare-free",
        action="store_true",
        help="also time the same job with --family free and print the ratio of wall times",
    )
    args = ap.parse_args(argv)
    run = harness.Run("sample_throughput", args)
    config = load_config().with_grid(args.grid)
    grid = config.run.grid
    base = baseline_per_minute(grid)
    s, wall = timed_run(args, config)
    if args.compare_free:
        free, free_wall = timed_run(args, config.with_family("free"))
        run.say(
            f"family {config.sampler.family}: {wall:.1f} s, {s.accepted} of {s.drawn} drawn; "
            f"family free: {free_wall:.1f} s, {free.accepted} of {free.drawn} drawn"
        )
        run.say(f"  ratio of wall times {config.sampler.family} / free: {wall / free_wall:.3f}")
    rate = 60.0 * s.accepted / wall
    total_stage = sum(s.stage_seconds.values()) or 1.0
    run.say(f"sample --n {args.n} --seed {args.seed} --grid {grid} --workers {args.workers}")
    run.say(
        f"  accepted {s.accepted} of {s.drawn} drawn: acceptance {100 * s.accepted / s.drawn:.1f}%"
    )
    run.say(f"  wall time {wall:.1f} s: {rate:.1f} accepted shapes/min")
    run.say(f"  baseline (gyroid preset, eval+mesh+measure, 1 process): {base:.0f} shapes/min")
    run.say(f"  ratio accepted-shapes rate / baseline: {rate / base:.3f}")
    run.say(
        "  worker time by stage: "
        + ", ".join(
            f"{k} {v:.1f} s ({100 * v / total_stage:.0f}%)"
            for k, v in sorted(s.stage_seconds.items())
        )
    )
    run.say(
        "  rejections: "
        + ", ".join(f"{k} {v}" for k, v in sorted(s.counts.items(), key=lambda kv: -kv[1]))
    )
    for name, rate_ in crossing_rates(args.seed, 300, config).items():
        run.say(f"  surface crosses the box with {name}: {100 * rate_:.0f}% of 300 draws")
    est = 1000 / rate
    run.say(f"  projected `sample --n 1000 --seed 7`: {est:.1f} min")
    run.record(
        accepted=s.accepted,
        drawn=s.drawn,
        wall_seconds=wall,
        per_minute=rate,
        baseline_per_minute=base,
        stage_seconds=s.stage_seconds,
        rejections=s.counts,
    )
    run.save()


if __name__ == "__main__":
    main()
