"""The main job, `surfgen sample --n 1000 --seed 7`, before and after, in one run.

    python -m benchmarks.main_job --baseline REV [--n 1000] [--seed 7] [--workers 2]
        [--rounds 1] [--json PATH]

Runs the job (default config, thumbnails on, a fresh catalogue in a temporary folder) with the
code of this checkout and with the code of git revision REV exported into a temporary folder,
each in a child process, taking turns ``--rounds`` times (baseline first), so a change in the
machine's speed hits both alike. Each code first samples one shape at a tiny grid, so numba's
compilation (cached per code folder) is not timed. Prints, per run, the wall time, the CPU time
of the job and its workers, the draws and the rejections, then the ratios baseline / now of the
best wall and CPU times (above 1: this checkout is faster). The machine this project is developed on is shared: read the ratios.
"""

from __future__ import annotations

import os

from benchmarks import harness

_CHILD = r"""
import json, resource, sys, tempfile, time
from pathlib import Path
import surfgen.pipelines.run.sampling as sampling
from surfgen.pipelines.run.config import load_config
n, seed, workers = (int(a) for a in sys.argv[1:4])
config = load_config().with_run(timeout=3600.0)
def cpu():
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime
with tempfile.TemporaryDirectory() as tmp:
    if n > 1:  # load (or compile) every kernel first, untimed
        sampling.run_sample(n=1, seed=seed, config=config.with_grid(16),
                            catalogue=Path(tmp) / "warm", workers=1)
    c, t = cpu(), time.perf_counter()
    s = sampling.run_sample(n=n, seed=seed, config=config, catalogue=Path(tmp) / "cat",
                            workers=workers)
    wall, used = time.perf_counter() - t, cpu() - c
print(json.dumps({"code": sampling.__file__, "wall": wall, "cpu": used,
                  "accepted": s.accepted, "drawn": s.drawn, "reasons": s.counts}))
"""


def main(argv: list[str] | None = None) -> None:
    ap = harness.parser(__doc__, baseline="required")
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--rounds", type=int, default=1)
    args = ap.parse_args(argv)
    if args.n < 1 or args.rounds < 1 or args.workers < 1:
        raise SystemExit("error: --n, --rounds and --workers must be >= 1")
    run = harness.Run("main_job", args)
    best: dict[str, dict[str, float]] = {}
    with harness.revisions(args.baseline) as versions:
        for r in range(args.rounds):
            for label, path in versions.items():
                res = harness.run_child(path, _CHILD, args.n, args.seed, args.workers)
                top = sorted(res["reasons"].items(), key=lambda kv: -kv[1])[:4]
                run.say(
                    f"round {r + 1} {label:<8} wall {res['wall']:7.1f} s  cpu {res['cpu']:7.1f} s"
                    f"  {res['accepted']}/{res['drawn']} accepted  "
                    + ", ".join(f"{k} {v}" for k, v in top)
                )
                b = best.setdefault(label, {"wall": float("inf"), "cpu": float("inf")})
                b["wall"] = min(b["wall"], res["wall"])
                b["cpu"] = min(b["cpu"], res["cpu"])
    b, a = best["baseline"], best["now"]
    run.say(
        f"best of {args.rounds}: wall {b['wall']:.1f} -> {a['wall']:.1f} s"
        f" (baseline / now x{harness.ratio(b['wall'], a['wall']):.2f}), cpu "
        f"{b['cpu']:.1f} -> {a['cpu']:.1f} s (x{harness.ratio(b['cpu'], a['cpu']):.2f})"
    )
    run.record(best=best)
    run.save()


if __name__ == "__main__":
    main()
