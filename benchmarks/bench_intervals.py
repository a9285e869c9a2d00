"""Interval bounds over boxes (``intervals.program_bounds``) against the point evaluator on as
many points, measured in one run.

    python -m benchmarks.bench_intervals [--boxes 4096] [--formulas 10] [--repeats 5] [--json PATH]

For each of the first ``--formulas`` stored eq. (13) formulas (tests/support/data), K random
boxes inside the formula's box and K random points: the numba interval interpreter bounds F
over the boxes, the points kernel (``PointsEvaluator.plain``, every level at every point as the
box interpreter does) evaluates F at the points; both timed in turns, best of ``--repeats``.
Prints box evaluations per second, tape operations per second (boxes x code rows / time) and
the ratio of the box time to the point time (how many point evaluations one box costs).
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
    ap.add_argument("--boxes", type=int, default=4096, help="boxes (and points) per formula")
    ap.add_argument("--formulas", type=int, default=10, help="stored formulas to run")
    args = ap.parse_args(argv)
    run = harness.Run("bench_intervals", args)
    rows = [json.loads(line) for line in FORMULAS.read_text().splitlines() if line.strip()]
    rng = np.random.default_rng(5)
    ratios, box_rates, op_rates = [], [], []
    for i, row in enumerate(rows[: args.formulas]):
        program = compile_tree(parse(row["formula"]))
        lo, hi = np.array(row["lo"]), np.array(row["hi"])
        c = rng.uniform(lo, hi, (args.boxes, 3))
        w = (hi - lo) / 32 * rng.uniform(0.5, 1.0, (args.boxes, 3))
        blo, bhi = c - w, c + w
        pts = [np.ascontiguousarray(c[:, a]) for a in range(3)]
        points = PointsEvaluator(program)
        timings = harness.take_turns(
            {
                "points": lambda points=points, pts=pts: points.plain(*pts),
                "boxes": lambda p=program, a=blo, b=bhi: program_bounds(p, a, b),
            },
            args.repeats,
        )
        t_box, t_pt = timings["boxes"].best, timings["points"].best
        ops = len(program.code)
        ratio = t_box / t_pt
        ratios.append(ratio)
        box_rates.append(args.boxes / t_box)
        op_rates.append(args.boxes * ops / t_box)
        run.record(**{f"formula {i}": {"ops": ops, "box_seconds": t_box, "point_seconds": t_pt}})
        run.say(
            f"formula {i:2d} ({ops:3d} ops): {args.boxes / t_box / 1e3:8.1f} k boxes/s, "
            f"{args.boxes * ops / t_box / 1e6:7.2f} M box-ops/s; points "
            f"{args.boxes / t_pt / 1e3:8.1f} k/s, {args.boxes * ops / t_pt / 1e6:7.2f} M ops/s: "
            f"a box costs {ratio:5.1f} points"
        )
    run.say(
        f"median: {np.median(box_rates) / 1e3:.1f} k boxes/s, {np.median(op_rates) / 1e6:.2f} M "
        f"box-ops/s, a box costs {np.median(ratios):.1f} point evaluations"
    )
    run.record(
        median_ratio=float(np.median(ratios)), median_boxes_per_s=float(np.median(box_rates))
    )
    run.save()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
