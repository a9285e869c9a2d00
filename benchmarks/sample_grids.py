"""Throughput of `surfgen sample` across grids, before and after, in one run.

    python -m benchmarks.sample_grids [--grids 48 64 96 128] [--n 6 6 4 3] [--seed 7]
        [--workers 2] [--baseline REV] [--json PATH]

For every grid it runs ``sample --n N --seed S`` (default config, thumbnails on) with the code
of this checkout and, with ``--baseline REV`` (a git revision, e.g. ``main``), with the code of
that revision exported into a temporary folder; both run as child processes, interleaved grid by
grid so a change in the machine's load hits both alike. It prints accepted shapes per minute,
the acceptance rate, worker seconds per accepted shape by stage, and the ratios baseline / now
(above 1: this checkout is faster).

Each version first samples one shape at a tiny grid so numba's compilation (cached per code
folder) is not timed. The machine this project is developed on is shared: read the ratios,
not the absolute figures. Without ``--baseline`` only this checkout is measured, and
"grid cost" (worker seconds per accepted shape / grid points, relative to the first grid) shows
whether the cost grows linearly with the grid.
"""

from __future__ import annotations

import os

from benchmarks import harness

_CHILD = r"""
import json, sys, tempfile, time
from pathlib import Path
import surfgen.pipelines.run.sampling as sampling
from surfgen.pipelines.run.config import load_config
n, seed, grid, workers = (int(a) for a in sys.argv[1:5])
config = load_config().with_grid(grid).with_run(timeout=3600.0)
with tempfile.TemporaryDirectory() as tmp:
    t = time.perf_counter()
    s = sampling.run_sample(n=n, seed=seed, config=config, catalogue=Path(tmp) / "cat",
                            workers=workers)
    wall = time.perf_counter() - t
print(json.dumps({"code": sampling.__file__, "wall": wall, "accepted": s.accepted,
                  "drawn": s.drawn, "stages": s.stage_seconds}))
"""


def run_child(path, n: int, seed: int, grid: int, workers: int) -> dict:
    """One sampling job in a child process with the code at ``path`` (None: this checkout)."""
    return harness.run_child(path, _CHILD, n, seed, grid, workers)


def describe(label: str, r: dict, grid: int) -> str:
    acc = max(r["accepted"], 1)
    rate = 60.0 * r["accepted"] / r["wall"]
    stages = ", ".join(f"{k} {v / acc:.2f}" for k, v in sorted(r["stages"].items()))
    per = sum(r["stages"].values()) / acc
    return (
        f"  {label:<9} {rate:7.1f} shapes/min  {r['accepted']}/{r['drawn']} accepted  "
        f"worker s/accepted {per:.2f} ({stages})"
    )


def main(argv: list[str] | None = None) -> None:
    ap = harness.parser(__doc__, baseline="optional")
    ap.add_argument("--grids", type=int, nargs="+", default=[48, 64, 96, 128])
    ap.add_argument("--n", type=int, nargs="+", default=[6, 6, 4, 3], help="per grid")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    args = ap.parse_args(argv)
    ns = (args.n * len(args.grids))[: len(args.grids)] if len(args.n) == 1 else args.n
    if len(ns) != len(args.grids):
        raise SystemExit("error: give one --n, or one per grid")
    run = harness.Run("sample_grids", args)
    with harness.revisions(args.baseline) as versions:
        for path in versions.values():  # compile numba's kernels outside the timings
            run_child(path, 1, args.seed, 16, 1)
        first_cost = None
        for grid, n in zip(args.grids, ns, strict=True):
            run.say(f"grid {grid} (n {n}, seed {args.seed}, {args.workers} workers)")
            results = {
                label: run_child(p, n, args.seed, grid, args.workers)
                for label, p in versions.items()
            }
            for label, r in results.items():
                run.say(describe(label, r, grid))
            new = results["now"]
            cost = sum(new["stages"].values()) / max(new["accepted"], 1) / grid**3
            first_cost = first_cost or cost
            run.say(
                f"  grid cost (worker s per accepted shape per grid point) x{cost / first_cost:.2f}"
                f" of grid {args.grids[0]}'s"
            )
            if "baseline" in results:
                per_shape = {k: r["wall"] / max(r["accepted"], 1) for k, r in results.items()}
                work = {
                    k: sum(r["stages"].values()) / max(r["accepted"], 1) for k, r in results.items()
                }
                speed = harness.ratio(per_shape["baseline"], per_shape["now"])
                run.say(
                    f"  ratio baseline / now: wall time per accepted shape x{speed:.2f}, "
                    f"worker time per accepted shape "
                    f"x{harness.ratio(work['baseline'], work['now']):.2f}"
                )
            run.record(**{f"grid_{grid}": results})
    run.save()


if __name__ == "__main__":
    main()
