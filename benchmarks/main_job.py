"""The main job, `surfgen sample --n 1000 --seed 7`, before and after, in one run.

    python -m benchmarks.main_job --baseline REV [--n 1000] [--seed 7] [--workers 2]
        [--rounds 1] [--cold] [--json PATH]

Runs the job (default config, thumbnails on, a fresh catalogue in a temporary folder) with the
code of this checkout and with the code of git revision REV exported into a temporary folder,
each in a child process, taking turns ``--rounds`` times (baseline first), so a change in the
machine's speed hits both alike. Each code first samples one shape at a tiny grid, so numba's
compilation (cached per code folder) is not timed. With ``--cold`` every run starts from an
empty numba cache of its own (``NUMBA_CACHE_DIR``, a new temporary folder) and is timed from
the child's start, imports and the warm-up's compile included: the first run on a fresh
machine, as ``surfgen sample`` makes it. Prints, per run, the wall time, the CPU time of the
job and its workers (with ``--cold`` the warm-up's child too), the draws and the rejections,
then the ratios baseline / now of the best wall and CPU times (above 1: this checkout is
faster). The machine this project is developed on is shared: read the ratios.
"""

from __future__ import annotations

import os
import tempfile

from benchmarks import harness

_CHILD = r"""
import time
start = time.perf_counter()  # --cold: the job as a fresh process makes it, imports included
import json, resource, sys, tempfile
from pathlib import Path
import surfgen.pipelines.run.sampling as sampling
from surfgen.pipelines.run.config import load_config
n, seed, workers = (int(a) for a in sys.argv[1:4])
cold = sys.argv[4] == "cold"
config = load_config().with_run(timeout=3600.0)
def cpu():
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime
with tempfile.TemporaryDirectory() as tmp:
    if n > 1 and not cold:  # load (or compile) every kernel first, untimed
        sampling.run_sample(n=1, seed=seed, config=config.with_grid(16),
                            catalogue=Path(tmp) / "warm", workers=1)
    c, t = (0.0, start) if cold else (cpu(), time.perf_counter())
    s = sampling.run_sample(n=n, seed=seed, config=config, catalogue=Path(tmp) / "cat",
                            workers=workers)
    wall, used = time.perf_counter() - t, cpu() - c
print(json.dumps({"code": sampling.__file__, "wall": wall, "cpu": used,
                  "accepted": s.accepted, "drawn": s.drawn, "reasons": s.counts}))
"""


def _run(path, args) -> dict:
    """One run of the job in a child (``--cold``: with an empty numba cache of its own)."""
    mode = "cold" if args.cold else "warm"
    if not args.cold:
        return harness.run_child(path, _CHILD, args.n, args.seed, args.workers, mode)
    with tempfile.TemporaryDirectory(prefix="surfgen-numba-") as cache:
        return harness.run_child(
            path, _CHILD, args.n, args.seed, args.workers, mode, env={"NUMBA_CACHE_DIR": cache}
        )


def main(argv: list[str] | None = None) -> None:
    ap = harness.parser(__doc__, baseline="required")
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--cold", action="store_true", help="each run from an empty numba cache")
    args = ap.parse_args(argv)
    if args.n < 1 or args.rounds < 1 or args.workers < 1:
        raise SystemExit("error: --n, --rounds and --workers must be >= 1")
    run = harness.Run("main_job", args)
    best: dict[str, dict[str, float]] = {}
    with harness.revisions(args.baseline) as versions:
        for r in range(args.rounds):
            for label, path in versions.items():
                res = _run(path, args)
                top = sorted(res["reasons"].items(), key=lambda kv: -kv[1])[:4]
                mode = "cold " if args.cold else ""
                run.say(
                    f"round {r + 1} {label:<8} {mode}wall {res['wall']:7.1f} s"
                    f"  cpu {res['cpu']:7.1f} s  {res['accepted']}/{res['drawn']} accepted  "
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
    run.record(best=best, cold=args.cold)
    run.save()


if __name__ == "__main__":
    main()
