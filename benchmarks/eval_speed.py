"""Points per second of the fast evaluator against numpy, measured in one run.

    python benchmarks/bench_eval.py            # the issue's cases (tens of minutes here)
    python benchmarks/bench_eval.py --quick    # smaller grids, 10 random formulas

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

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from dataclasses import dataclass

import numpy as np

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

# ----------------------------------------------------------------------------- random eq. (13)


def random_eq13(rng: np.random.Generator) -> Expr:
    """An eq. (13) formula drawn the way the sampler draws them (1-2 sums of 1-2 factors, power
    functions of 1-3 terms, real exponents on absolute values, trigonometric and constituent
    H and G, absolute values on elements)."""
    from surfgen.generator.model import equation13 as eq

    def power() -> eq.PowerFunction:
        absolute = bool(rng.random() < 0.6)
        terms = []
        for _ in range(rng.integers(1, 4)):
            exps = []
            for _ in range(3):
                if rng.random() < 0.35:
                    exps.append(0.0)
                elif absolute and rng.random() < 0.5:
                    exps.append(float(rng.choice([0.31, 0.5, 1.3, 1.38, 2.7, 3.3])))
                else:
                    exps.append(float(rng.integers(1, 5)))
            a = float(np.round(rng.uniform(0.2, 3.0), 2) * rng.choice([1, 1, -1]))
            terms.append(eq.PowerTerm(a, *exps))
        return eq.PowerFunction(tuple(terms), absolute)

    def transform(names) -> eq.Transform:
        if rng.random() < 0.2:
            name = str(rng.choice(list(eq.CONSTITUENT_TRANSFORMS)))
            params = {"r": 0.5 + rng.random(), "p": float(rng.integers(1, 6)), "h": 1.5}
            params["t"] = 0.3 if name != "rect3" else 0.5
            return eq.Transform(name, tuple(params[k] for k in eq.CONSTITUENT_TRANSFORMS[name]))
        return eq.Transform(str(rng.choice(names)))

    def exponent() -> float:
        return float(rng.choice([1, 1, 1, 2, 3, -1, 0.5, 1.5]))

    products = []
    for _ in range(rng.integers(1, 3)):
        factors = []
        for _ in range(rng.integers(1, 3)):
            powers = tuple(
                power() if rng.random() < 0.85 else eq.PowerFunction.constant() for _ in range(8)
            )
            factors.append(
                eq.Factor(
                    powers=powers,
                    lambdas=tuple(exponent() for _ in range(8)),
                    mus=tuple(exponent() for _ in range(4)),
                    h=transform(eq.DIRECT_TRIG),
                    g=transform(eq.INVERSE_TRIG),
                    absolute=tuple(bool(rng.random() < 0.4) for _ in range(6)),
                )
            )
        products.append(tuple(factors))
    return eq.Equation13(tuple(products), float(np.round(rng.uniform(-1, 1), 2))).to_tree()


def kept_eq13(rng: np.random.Generator, tries: int = 100) -> Expr:
    """A random eq. (13) formula (own generator) whose 16^3 field changes sign."""
    coarse = Grid(Box.cube(2.0), (16, 16, 16))
    for _ in range(tries):
        tree = random_eq13(rng)
        v = evaluate_reference(tree, coarse).values
        if (v < 0).any() and (v > 0).any():
            return tree
    return tree


STORED = os.path.join(os.path.dirname(__file__), "..", "tests", "support", "data")
STORED = os.path.join(STORED, "eq13_formulas.jsonl")


def stored_eq13(count: int) -> list[tuple[Expr, Box]]:
    """The 50 eq. (13) formulas stored for the field-hash test (drawn once by the sampler,
    seed 7): the same formulas whatever the sampler becomes."""
    from surfgen.generator.formula.parser import parse

    with open(STORED) as f:
        rows = [json.loads(line) for line in f][:count]
    return [(parse(r["formula"]), Box(tuple(r["lo"]), tuple(r["hi"]))) for r in rows]


def sampled_eq13(seed: int, count: int) -> list[tuple[Expr, Box]]:
    """The first ``count`` formulas of the project's sampler (default config) that get a d,
    with their boxes; falls back to :func:`kept_eq13` when the sampler is not there."""
    try:
        from surfgen.generator.model.sampler import SamplerConfig, choose_d, draw_equation
    except ImportError:
        rngs = (np.random.default_rng(np.random.SeedSequence([seed, i])) for i in range(count))
        return [(kept_eq13(rng), Box.cube(2.0)) for rng in rngs]
    cfg = SamplerConfig()
    out, index = [], 0
    while len(out) < count:
        draw = draw_equation(seed, index, cfg)
        index += 1
        d = choose_d(draw, cfg, evaluator="reference")
        if d is not None:
            out.append((draw.equation.with_d(d).to_tree(), draw.box))
    return out


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


def best_time(fn, repeats: int) -> tuple[float, np.ndarray]:
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def compare(a: np.ndarray, b: np.ndarray) -> tuple[float, bool]:
    same = np.array_equal(np.isnan(a), np.isnan(b)) and np.array_equal(np.isinf(a), np.isinf(b))
    fin = np.isfinite(a) & np.isfinite(b)
    d = np.abs(a[fin] - b[fin])
    m = np.maximum(np.abs(a[fin]), np.abs(b[fin]))
    rel = np.divide(d, m, out=np.zeros_like(d), where=m > 0)
    return (float(rel.max()) if rel.size else 0.0), same


def interleaved(fns: dict, repeats: int) -> tuple[dict[str, float], dict[str, np.ndarray]]:
    """Best time of each function over ``repeats`` rounds, the functions taking turns in every
    round: on a shared machine a burst of load then hits all candidates alike instead of
    whichever happened to be timed at that moment (the ratios are what this script reports)."""
    best = dict.fromkeys(fns, float("inf"))
    outs: dict[str, np.ndarray] = {}
    for _ in range(repeats):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            outs[name] = fn()
            best[name] = min(best[name], time.perf_counter() - t0)
    return best, outs


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
    times, outs = interleaved(fns, repeats)
    t1, t2, tr = times["fast1"], times["fast2"], times["ref"]
    fast, ref = outs["fast1"], outs["ref"]
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
    import math

    import numba
    from numba import njit, prange

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
        t, _ = best_time(lambda: spread(out), 2)
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
    env = dict(os.environ)
    if cache_dir:
        env["NUMBA_CACHE_DIR"] = cache_dir
    code = _STARTUP.format(parallel=parallel)
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


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
    code = _MEMORY.format(name=name, n=n, threads=threads)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
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
    args = ap.parse_args()
    quick = args.quick
    n_formulas = args.formulas or (10 if quick else 50)
    big, rand_n, mem_n = (128, 64, 256) if quick else (256, 128, 512)
    rand_n = args.random_n or rand_n

    print(f"numba interpreter warm-up (compiles on first use): {warm_up():.2f} s", flush=True)
    speedup, load = thread_calibration()
    print(
        f"machine check: 2 threads on a plain numba compute loop run {speedup:.2f}x faster"
        f" than 1 (load average {load:.1f} on {os.cpu_count()} cores)",
        flush=True,
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
    print("\nMpoints/s; numpy = numpy's own ufuncs on the open grid (same run; best of repeats)")
    print(header)
    print("-" * len(header))
    rows: list[Row] = []
    for case in cases + randoms:
        repeats = 1 if case.n >= 256 else 3 if case.n > 64 else 5
        row = run_case(case, repeats)
        rows.append(row)
        print(
            f"{row.name:12s} {row.n:>4d}^3 {row.fast1 / 1e6:9.2f} {row.fast2 / 1e6:9.2f}"
            f" {row.ref / 1e6:8.2f} {row.ratio1:6.1f} {row.ratio2:6.1f} {row.scaling:6.2f}"
            f" {'-' if row.ratio_dense is None else f'{row.ratio_dense:.1f}':>8s}"
            f" {row.finite:6.0%} {row.maxrel:8.1e} {'same' if row.same_nonfinite else 'differ'}"
            f" {'exact' if row.exact else 'NOT EXACT'}",
            flush=True,
        )
    preset_rows, random_rows = rows[: len(cases)], rows[len(cases) :]
    med1 = float(np.median([r.ratio1 for r in random_rows]))
    med2 = float(np.median([r.ratio2 for r in random_rows]))
    scal = float(np.median([r.scaling for r in rows if r.n >= 128]))
    print("-" * len(header))
    print(
        f"random eq. (13) at {rand_n}^3, median fast/numpy: 1 thread {med1:.1f}x, 2 threads {med2:.1f}x"
    )
    q1, q3 = np.percentile([r.ratio1 for r in random_rows], [25, 75])
    at3 = sum(r.ratio1 >= 3.0 for r in random_rows)
    print(
        f"random eq. (13) at {rand_n}^3, fast (1 thread)/numpy quartiles: {q1:.2f}x / {med1:.2f}x"
        f" / {q3:.2f}x ({at3} of {len(random_rows)} at 3x or more)"
    )
    dense = [r.ratio_dense for r in random_rows if r.ratio_dense is not None]
    if dense:
        print(
            f"random eq. (13) at {rand_n}^3, median fast (1 thread) / numpy on dense arrays:"
            f" {float(np.median(dense)):.1f}x"
        )
    tape = float(np.median([r.ops * r.fast1 for r in random_rows]))
    work = float(np.median([r.ops_point * r.fast1 for r in random_rows]))
    print(
        f"random eq. (13) at {rand_n}^3, 1 thread, median op-evaluations/s: {tape / 1e9:.2f} G"
        f" (tape ops x points / s; {work / 1e9:.2f} G counting only the per-point block)"
    )
    print(f"presets, fast/numpy on 1 thread: min {min(r.ratio1 for r in preset_rows):.1f}x")
    print(f"2 threads / 1 thread, median over grids >= 128^3: {scal:.2f}x")
    speedup, load = thread_calibration()
    print(f"machine check after the run: plain loop 2T/1T {speedup:.2f}x, load average {load:.1f}")
    exact = all(r.exact for r in rows)
    print(f"fast == surfgen's reference bit for bit in every case: {exact}")

    # Where the time goes.
    programs = [(compile_tree(c.tree, c.params), c.box) for c in randoms]
    by_op, by_level, total = profile(programs, 48 if quick else 64)
    xyz = sum(by_op.values())
    print(
        f"\nfast-path profile, {len(programs)} random formulas (cycles by opcode, per-point block)"
    )
    print(
        f"  per-point block: {xyz / total:.0%} of all cycles; by level: "
        + ", ".join(f"{k} {v / total:.1%}" for k, v in by_level.items() if v / total >= 0.001)
    )
    libm = sum(v for k, v in by_op.items() if k in LIBM)
    print(
        f"  elementary functions (surfgen's pow, trigonometric, round trips, ...): {libm / xyz:.0%}"
    )
    for k, v in sorted(by_op.items(), key=lambda kv: -kv[1])[:10]:
        print(f"    {k:8s} {v / xyz:6.1%}")

    if not args.skip_compile:
        print("\nstart-up of the interpreter (subprocesses)")
        if not quick:
            with tempfile.TemporaryDirectory() as tmp:
                cold = startup(tmp, parallel=True)
                cached = startup(tmp, parallel=True)
            print(
                f"  cold compile (empty cache): serial {cold['serial']:.1f} s + parallel {cold['parallel']:.1f} s"
            )
        else:
            cached = startup(None, parallel=True)
        print(f"  import surfgen.generator.eval.tape: {cached['import']:.2f} s")
        print(
            f"  from cache: serial kernel {cached['serial']:.2f} s, parallel kernel {cached['parallel']:.2f} s"
        )

    if not args.skip_memory:
        print(f"\npeak memory of one {mem_n}^3 evaluation on 2 threads (subprocess, VmHWM)")
        for name in ("eqA", "eqB", "eqC"):
            if quick and name != "eqC":
                continue
            m = peak_memory(name, mem_n, threads=2)
            extra = m["peak"] - m["before"] - m["field"]
            spec = get_preset(name).spec()
            grid = Grid(Box.from_bounds(spec.box), (mem_n,) * 3)
            planned = scratch_bytes(compile_tree(spec.tree(), spec.params), grid, threads=2)
            print(
                f"  {name}: field {m['field'] / 2**20:.0f} MiB; peak resident beyond it"
                f" {extra / 2**20:.1f} MiB = {extra / m['field']:.2%} of the field"
                f" (interpreter scratch {planned / 2**20:.1f} MiB)"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
