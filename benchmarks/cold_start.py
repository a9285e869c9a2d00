"""The first run on a machine: compiling every kernel a sampled shape needs, on one CPU and on two.

    python -m benchmarks.cold_start [--rounds 1] [--json PATH]

Each run is a fresh process with an empty numba cache (``NUMBA_CACHE_DIR``, a new temporary
folder) that calls :func:`surfgen.pipelines.run.warmup.warm_shape_kernels`, as ``surfgen sample``
does before it forks its workers: once with ``parallel=False`` (everything compiled in one
process, the baseline) and once with ``parallel=True`` (every kernel but the interpreter
compiled by a child process while this one compiles the interpreter), taking turns ``--rounds``
times, baseline first.
Prints each run's wall time (the process's start and imports included) and CPU time, then the
ratio of the best parallel run over the best serial one. Afterwards the cache of every run is
checked for the grid kernel, loadable by a fresh process (so the parallel runs left nothing
to compile). Needs two CPUs to show a gain.
"""

from __future__ import annotations

import os
import resource
import tempfile

from benchmarks import harness

_RUN = """
import json, sys, time
from surfgen.pipelines.run.warmup import warm_shape_kernels
seconds = warm_shape_kernels(parallel=sys.argv[1] == "parallel")
print(json.dumps({"warm_up": seconds}))
"""

_CHECK = """
import json
from surfgen.generator.eval import grid_driver as kernels
from surfgen.pipelines.run.warmup import grid_kernel_cached, warm_grid_kernel
cached = grid_kernel_cached()
warm_grid_kernel()
print(json.dumps({"cached": cached, "misses": sum(kernels.run_grid.stats.cache_misses.values())}))
"""


def _run(mode: str, cache: str) -> dict:
    """A warm-up in ``mode`` on the empty cache ``cache``, then the check of what it left."""
    env = {"NUMBA_CACHE_DIR": cache}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    result, wall = harness.timed_child(None, _RUN, mode, env=env)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    check = harness.run_child(None, _CHECK, env=env)
    return {"wall": wall, "cpu": cpu, **result, **check}


def main(argv: list[str] | None = None) -> None:
    ap = harness.parser(__doc__)
    ap.add_argument("--rounds", type=int, default=1)
    args = ap.parse_args(argv)
    run = harness.Run("cold_start", args)
    best: dict[str, float] = {}
    for round_ in range(args.rounds):
        for mode in ("serial", "parallel"):
            with tempfile.TemporaryDirectory(prefix="surfgen-cold-") as cache:
                r = _run(mode, cache)
            best[mode] = min(best.get(mode, float("inf")), r["wall"])
            run.record(**{f"round {round_ + 1} {mode}": r})
            run.say(
                f"round {round_ + 1} {mode:8s}: {r['wall']:6.1f} s wall, {r['cpu']:6.1f} s CPU "
                f"(warm-up {r['warm_up']:.1f} s); then a fresh process finds the grid kernel "
                f"cached: {r['cached']}, compiles it again: {r['misses'] > 0}"
            )
    run.say(
        f"first run's compile, two CPUs / one: {best['parallel']:.1f} s / {best['serial']:.1f} s "
        f"= {best['parallel'] / best['serial']:.2f}"
    )
    run.say(f"load average after the runs {os.getloadavg()[0]:.1f}")
    run.record(best_wall=best)
    run.save()


if __name__ == "__main__":
    main()
