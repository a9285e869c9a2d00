"""Sparse against dense meshing: time, peak memory, share of points evaluated, op-evaluations/s.

    python -m benchmarks.bench_sparse [--grids 128,256,512,1024] [--shapes eqA,eqB,eqC,...]
        [--repeats N] [--walls keep]

Each shape is meshed as ``surfgen render`` meshes it (``realise``, caps as the shape has them,
the sparse samples freed once read: ``keep_samples=False``; the allocator giving freed memory
back, :func:`~surfgen.generator.allocator.one_shot_memory_policy`; the walls not classified, or
as ``--walls`` says: ``keep``, render's default, classifies every crossing) with
``--evaluator fast`` (every grid point) and ``--evaluator sparse``, each run in a fresh
process after a warm-up that calls every kernel the run will (:func:`warm_up`; the table is
followed by any kernel first called inside a timed run, which would time its compile or its
load from numba's cache). Numba's allocations are invisible to tracemalloc: the peak is the
process's VmHWM from ``/proc/self/status``, started afresh after the warm-up
(:func:`reset_peak`), and ``rss0`` the process's size then, so ``peak - rss0`` is what the run
added: the table's *added ratio*, beside the ratio of the peaks, which the process's own
170-200 MiB bound: *bound* is the highest ratio of the peaks any run returning the same mesh
could reach, the dense peak over the warmed-up process plus the mesh's arrays
(:func:`memory_bound`). Both runs hash their mesh (vertices and faces bytes): the table says
whether they are the same mesh, bit for bit. Dense runs are skipped where the dense estimate
exceeds the available memory (``--dense-max`` caps the grid too). With ``--repeats N`` each
pair runs N times, in turns (sparse, dense, sparse, ...): the table gives the best time of
each and the median peak (the dense runs' times vary most here: the machine is shared, and
faulting in 2 GiB of pages is slow at times: a dense 512^3 run took 2.0 s on one day and
3.4-5.4 s on another, on the same Xeon).

Shapes: the paper's equations A, B, C (presets) and the first draws of each sampler family
(seed 5) that have a surface: ``sculpture-1``, ``sculpture-3``, ``lattice-0``, ``free-0``...
``ops/s`` is the program's length times the points evaluated per second of evaluation
(dense: the grid; sparse: the bricks' points), beside Fidget's published figures for its
Prospero benchmark (7866 clauses on 1024^2 points, brute force: 5.8 s bytecode, 0.182 s JIT;
M. Keeter's Fidget write-up): 1.4e9 and 4.5e10 clause-evaluations/s.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from typing import Any

from numba.core.registry import CPUDispatcher as Dispatcher

from benchmarks import harness
from surfgen.generator.allocator import one_shot_memory_policy
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.interval_poly import polynomial_structure
from surfgen.generator.formula.limits import MemoryBudget, available_memory, estimate_memory
from surfgen.generator.mesh.realise import realise
from surfgen.generator.model.presets import PRESETS
from surfgen.generator.model.sampler import SamplerConfig, choose_d, draw_equation
from surfgen.generator.model.spec import SurfaceSpec

FIDGET_OPS = {"fidget VM (brute force)": 7866 * 1024**2 / 5.8, "fidget JIT": 7866 * 1024**2 / 0.182}
WARM_UP_GRIDS = (64, 256)
DEFAULT_SHAPES = (
    "eqA,eqB,eqC,sculpture-1,sculpture-3,sculpture-5,lattice-0,infill-0,assembly-0,twist-0,free-0"
)


def spec_of(name: str):
    """The spec of a shape name: a preset, or ``family-index`` (a draw of seed 5)."""
    if name in PRESETS:
        return PRESETS[name].spec(), PRESETS[name].cap
    family, index = name.rsplit("-", 1)
    cfg = SamplerConfig(family=family)
    draw = draw_equation(5, int(index), cfg)
    d = choose_d(draw, cfg, threads=1)
    if d is None:
        raise SystemExit(f"{name}: the draw has no d")
    tree = draw.equation.with_d(d).to_tree()
    return SurfaceSpec.from_tree(tree, draw.box.bounds(), (64, 64, 64)), True


def vm_hwm() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def vm_rss() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    return 0


def reset_peak() -> None:
    """Start the process's VmHWM afresh at its current size (Linux's ``clear_refs`` 5), so the
    peak is the timed run's and not the warm-up's (whose compiles alone can take a few hundred
    MiB on an empty numba cache)."""
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")


def kernel_signatures() -> dict[str, int]:
    """The signatures each of surfgen's numba kernels has in this process: a kernel's first
    call with new argument types adds one, whether numba compiles it or loads it from its
    cache (both take time: a kernel first called inside the timed run is timed with it)."""
    modules = [m for name, m in list(sys.modules.items()) if name.startswith("surfgen.")]
    kernels = {v for m in modules for v in vars(m).values() if isinstance(v, Dispatcher)}
    return {f"{k.py_func.__module__}.{k.py_func.__name__}": len(k.overloads) for k in kernels}


def warm_up(spec: SurfaceSpec, cap: bool, evaluator: str, walls: str | None = None) -> None:
    """Compile (or load from numba's cache) every kernel the timed run calls: equation C,
    capped as the job is, on WARM_UP_GRIDS (a small mesh, and one large enough that the
    marching runs on every thread and its vertices are grouped plane by plane), then the job's
    own formula on 24^3.  A 24^3 warm-up alone left the large meshes' kernels to be loaded, or
    compiled, inside the timed run."""
    warm = PRESETS["eqC"].spec()
    for n in WARM_UP_GRIDS:
        realise(warm, grid=Grid(Box.from_bounds(warm.box), (n,) * 3), evaluator=evaluator,
                cap=cap, walls=walls, keep_samples=False)  # fmt: skip
    box = Box.from_bounds(spec.box)
    realise(spec, grid=Grid(box, (24,) * 3), evaluator=evaluator, cap=cap, walls=walls,
            allow_empty=True)  # fmt: skip


def child(job: dict[str, Any]) -> dict[str, Any]:
    """One run in this (fresh) process: warm up (:func:`warm_up`), then mesh on the job's grid.
    The spec comes as JSON (the parent drew it), as ``render --from`` reads a stored one: the
    process loads what meshing needs, not the sampler's kernels too.  ``compiled`` counts the
    kernels numba compiled inside the timed run (0 when the warm-up did its job)."""
    one_shot_memory_policy()  # the allocator's policy of `render` and `export`
    spec, cap = SurfaceSpec.from_json(job["spec"]), job["cap"]
    walls = job.get("walls")
    warm_up(spec, cap, job["evaluator"], walls)
    reset_peak()
    rss0 = vm_rss()
    n = job["grid"]
    before = kernel_signatures()
    grid = Grid(Box.from_bounds(spec.box), (n,) * 3)
    polynomial_structure.cache_clear()  # the formula's analysis counted, as in a fresh render
    t0 = time.perf_counter()
    budget = MemoryBudget.begin(None, f"{job['shape']} at {n}^3")  # as render refuses
    made = realise(spec, grid=grid, evaluator=job["evaluator"], cap=cap, walls=walls,
                   allow_empty=True, keep_samples=False, budget=budget)  # fmt: skip
    seconds = time.perf_counter() - t0
    after = kernel_signatures()
    first_called = sorted(k for k, count in after.items() if count > before.get(k, 0))
    mesh = made.mesh
    digest = hashlib.sha256()
    faces = mesh_bytes = 0
    if mesh is not None:
        digest.update(mesh.vertices.tobytes())
        digest.update(mesh.faces.tobytes())
        faces = mesh.n_faces
        mesh_bytes = mesh.vertices.nbytes + mesh.faces.nbytes
    ops = len(compile_tree(spec.tree(), dict(spec.params)).code)
    if made.sparse:
        points = made.field.points_evaluated
        eval_s = made.field.stats["sample_seconds"]
        share = made.field.share
        boxes = made.field.stats["boxes"]
    else:
        points, share, boxes = n**3, 1.0, 0
        eval_s = made.seconds["evaluate"]
    return {
        "seconds": seconds,
        "evaluate": made.seconds["evaluate"],
        "mesh_seconds": made.seconds["mesh"],
        "peak": vm_hwm(),
        "rss0": rss0,
        "points": points,
        "share": share,
        "boxes": boxes,
        "faces": faces,
        "mesh_bytes": mesh_bytes,
        "ops_per_s": ops * points / eval_s if eval_s > 0 else None,
        "hash": digest.hexdigest()[:16] if mesh is not None else None,
        "first_called": first_called,
    }


def _added(result: dict[str, Any]) -> float:
    """What the run added to its process's memory (its peak less the warmed-up process's
    resident size: the interpreter, numpy, numba and the compiled kernels are not the run's)."""
    return max(result["peak"] - result["rss0"], 1 << 20)


def memory_bound(dense: dict[str, Any], sparse: dict[str, Any]) -> float:
    """The highest peak-memory ratio any run that returns this mesh could reach against this
    dense run: the dense peak over the *floor*, the warmed-up process (``rss0``) plus the
    mesh's arrays, which the run returns and so holds at its end, whatever it did before."""
    return dense["peak"] / (sparse["rss0"] + sparse["mesh_bytes"])


def _combined(runs: list[dict[str, Any] | None]) -> dict[str, Any] | None:
    """One row of repeated runs: the fastest run's figures, with the runs' median peak (and
    warmed-up size); None if any run failed."""
    if not runs or any(r is None for r in runs):
        return None
    best = dict(min(runs, key=lambda r: r["seconds"]))
    best["peak"] = statistics.median_low([r["peak"] for r in runs])
    best["rss0"] = statistics.median_low([r["rss0"] for r in runs])
    best["runs"] = len(runs)
    return best


def run_job(job: dict[str, Any]) -> dict[str, Any] | None:
    cmd = [sys.executable, "-m", "benchmarks.bench_sparse", "--child", json.dumps(job)]
    out = subprocess.run(cmd, capture_output=True, text=True, cwd=harness.ROOT, check=False)
    if out.returncode != 0:
        said = {k: v for k, v in job.items() if k != "spec"}
        why = out.stderr.strip().splitlines()[-1:] or [f"exit code {out.returncode}"]
        print(f"  {said}: failed: {why[0][-2000:]}", flush=True)
        return None
    return json.loads(out.stdout.strip().splitlines()[-1])


def dense_fits(n: int, dense_max: int) -> bool:
    need = sum(estimate_memory(n**3, mesh=True).values())
    return n <= dense_max and need < 0.8 * available_memory()


def main(argv: list[str] | None = None) -> None:
    ap = harness.parser(__doc__, repeats=1)
    ap.add_argument("--grids", default="128,256,512,1024")
    ap.add_argument("--shapes", default=DEFAULT_SHAPES)
    ap.add_argument("--dense-max", type=int, default=1024, help="largest grid run densely")
    ap.add_argument("--walls", choices=["keep", "mark", "remove"],
                    help="classify the walls as render does (default: not classified)")  # fmt: skip
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(json.loads(args.child))))
        return
    run = harness.Run("bench_sparse", args)
    grids = [int(g) for g in args.grids.split(",")]
    shapes = args.shapes.split(",")
    rows = []
    if args.walls:
        run.say(f"walls: {args.walls} (every crossing classified, as render does)")
    run.say(
        "| shape | grid | dense s | sparse s | speed-up | dense peak MiB | sparse peak MiB "
        "| memory ratio | bound | added ratio | share | faces | same mesh | sparse ops/s |"
    )
    run.say("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for shape in shapes:
        spec, cap = spec_of(shape)
        job = {"shape": shape, "spec": spec.to_json(), "cap": cap, "walls": args.walls}
        for n in grids:
            sparses, denses = [], []
            for _ in range(max(1, args.repeats)):
                sparses.append(run_job({**job, "grid": n, "evaluator": "sparse"}))
                if dense_fits(n, args.dense_max):
                    denses.append(run_job({**job, "grid": n, "evaluator": "fast"}))
            sparse, dense = _combined(sparses), _combined(denses)
            if sparse is None:
                continue
            row = {"shape": shape, "grid": n, "sparse": sparse, "dense": dense}
            rows.append(row)
            mib = 1 << 20
            if dense is not None:
                speed = f"{dense['seconds'] / sparse['seconds']:.1f}x"
                memory = f"{dense['peak'] / sparse['peak']:.1f}x"
                bound = f"{memory_bound(dense, sparse):.1f}x"
                added = f"{_added(dense) / _added(sparse):.1f}x"
                same = "yes" if dense["hash"] == sparse["hash"] else "NO"
                d_s, d_m = f"{dense['seconds']:.2f}", f"{dense['peak'] / mib:.0f}"
            else:
                speed = memory = bound = added = same = d_s = d_m = "not run"
            ops = sparse["ops_per_s"]
            run.say(
                f"| {shape} | {n} | {d_s} | {sparse['seconds']:.2f} | {speed} | {d_m} | "
                f"{sparse['peak'] / mib:.0f} | {memory} | {bound} | {added} | {sparse['share']:.3f} | "
                f"{sparse['faces']} | {same} | {f'{ops:.2g}' if ops else '-'} |"
            )
    for r in rows:
        for kind in ("sparse", "dense"):
            if r[kind] and r[kind]["first_called"]:
                run.say(f"{r['shape']} {r['grid']}^3 {kind}: kernels first called (compiled or "
                        f"loaded) inside the timed run: {', '.join(r[kind]['first_called'])}")  # fmt: skip
    for label, value in FIDGET_OPS.items():
        run.say(f"{label}: {value:.2g} clause-evaluations/s (published)")
    sculptures = [r for r in rows if r["shape"].startswith("sculpture") and r["dense"]]
    for n in grids:
        ratios = [r["dense"]["seconds"] / r["sparse"]["seconds"] for r in sculptures
                  if r["grid"] == n]  # fmt: skip
        if ratios:
            run.say(f"median sculpture speed-up at {n}^3: {statistics.median(ratios):.1f}x")
            added = [_added(r["dense"]) / _added(r["sparse"]) for r in sculptures
                     if r["grid"] == n]  # fmt: skip
            peaks = [r["dense"]["peak"] / r["sparse"]["peak"] for r in sculptures
                     if r["grid"] == n]  # fmt: skip
            run.say(f"median sculpture peak-memory ratio at {n}^3: {statistics.median(peaks):.1f}x")
            bounds = [memory_bound(r["dense"], r["sparse"]) for r in sculptures
                      if r["grid"] == n]  # fmt: skip
            run.say(
                f"median sculpture bound on the peak-memory ratio at {n}^3 (dense peak over "
                f"the warmed-up process plus the mesh): {statistics.median(bounds):.1f}x"
            )
            run.say(
                f"median sculpture added-memory ratio at {n}^3: {statistics.median(added):.1f}x"
            )
    run.record(rows=rows, cpu=os.cpu_count())
    run.save()


if __name__ == "__main__":
    main()
