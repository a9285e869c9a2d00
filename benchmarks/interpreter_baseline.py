"""The row table (``generator/far.py``, ``generator/row_table.py``) against a baseline revision:
the interpreter's cold compile, its load from the cache, the warm-up of a fresh machine, and
evaluation speed, each revision in turn in fresh processes.

    python benchmarks/bench_row_table.py --baseline REV [--rounds 2] [--skip-warm-up]

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

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from bench_interleave import _CHILD as _EVALUATE  # noqa: E402
from bench_interleave import ratios  # noqa: E402
from bench_sample_grids import export_revision  # noqa: E402

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
    env = dict(os.environ, NUMBA_CACHE_DIR=cache, OMP_NUM_THREADS="1")
    if path is not None:  # the baseline's packages shadow the installed ones
        env["PYTHONPATH"] = str(path) + os.pathsep + env.get("PYTHONPATH", "")
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    return json.loads(done.stdout.strip().splitlines()[-1]), time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", required=True, help="git revision to compare with")
    ap.add_argument("--rounds", type=int, default=4, help="evaluation rounds per revision")
    ap.add_argument("--n", type=int, default=128, help="grid of the formulas")
    ap.add_argument("--skip-warm-up", action="store_true")
    args = ap.parse_args()

    with tempfile.TemporaryDirectory(prefix="bench-row-table-") as tmp:
        revisions = {"baseline": export_revision(args.baseline, Path(tmp) / "base"), "now": None}
        caches = {k: os.path.join(tmp, f"cache-{k}") for k in revisions}
        print(f"baseline {args.baseline} against this tree; load average {os.getloadavg()[0]:.2f}")

        print("\ncold compile of the interpreter (empty cache), then its load from the cache:")
        cold = {}
        for key, path in revisions.items():
            result, _ = _run(path, _LOAD, caches[key])
            warm, wall = _run(path, _LOAD, caches[key])
            cold[key] = result["seconds"]
            print(
                f"  {key:8s} compile {result['seconds']:6.1f} s; load {warm['seconds']:.2f} s"
                f" ({wall:.2f} s with the process)",
                flush=True,
            )
        print(f"  compile: baseline / now {cold['baseline'] / cold['now']:.2f}x")

        if not args.skip_warm_up:
            print("\nthe warm-up of a fresh machine (two processes, empty cache):")
            warm_up = {}
            for key, path in revisions.items():
                cache = os.path.join(tmp, f"warm-{key}")
                result, wall = _run(path, _WARM_UP, cache)
                warm_up[key] = wall
                print(
                    f"  {key:8s} {result['seconds']:6.1f} s ({wall:.1f} s with the process)",
                    flush=True,
                )
            print(f"  warm-up: baseline / now {warm_up['baseline'] / warm_up['now']:.2f}x")

        code = _EVALUATE.format(here=HERE, n=args.n, count=50, repeats=3)
        runs: dict[str, list[dict]] = {k: [] for k in revisions}
        for r in range(args.rounds):  # ABBA: the first run of a round is often the fastest
            for key in sorted(revisions, reverse=r % 2 == 1):
                runs[key].append(_run(revisions[key], code, caches[key])[0])
        same = len({run["sha256"] for v in runs.values() for run in v}) == 1
        best = {k: np.min([run["best"] for run in v], axis=0) for k, v in runs.items()}
        print(
            f"\n{len(best['now'])} stored eq. (13) formulas at {args.n}^3, 1 thread,"
            f" {args.rounds} rounds: baseline / now {ratios(best['baseline'], best['now'])}"
            f" ({best['now'].sum():.2f} s now); the same fields (sha256): {same}"
        )
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
