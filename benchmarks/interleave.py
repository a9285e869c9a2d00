"""What forcing LLVM's interleave count gains (generator/jit/interleave.py), measured in one run.

    python -m benchmarks.interleave              # rows, then the 50 stored formulas
    python -m benchmarks.interleave --rows-only  # the elementary rows alone (a minute)

1. **The elementary functions' rows**, in this process: each row function compiled twice from
   its own source, once as surfgen compiles it (``SURFGEN_INTERLEAVE``, default 4 vectors per
   iteration) and once with LLVM's own choice, timed in turn on the same 1024-value row (the
   interpreter's tile), best of many; the two must give the same bits.
2. **Whole evaluations**: the 50 stored eq. (13) formulas of the field-hash test at 128^3 on one
   thread, in subprocesses that compile the interpreter with LLVM's choice
   (``SURFGEN_INTERLEAVE=0``) and with surfgen's, each in a numba cache of its own (the first
   pass compiles: about a minute and a half each), then alternately; per formula the best time.
   The fields' sha256 must agree.

Ratios are LLVM's choice's time over surfgen's: above 1, surfgen's compile is faster.
"""

from __future__ import annotations

import sys
import tempfile
import types

import numpy as np
from numba import njit

from benchmarks import harness
from surfgen.generator.elementary import REGISTRY
from surfgen.generator.jit.interleave import INTERLEAVE

N = 1024  # a W row of the interpreter's tile

UNARY = {  # name: argument range
    "sin": (-10.0, 10.0),
    "cos": (-10.0, 10.0),
    "tan": (-10.0, 10.0),
    "asin": (-1.0, 1.0),
    "acos": (-1.0, 1.0),
    "atan": (-10.0, 10.0),
    "exp": (-20.0, 20.0),
    "log": (1e-3, 1e3),
    "cbrt": (-10.0, 10.0),
    "tanh": (-5.0, 5.0),
}


def _copy(func, module: str):
    """A new Python function of the same code, as if defined in ``module`` (numba compiles it
    afresh; the interleave listener matches on the module)."""
    f = types.FunctionType(
        func.__code__, func.__globals__, func.__name__, func.__defaults__, func.__closure__
    )
    f.__module__ = module
    return f


def rows(run: harness.Run, repeats: int) -> list[tuple[str, float, bool]]:
    """Each row function compiled both ways, timed in turns: (name, LLVM's / ours, same bits)."""
    rng = np.random.default_rng(7)
    cases = []
    for name, (lo, hi) in UNARY.items():
        row = REGISTRY[name].row.py_func
        W = np.zeros((4, N))
        W[0] = rng.uniform(lo, hi, N)
        cases.append((name, row, (W, 1, 0, N), W))
    pw = REGISTRY["pow"].row_vs.py_func
    W = np.zeros((4, N))
    W[0] = rng.uniform(1e-3, 10.0, N)
    cases.append(("pow (x^1.37)", pw, (W, 1, 0, 1.37, N), W))
    at2 = REGISTRY["atan2"].row_vv.py_func
    W = np.zeros((4, N))
    W[0], W[2] = rng.uniform(-5.0, 5.0, N), rng.uniform(-5.0, 5.0, N)
    cases.append(("atan2", at2, (W, 1, 0, 2, N), W))

    opts = {"error_model": "numpy", "nogil": True}
    out = []
    for name, func, args, W in cases:
        ours = njit(**opts)(_copy(func, func.__module__))  # as surfgen compiles it
        llvms = njit(**opts)(_copy(func, "benchmarks.interleave"))  # LLVM's own choice
        results = []
        for f in (ours, llvms):
            W[1] = 0.0
            f(*args)
            results.append(W[1].copy())
        same = np.array_equal(results[0].view(np.int64), results[1].view(np.int64))
        timings = harness.take_turns(
            {key: _calls(f, args, 200) for key, f in (("ours", ours), ("llvm", llvms))}, repeats
        )
        best = {key: t.best / 200 for key, t in timings.items()}
        out.append((name, harness.ratio(best["llvm"], best["ours"]), same))
        run.say(
            f"  {name:14s} {best['ours'] / N * 1e9:6.2f} ns/value with {INTERLEAVE} vectors per"
            f" iteration, {best['llvm'] / N * 1e9:6.2f} with LLVM's choice:"
            f" {best['llvm'] / best['ours']:.2f}x{'' if same else '  BITS DIFFER'}"
        )
    return out


