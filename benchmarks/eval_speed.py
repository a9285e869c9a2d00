"""Points per second of the fast evaluator against numpy, measured in one run.

    python -m benchmarks.eval_speed            # the issue's cases (tens of minutes here)
    python -m benchmarks.eval_speed --quick    # smaller grids, 10 random formulas

Cases: presets A (82^3, 256^3), B (34^3, 256^3), C (256^3) and random eq. (13) formulas at
128^3. Baselines, timed in the same run: "numpy" is the reference evaluator on the open
(broadcast) grid computing with **numpy's own ufuncs** (``maths="numpy"``: SIMD maths where the
CPU has it, the direct forms of the round trips), "dense" the same on dense ``np.meshgrid``
arrays (a notebook user's code: every node per point). Also printed: op-evaluations per second
(tape operations x points / s, as fidget counts them for a brute-force evaluator, and the
per-point block's operations x points / s, the work actually done), the one-time compile cost
of the interpreter, the peak memory of a 512^3 evaluation and a cycle profile by opcode. Speed
figures are ratios measured in the same run, because the machine is shared and absolute times
are noisy. Every fast field is checked bit for bit against surfgen's reference (the same maths
in numpy) and compared with the numpy-ufunc field (max relative difference).
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
from collections import defaultdict
from dataclasses import asdict, dataclass

import numba
import numpy as np
from numba import njit, prange

from benchmarks import harness
from benchmarks.workloads import sampled_eq13, stored_eq13
from surfgen.generator.eval.compiler import LEVEL_NAMES, OPNAMES, Program, compile_tree
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.reference import evaluate_points, evaluate_reference
from surfgen.generator.eval.tape import evaluate_program, profile_program, scratch_bytes, warm_up
from surfgen.generator.formula.expr import Expr
from surfgen.generator.model.presets import get_preset

# A second, naive baseline: numpy on dense (Nx, Ny, Nz) coordinate arrays, so every
# sub-expression is computed per point (what an evaluator without hoisting does). The numpy
# reference itself evaluates on an open, broadcast grid, which already hoists.
DENSE_MAX_N = 128

LIBM = {"pow", "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "exp", "log", "log10"}
LIBM |= {"sinh", "cosh", "tanh", "asinh", "acosh", "atanh", "cbrt", "powi"}
LIBM |= {"atantan", "asinsin", "acoscos", "acotcot"}

# ----------------------------------------------------------------------------- timing


@dataclass
class Case:
    name: str
    tree: Expr
    box: Box
    n: int
    params: dict


@dataclass
class Row:
    name: str
    n: int
    fast1: float  # points per second
    fast2: float
    ref: float  # numpy's ufuncs on the open grid
    maxrel: float  # fast vs numpy's ufuncs
    same_nonfinite: bool
    finite: float
    exact: bool  # fast == surfgen's reference bit for bit
    ops: int  # tape operations
    ops_point: int  # operations of the per-point block
    dense: float | None = None  # numpy on dense 3-D coordinates: every node per point

    @property
    def ratio_dense(self) -> float | None:
        return None if self.dense is None else self.fast1 / self.dense

    @property
    def ratio1(self) -> float:
        return self.fast1 / self.ref

    @property
    def ratio2(self) -> float:
        return self.fast2 / self.ref

    @property
    def scaling(self) -> float:
        return self.fast2 / self.fast1


def compare(a: np.ndarray, b: np.ndarray) -> tuple[float, bool]:
    same = np.array_equal(np.isnan(a), np.isnan(b)) and np.array_equal(np.isinf(a), np.isinf(b))
    fin = np.isfinite(a) & np.isfinite(b)
    d = np.abs(a[fin] - b[fin])
    m = np.maximum(np.abs(a[fin]), np.abs(b[fin]))
    rel = np.divide(d, m, out=np.zeros_like(d), where=m > 0)
    return (float(rel.max()) if rel.size else 0.0), same


def run_case(case: Case, repeats: int) -> Row:
    grid = Grid(case.box, (case.n,) * 3)
    program = compile_tree(case.tree, case.params)
    fns = {
        "fast1": lambda: evaluate_program(program, grid, threads=1).values,
        "fast2": lambda: evaluate_program(program, grid, threads=2).values,
        "ref": lambda: evaluate_reference(case.tree, grid, case.params, maths="numpy").values,
    }
    if case.n <= DENSE_MAX_N:  # the dense baseline keeps every node's full array: small grids only
        ax = np.meshgrid(*grid.axes(), indexing="ij", copy=True)
        fns["dense"] = lambda: evaluate_points(case.tree, *ax, case.params, maths="numpy")
    # the candidates take turns: a burst of load on a shared machine hits all alike
    timings = harness.take_turns(fns, repeats)
    times = {name: t.best for name, t in timings.items()}
    t1, t2, tr = times["fast1"], times["fast2"], times["ref"]
    fast, ref = timings["fast1"].result, timings["ref"].result
    maxrel, same = compare(fast, ref)
    own = evaluate_reference(case.tree, grid, case.params).values
    exact = bool(
        ((fast.view(np.int64) == own.view(np.int64)) | (np.isnan(fast) & np.isnan(own))).all()
    )
    pts = grid.size
    dense = pts / times["dense"] if "dense" in times else None
    return Row(
        case.name,
        case.n,
        pts / t1,
        pts / t2,
        pts / tr,
        maxrel,
        same,
        np.isfinite(ref).mean(),
        exact,
        len(program.code),
        int(program.blocks[7, 1] - program.blocks[7, 0]),
        dense,
    )


# ----------------------------------------------------------------------------- machine check


def thread_calibration() -> tuple[float, float]:
    """Speed-up of 2 numba threads over 1 on a pure compute loop (not the interpreter), and the
    load average: on a shared machine this says how many cores the run really had."""

    @njit(cache=True)
    def spin(i0, i1, out):
        for i in range(i0, i1):
            s = 0.0
            for k in range(100_000):
                s += math.sin(k * 1e-3 + i)
            out[i] = s

    @njit(parallel=True, cache=True)
    def spread(out):
        for c in prange(16):
            spin(c * out.size // 16, (c + 1) * out.size // 16, out)

    out = np.zeros(128)
    spread(out)
    times = {}
    previous = numba.get_num_threads()
    for threads in (1, 2, 1, 2):
        numba.set_num_threads(threads)
        t = harness.best_of(lambda: spread(out), 2, warmup=0).best
        times[threads] = min(times.get(threads, t), t)
    numba.set_num_threads(previous)
    return times[1] / times[2], os.getloadavg()[0]


# ----------------------------------------------------------------------------- compile, memory

_STARTUP = """
import json, time
t0 = time.perf_counter()
from surfgen.generator.eval.tape import warm_up
t1 = time.perf_counter()
serial = warm_up(parallel=False)
both = warm_up(parallel=True) if {parallel} else 0.0
print(json.dumps({{"import": t1 - t0, "serial": serial, "parallel": both}}))
"""


def startup(cache_dir: str | None, parallel: bool) -> dict:
    env = {"NUMBA_CACHE_DIR": cache_dir} if cache_dir else {}
    return harness.run_child(None, _STARTUP.format(parallel=parallel), env=env)


_MEMORY = """
import json, numpy as np
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.tape import evaluate_program, warm_up
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.model.presets import get_preset

