"""Interval bounds over boxes (``intervals.program_bounds``) against the point evaluator on as
many points, measured in one run.

    python -m benchmarks.bench_intervals [--grid 16] [--formulas 10] [--repeats 5] [--json PATH]

For each of the first ``--formulas`` stored eq. (13) formulas (tests/support/data), K = n^3
boxes (``--grid n``) two ways, the cells of an n^3 grid over the formula's box (what a sparse
evaluator asks for: the boxes share their x, y, z ranges, so each level is bounded once per
distinct range) and K random boxes (nothing shared), and K random points: the numba interval
interpreter bounds F over the boxes, the points kernel (``PointsEvaluator.plain``, every level
at every point) evaluates F at the points; all timed in turns, best of ``--repeats``. Prints
box evaluations per second, tape operations per second (boxes x code rows / time) and the
ratio of the box time to the point time (how many point evaluations one box costs).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from benchmarks import harness
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.intervals import program_bounds
from surfgen.generator.eval.tape import PointsEvaluator
from surfgen.generator.formula.parser import parse

FORMULAS = (
    Path(__file__).resolve().parents[1] / "tests" / "support" / "data" / "eq13_formulas.jsonl"
)


def main(argv: list[str] | None = None) -> int:
    ap = harness.parser(__doc__, repeats=5)
    ap.add_argument("--grid", type=int, default=16, help="n: n^3 boxes (and points) per formula")
    ap.add_argument("--formulas", type=int, default=10, help="stored formulas to run")
    args = ap.parse_args(argv)
    run = harness.Run("bench_intervals", args)
    rows = [json.loads(line) for line in FORMULAS.read_text().splitlines() if line.strip()]
    rng = np.random.default_rng(5)
    K = args.grid**3
    costs: dict[str, list[float]] = {"grid": [], "random": []}
    rates: dict[str, list[float]] = {"grid": [], "random": []}
    for i, row in enumerate(rows[: args.formulas]):
        program = compile_tree(parse(row["formula"]))
        lo, hi = np.array(row["lo"]), np.array(row["hi"])
        edges = [np.linspace(lo[a], hi[a], args.grid + 1) for a in range(3)]
        cell = np.stack(np.meshgrid(*[np.arange(args.grid)] * 3, indexing="ij"), -1).reshape(-1, 3)
        glo = np.stack([edges[a][cell[:, a]] for a in range(3)], axis=1)
        ghi = np.stack([edges[a][cell[:, a] + 1] for a in range(3)], axis=1)
        c = rng.uniform(lo, hi, (K, 3))
        w = (hi - lo) / (2 * args.grid) * rng.uniform(0.5, 1.0, (K, 3))
        pts = [np.ascontiguousarray(c[:, a]) for a in range(3)]
        points = PointsEvaluator(program)
        timings = harness.take_turns(
            {
                "points": lambda points=points, pts=pts: points.plain(*pts),
                "grid": lambda p=program, a=glo, b=ghi: program_bounds(p, a, b),
                "random": lambda p=program, a=c - w, b=c + w: program_bounds(p, a, b),
            },
            args.repeats,
        )
        t_pt = timings["points"].best
        ops = len(program.code)
        line = []
        for kind in ("grid", "random"):
            t = timings[kind].best
            costs[kind].append(t / t_pt)
            rates[kind].append(K / t)
            line.append(f"{kind} {K / t / 1e3:7.0f} k boxes/s ({K * ops / t / 1e6:6.1f} M ops/s, "
                        f"{t / t_pt:5.2f} points)")  # fmt: skip
        run.record(**{f"formula {i}": {"ops": ops, "point_seconds": t_pt,
                                       **{k: timings[k].best for k in ("grid", "random")}}})  # fmt: skip
        run.say(
            f"formula {i:2d} ({ops:3d} ops): points {K / t_pt / 1e3:6.0f} k/s; " + "; ".join(line)
        )
    for kind in ("grid", "random"):
        run.say(
            f"median, {kind} boxes: {np.median(rates[kind]) / 1e3:.0f} k boxes/s, "
            f"a box costs {np.median(costs[kind]):.2f} point evaluations"
        )
        run.record(**{f"median_cost_{kind}": float(np.median(costs[kind]))})
    run.save()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
