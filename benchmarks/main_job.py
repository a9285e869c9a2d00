"""The main job, `surfgen sample --n 1000 --seed 7`, before and after, in one run.

    python benchmarks/bench_main_job.py --baseline REV [--n 1000] [--seed 7] [--workers 2]
        [--rounds 1]

Runs the job (default config, thumbnails on, a fresh catalogue in a temporary folder) with the
code of this checkout and with the code of git revision REV exported into a temporary folder,
each in a child process, taking turns ``--rounds`` times (baseline first), so a change in the
machine's speed hits both alike. Each code first samples one shape at a tiny grid, so numba's
compilation (cached per code folder) is not timed. Prints, per run, the wall time, the CPU time
of the job and its workers, the draws and the rejections, then the ratios new / baseline of the
best wall and CPU times. The machine this project is developed on is shared: read the ratios.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_sample_grids import export_revision, run_code  # noqa: E402

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", required=True, help="git revision to compare against")
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--rounds", type=int, default=1)
    args = ap.parse_args()
    if args.n < 1 or args.rounds < 1 or args.workers < 1:
        raise SystemExit("error: --n, --rounds and --workers must be >= 1")
    best: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        base = export_revision(args.baseline, Path(tmp))
        for r in range(args.rounds):
            for label, path in (("baseline", base), ("new", None)):
                res = run_code(path, _CHILD, args.n, args.seed, args.workers)
                top = sorted(res["reasons"].items(), key=lambda kv: -kv[1])[:4]
                print(
                    f"round {r + 1} {label:<8} wall {res['wall']:7.1f} s  cpu {res['cpu']:7.1f} s"
                    f"  {res['accepted']}/{res['drawn']} accepted  "
                    + ", ".join(f"{k} {v}" for k, v in top),
                    flush=True,
                )
                b = best.setdefault(label, {"wall": float("inf"), "cpu": float("inf")})
                b["wall"] = min(b["wall"], res["wall"])
                b["cpu"] = min(b["cpu"], res["cpu"])
    print(
        f"best of {args.rounds}: wall {best['baseline']['wall']:.1f} -> {best['new']['wall']:.1f} s"
        f" (x{best['new']['wall'] / best['baseline']['wall']:.2f}), cpu "
        f"{best['baseline']['cpu']:.1f} -> {best['new']['cpu']:.1f} s"
        f" (x{best['new']['cpu'] / best['baseline']['cpu']:.2f})"
    )


if __name__ == "__main__":
    main()