def status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1]) * 1024

spec = get_preset("{name}").spec()
program = compile_tree(spec.tree(), spec.params)
grid = Grid(Box.from_bounds(spec.box), ({n}, {n}, {n}))
warm_up(parallel={threads} > 1)
open("/proc/self/clear_refs", "w").write("5")  # reset the peak (VmHWM) to the current RSS
before = status("VmRSS:")
field = evaluate_program(program, grid, threads={threads})
print(json.dumps({{"before": before, "peak": status("VmHWM:"), "field": field.values.nbytes}}))
"""


def peak_memory(name: str, n: int, threads: int) -> dict:
    return harness.run_child(None, _MEMORY.format(name=name, n=n, threads=threads))


# ----------------------------------------------------------------------------- profile


def profile(programs: list[tuple[Program, Box]], n: int) -> tuple[dict, dict, float]:
    """Share of fast-path cycles by opcode (per-point block) and by level."""
    by_op: dict[str, float] = defaultdict(float)
    by_level: dict[str, float] = defaultdict(float)
    total = 0.0
    for program, box in programs:
        _, cycles = profile_program(program, Grid(box, (n, n, n)))
        for lv, name in LEVEL_NAMES.items():
            c0, c1 = program.blocks[lv, :2]
            by_level[name] += cycles[c0:c1].sum()
        c0, c1 = program.blocks[7, :2]
        for row, c in zip(program.code[c0:c1], cycles[c0:c1], strict=True):
            by_op[OPNAMES[int(row[0])]] += c
        total += cycles.sum()
    return by_op, by_level, total


# ----------------------------------------------------------------------------- main


def main(argv: list[str] | None = None) -> int:
    ap = harness.parser(__doc__)
    ap.add_argument(
        "--quick", action="store_true", help="small grids, 10 formulas, no cold compile"
    )
    ap.add_argument("--formulas", type=int, default=None, help="random eq. (13) formulas")
    ap.add_argument("--random-n", type=int, default=None, help="grid of the random formulas")
    ap.add_argument(
        "--seed", type=int, default=None, help="draw the formulas with the sampler (this seed)"
    )
    ap.add_argument("--skip-compile", action="store_true", help="do not measure compile cost")
    ap.add_argument("--skip-memory", action="store_true", help="do not measure 512^3 memory")
    args = ap.parse_args(argv)
    run = harness.Run("eval_speed", args)
    quick = args.quick
    n_formulas = args.formulas or (10 if quick else 50)
    big, rand_n, mem_n = (128, 64, 256) if quick else (256, 128, 512)
    rand_n = args.random_n or rand_n

    run.say(f"numba interpreter warm-up (compiles on first use): {warm_up():.2f} s")
    speedup, load = thread_calibration()
    run.say(
        f"machine check: 2 threads on a plain numba compute loop run {speedup:.2f}x faster"
        f" than 1 (load average {load:.1f} on {os.cpu_count()} cores)"
    )
    cases = []
    for preset, sizes in (("eqA", (82, big)), ("eqB", (34, big)), ("eqC", (big,))):
        spec = get_preset(preset).spec()
        for n in sizes:
            box = Box.from_bounds(spec.box)
            cases.append(Case(preset, spec.tree(), box, n, dict(spec.params)))
    randoms = [
        Case(f"eq13 #{i}", tree, box, rand_n, {})
        for i, (tree, box) in enumerate(
            stored_eq13(n_formulas) if args.seed is None else sampled_eq13(args.seed, n_formulas)
        )
    ]

    header = (
        f"{'case':12s} {'grid':>6s} {'fast 1T':>9s} {'fast 2T':>9s} {'numpy':>8s}"
        f" {'1T/np':>6s} {'2T/np':>6s} {'2T/1T':>6s} {'1T/dense':>8s} {'finite':>6s}"
        f" {'max rel':>8s} nonfinite surfgen-ref"
    )
    run.say("\nMpoints/s; numpy = numpy's own ufuncs on the open grid (same run; best of repeats)")
    run.say(header)
    run.say("-" * len(header))
    rows: list[Row] = []
    for case in cases + randoms:
        repeats = 1 if case.n >= 256 else 3 if case.n > 64 else 5
        row = run_case(case, repeats)
        rows.append(row)
        run.say(
            f"{row.name:12s} {row.n:>4d}^3 {row.fast1 / 1e6:9.2f} {row.fast2 / 1e6:9.2f}"
            f" {row.ref / 1e6:8.2f} {row.ratio1:6.1f} {row.ratio2:6.1f} {row.scaling:6.2f}"
            f" {'-' if row.ratio_dense is None else f'{row.ratio_dense:.1f}':>8s}"
            f" {row.finite:6.0%} {row.maxrel:8.1e} {'same' if row.same_nonfinite else 'differ'}"
            f" {'exact' if row.exact else 'NOT EXACT'}"
        )
    preset_rows, random_rows = rows[: len(cases)], rows[len(cases) :]
    med1 = float(np.median([r.ratio1 for r in random_rows]))
    med2 = float(np.median([r.ratio2 for r in random_rows]))
    scal = float(np.median([r.scaling for r in rows if r.n >= 128]))
    run.say("-" * len(header))
    run.say(
        f"random eq. (13) at {rand_n}^3, median fast/numpy: 1 thread {med1:.1f}x, 2 threads {med2:.1f}x"
    )
    q1, q3 = np.percentile([r.ratio1 for r in random_rows], [25, 75])
    at3 = sum(r.ratio1 >= 3.0 for r in random_rows)
    run.say(
        f"random eq. (13) at {rand_n}^3, fast (1 thread)/numpy quartiles: {q1:.2f}x / {med1:.2f}x"
        f" / {q3:.2f}x ({at3} of {len(random_rows)} at 3x or more)"
    )
    dense = [r.ratio_dense for r in random_rows if r.ratio_dense is not None]
    if dense:
        run.say(
            f"random eq. (13) at {rand_n}^3, median fast (1 thread) / numpy on dense arrays:"
            f" {float(np.median(dense)):.1f}x"
        )
    tape = float(np.median([r.ops * r.fast1 for r in random_rows]))
    work = float(np.median([r.ops_point * r.fast1 for r in random_rows]))
    run.say(
        f"random eq. (13) at {rand_n}^3, 1 thread, median op-evaluations/s: {tape / 1e9:.2f} G"
        f" (tape ops x points / s; {work / 1e9:.2f} G counting only the per-point block)"
    )
    run.say(f"presets, fast/numpy on 1 thread: min {min(r.ratio1 for r in preset_rows):.1f}x")
    run.say(f"2 threads / 1 thread, median over grids >= 128^3: {scal:.2f}x")
    speedup, load = thread_calibration()
    run.say(
        f"machine check after the run: plain loop 2T/1T {speedup:.2f}x, load average {load:.1f}"
    )
    exact = all(r.exact for r in rows)
    run.say(f"fast == surfgen's reference bit for bit in every case: {exact}")
    run.record(
        rows=[asdict(r) for r in rows],
        random_median_fast_over_numpy={"1 thread": med1, "2 threads": med2},
        two_threads_over_one=scal,
        op_evaluations_per_second={"tape": tape, "per_point_block": work},
        exact=exact,
    )

    # Where the time goes.
    programs = [(compile_tree(c.tree, c.params), c.box) for c in randoms]
    by_op, by_level, total = profile(programs, 48 if quick else 64)
    xyz = sum(by_op.values())
    run.say(
        f"\nfast-path profile, {len(programs)} random formulas (cycles by opcode, per-point block)"
    )
    run.say(
        f"  per-point block: {xyz / total:.0%} of all cycles; by level: "
        + ", ".join(f"{k} {v / total:.1%}" for k, v in by_level.items() if v / total >= 0.001)
    )
    libm = sum(v for k, v in by_op.items() if k in LIBM)
    run.say(
        f"  elementary functions (surfgen's pow, trigonometric, round trips, ...): {libm / xyz:.0%}"
    )
    for k, v in sorted(by_op.items(), key=lambda kv: -kv[1])[:10]:
        run.say(f"    {k:8s} {v / xyz:6.1%}")
    run.record(profile={k: v / xyz for k, v in by_op.items()})

    if not args.skip_compile:
        run.say("\nstart-up of the interpreter (subprocesses)")
        if not quick:
            with tempfile.TemporaryDirectory() as tmp:
                cold = startup(tmp, parallel=True)
                cached = startup(tmp, parallel=True)
            run.say(
                f"  cold compile (empty cache): serial {cold['serial']:.1f} s + parallel {cold['parallel']:.1f} s"
            )
            run.record(cold_compile=cold)
        else:
            cached = startup(None, parallel=True)
        run.record(startup=cached)
        run.say(f"  import surfgen.generator.eval.tape: {cached['import']:.2f} s")
        run.say(
            f"  from cache: serial kernel {cached['serial']:.2f} s, parallel kernel {cached['parallel']:.2f} s"
        )

    if not args.skip_memory:
        run.say(f"\npeak memory of one {mem_n}^3 evaluation on 2 threads (subprocess, VmHWM)")
        for name in ("eqA", "eqB", "eqC"):
            if quick and name != "eqC":
                continue
            m = peak_memory(name, mem_n, threads=2)
            run.record(**{f"memory_{name}": m})
            extra = m["peak"] - m["before"] - m["field"]
            spec = get_preset(name).spec()
            grid = Grid(Box.from_bounds(spec.box), (mem_n,) * 3)
            planned = scratch_bytes(compile_tree(spec.tree(), spec.params), grid, threads=2)
            run.say(
                f"  {name}: field {m['field'] / 2**20:.0f} MiB; peak resident beyond it"
                f" {extra / 2**20:.1f} MiB = {extra / m['field']:.2%} of the field"
                f" (interpreter scratch {planned / 2**20:.1f} MiB)"
            )
    run.save()
    return 0


if __name__ == "__main__":
    sys.exit(main())
