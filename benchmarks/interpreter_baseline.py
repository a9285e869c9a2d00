"""The interpreter against a baseline revision (written for the row table,
``generator/eval/row_calls.py`` and ``row_functions.py``): its cold compile, its load from the
cache, the warm-up of a fresh machine, and evaluation speed, each revision in turn in fresh
processes.

    python -m benchmarks.interpreter_baseline --baseline REV [--rounds 2] [--skip-warm-up]

1. **Cold compile**: a fresh process with an empty numba cache (``NUMBA_CACHE_DIR``) loads the
   interpreter (:func:`surfgen.generator.eval.tape.warm_interpreter`: with the row table, its rows
   too); then a second process loads it from that cache (the import of surfgen included).
2. **Warm-up** (unless ``--skip-warm-up``): what ``surfgen sample`` runs first on a fresh machine,
   :func:`surfgen.pipelines.run.warmup.warm_shape_kernels` on two processes, on an empty cache.
3. **Evaluation**: the 50 stored eq. (13) formulas of the field-hash test at 128^3 on one thread,
   best of 3 each, in the caches of step 1, revisions taking turns ``--rounds`` times (which
   goes first alternates: the first run of a round tends to be the fastest); the
   per-formula time ratio baseline / this tree, and whether every field is the same (sha256).

Prints each figure for both revisions and their ratio (baseline / this tree: above 1 means this
tree is faster).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from benchmarks import harness
from benchmarks.interleave import _CHILD as _EVALUATE

_LOAD = """
import json, time
t0 = time.perf_counter()
from surfgen.generator.eval.tape import warm_interpreter
warm_interpreter()
print(json.dumps({"seconds": time.perf_counter() - t0}))
"""

_WARM_UP = """
import json
from surfgen.pipelines.run.warmup import warm_shape_kernels
print(json.dumps({"seconds": warm_shape_kernels(parallel=True)}))
"""


def _run(path: Path | None, code: str, cache: str) -> tuple[dict, float]:
    """``code`` in a fresh process of the revision at ``path``, numba's cache at ``cache``."""
    env = {"NUMBA_CACHE_DIR": cache, "OMP_NUM_THREADS": "1"}
    return harness.timed_child(path, code, env=env)


def main(argv: list[str] | None = None) -> int:
    ap = harness.parser(__doc__, baseline="required")
    ap.add_argument("--rounds", type=int, default=4, help="evaluation rounds per revision")
    ap.add_argument("--n", type=int, default=128, help="grid of the formulas")
    ap.add_argument("--skip-warm-up", action="store_true")
    args = ap.parse_args(argv)
    run = harness.Run("interpreter_baseline", args)

    with (
        harness.revisions(args.baseline) as revisions,
        tempfile.TemporaryDirectory(prefix="bench-interpreter-") as tmp,
    ):
        caches = {k: os.path.join(tmp, f"cache-{k}") for k in revisions}
        run.say(f"baseline {args.baseline} against this tree")

        run.say("\ncold compile of the interpreter (empty cache), then its load from the cache:")
        cold = {}
        for key, path in revisions.items():
            result, _ = _run(path, _LOAD, caches[key])
            warm, wall = _run(path, _LOAD, caches[key])
            cold[key] = result["seconds"]
            run.say(
                f"  {key:8s} compile {result['seconds']:6.1f} s; load {warm['seconds']:.2f} s"
                f" ({wall:.2f} s with the process)"
            )
        run.say(f"  compile: baseline / now {harness.ratio(cold['baseline'], cold['now']):.2f}x")
        run.record(compile_seconds=cold)

        if not args.skip_warm_up:
            run.say("\nthe warm-up of a fresh machine (two processes, empty cache):")
            warm_up = {}
            for key, path in revisions.items():
                cache = os.path.join(tmp, f"warm-{key}")
                result, wall = _run(path, _WARM_UP, cache)
                warm_up[key] = wall
                run.say(f"  {key:8s} {result['seconds']:6.1f} s ({wall:.1f} s with the process)")
            speed = harness.ratio(warm_up["baseline"], warm_up["now"])
            run.say(f"  warm-up: baseline / now {speed:.2f}x")
            run.record(warm_up_seconds=warm_up)

        code = _EVALUATE.format(n=args.n, count=50, repeats=3)
        runs: dict[str, list[dict]] = {k: [] for k in revisions}
        for r in range(args.rounds):  # ABBA: the first run of a round is often the fastest
            for key in sorted(revisions, reverse=r % 2 == 1):
                runs[key].append(_run(revisions[key], code, caches[key])[0])
        same = len({run["sha256"] for v in runs.values() for run in v}) == 1
        best = {k: np.min([run["best"] for run in v], axis=0) for k, v in runs.items()}
        run.say(
            f"\n{len(best['now'])} stored eq. (13) formulas at {args.n}^3, 1 thread,"
            f" {args.rounds} rounds: baseline / now"
            f" {harness.ratio_summary(best['baseline'], best['now'])}"
            f" ({best['now'].sum():.2f} s now); the same fields (sha256): {same}"
        )
        run.record(evaluation_seconds=best, same_fields=same)
    run.save()
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