def _calls(f, args: tuple, calls: int):
    """``f(*args)`` ``calls`` times, as one timed candidate."""

    def repeat() -> None:
        for _ in range(calls):
            f(*args)

    return repeat


# ----------------------------------------------------------------------------- whole evaluations

_CHILD = r"""
import hashlib, json, sys, time
from benchmarks.workloads import stored_eq13
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.tape import evaluate_program, warm_interpreter
from surfgen.generator.eval.grid import Grid
t0 = time.perf_counter()
warm_interpreter()
compile_s = time.perf_counter() - t0
items = [(compile_tree(t), Grid(box, ({n},) * 3)) for t, box in stored_eq13({count})]
best, digest = [], hashlib.sha256()
for program, grid in items:
    times = []
    for _ in range({repeats}):
        t = time.perf_counter()
        field = evaluate_program(program, grid, threads=1)
        times.append(time.perf_counter() - t)
    best.append(min(times))
    digest.update(field.values.tobytes())
print(json.dumps({{"best": best, "sha256": digest.hexdigest(), "compile": compile_s}}))
"""


def evaluations(
    run: harness.Run, cache_root: str, rounds: int, n: int, count: int, repeats: int
) -> None:
    """The stored formulas in subprocesses compiled both ways, alternately (round 0 compiles)."""
    code = _CHILD.format(n=n, count=count, repeats=repeats)
    runs: dict[str, list[dict]] = {"llvm": [], "ours": []}
    for r in range(rounds + 1):  # round 0 compiles (and fills each cache)
        for key, count_env in (("llvm", "0"), ("ours", str(INTERLEAVE))):
            env = {"SURFGEN_INTERLEAVE": count_env, "OMP_NUM_THREADS": "1"}
            env["NUMBA_CACHE_DIR"] = f"{cache_root}/interleave-{count_env}"
            result = harness.run_child(None, code, env=env)
            if r == 0:
                run.say(f"  interpreter compile, {key}: {result['compile']:.1f} s")
            runs[key].append(result)
    same = runs["llvm"][0]["sha256"] == runs["ours"][0]["sha256"]
    best = {k: np.min([run["best"] for run in v[1:]], axis=0) for k, v in runs.items()}
    run.say(
        f"  {len(best['ours'])} stored eq. (13) formulas at {n}^3, 1 thread: LLVM's choice /"
        f" surfgen's {INTERLEAVE}: {harness.ratio_summary(best['llvm'], best['ours'])}; the same"
        f" fields (sha256): {same}"
    )
    run.record(evaluations={"llvm": best["llvm"], "ours": best["ours"], "same": same})


def main(argv: list[str] | None = None) -> int:
    ap = harness.parser(__doc__, repeats=25)
    ap.add_argument("--rows-only", action="store_true", help="skip the whole evaluations")
    ap.add_argument("--rounds", type=int, default=3, help="alternate evaluation passes")
    ap.add_argument("--n", type=int, default=128, help="grid of the formulas")
    ap.add_argument("--formulas", type=int, default=50, help="stored formulas (at most 50)")
    ap.add_argument("--cache-dir", default=None, help="keep the two numba caches here")
    args = ap.parse_args(argv)
    run = harness.Run("interleave", args)

    run.say("elementary rows (same process, compiled both ways, timed in turn):")
    results = rows(run, args.repeats)
    ratios = [r for _, r, _ in results]
    run.record(rows={name: {"llvm_over_ours": r, "same_bits": same} for name, r, same in results})
    run.say(
        f"  median {np.median(ratios):.2f}x over {len(ratios)} functions;"
        f" the same bits in every case: {all(same for *_, same in results)}"
    )
    if not args.rows_only:
        run.say("\nwhole evaluations (subprocesses, alternately):")
        if args.cache_dir:
            evaluations(run, args.cache_dir, args.rounds, args.n, args.formulas, 3)
        else:
            with tempfile.TemporaryDirectory() as tmp:
                evaluations(run, tmp, args.rounds, args.n, args.formulas, 3)
    run.save()
    return 0


if __name__ == "__main__":
    sys.exit(main())
