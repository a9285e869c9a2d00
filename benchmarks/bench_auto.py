"""Whether ``--evaluator auto`` picks the faster path: dense and sparse timed on the same shapes.

    python -m benchmarks.bench_auto [--grids 96,128,160,192,256] [--shapes eqA,eqB,...]
        [--draws 3] [--repeats 3]

Issue 41 asks the default evaluator of ``render``/``export`` to be the faster one. For each
shape and grid, ``realise`` (the render path: caps as the shape has them, the sparse samples
freed once meshed, the one-shot allocator policy) runs with ``--evaluator dense`` and
``--evaluator sparse``, in turns (``harness.take_turns``, best of ``--repeats``), in this
process after a warm-up on the shape; the table gives both times, their ratio (dense /
sparse: above 1, sparse is faster), the share of the grid's points the sparse path sampled,
what ``auto`` picks there (:func:`~surfgen.generator.mesh.realise.resolve_evaluator`) and the
time ``auto`` loses against the faster of the two (1.00x: none). Both paths make the same
mesh, bit for bit (``bench_sparse`` hashes them); this one is about time only.

Shapes: the paper's equations A, B, C, the first ``--draws`` draws of each sampler family
(seed 5) that have a surface, and ``poles``, a sphere pierced by poles on the planes
``x + y + z = k pi / 9``, which no interval bound can prune (every block holds a pole).
"""

from __future__ import annotations

import statistics
import sys

from benchmarks import harness
from benchmarks.bench_sparse import spec_of
from surfgen.generator.allocator import one_shot_memory_policy
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.mesh.realise import realise, resolve_evaluator
from surfgen.generator.model.sampler import family_names
from surfgen.generator.model.spec import SurfaceSpec

#: No interval can exclude the level from a block a pole plane crosses (``x + y + z`` is not a
#: value of one axis): the bounds leave every leaf to sample.
POLES = SurfaceSpec("x^2+y^2+z^2-0.8+0.01/sin(9*(x+y+z))", (-1.0, 1.0) * 3, (64, 64, 64))


def shapes(names: str | None, draws: int) -> list[str]:
    """The shapes' names: ``names`` (comma-separated) or the default set."""
    if names:
        return names.split(",")
    return [
        "eqA",
        "eqB",
        "eqC",
        "poles",
        *(f"{f}-{i}" for f in family_names() for i in range(draws)),
    ]


def shape_spec(name: str) -> tuple[SurfaceSpec, bool] | None:
    """A shape's spec and whether it is capped; None for a draw with no surface."""
    if name == "poles":
        return POLES, True
    try:
        return spec_of(name)
    except SystemExit:  # a draw with no d: no surface to time
        return None


def measure(spec: SurfaceSpec, cap: bool, n: int, repeats: int) -> dict:
    """Both paths on ``n``^3 points of ``spec``'s box: best times, share, what auto picks."""
    grid = Grid(Box.from_bounds(spec.box), (n,) * 3)
    shares = []

    def run(evaluator: str):
        def go():
            made = realise(spec, grid=grid, evaluator=evaluator, cap=cap, allow_empty=True,
                           keep_samples=False)  # fmt: skip
            if made.sparse:
                shares.append(made.field.share)
            return None if made.mesh is None else made.mesh.n_faces

        return go

    timings = harness.take_turns({"dense": run("fast"), "sparse": run("sparse")}, repeats)
    dense, sparse = timings["dense"].best, timings["sparse"].best
    picked = "sparse" if resolve_evaluator("auto", grid) == "sparse" else "dense"
    faster = min(dense, sparse)
    return {
        "grid": n,
        "dense": dense,
        "sparse": sparse,
        "ratio": dense / sparse,
        "share": shares[-1],
        "faces": timings["sparse"].result or 0,
        "auto": picked,
        "loss": (sparse if picked == "sparse" else dense) / faster,
    }


def main(argv: list[str] | None = None) -> None:
    ap = harness.parser(__doc__, repeats=3)
    ap.add_argument("--grids", default="96,128,160,192,256")
    ap.add_argument("--shapes", help="comma-separated (default: presets, poles, family draws)")
    ap.add_argument("--draws", type=int, default=3, help="draws of each family (default 3)")
    args = ap.parse_args(argv)
    if args.repeats < 1:
        sys.exit("error: --repeats must be at least 1")
    run = harness.Run("bench_auto", args)
    one_shot_memory_policy()  # render's and export's
    grids = [int(g) for g in args.grids.split(",")]
    run.say("| shape | grid | dense s | sparse s | dense / sparse | share | faces | auto | "
            "auto's loss |")  # fmt: skip
    run.say("|---|---|---|---|---|---|---|---|---|")
    rows = []
    for name in shapes(args.shapes, args.draws):
        made = shape_spec(name)
        if made is None:
            continue
        spec, cap = made
        warm = Grid(Box.from_bounds(spec.box), (24,) * 3)
        for evaluator in ("fast", "sparse"):  # compile or load the shape's kernels untimed
            realise(spec, grid=warm, evaluator=evaluator, cap=cap, allow_empty=True)
        for n in grids:
            row = {"shape": name, **measure(spec, cap, n, args.repeats)}
            rows.append(row)
            run.say(f"| {name} | {n} | {row['dense']:.3f} | {row['sparse']:.3f} | "
                    f"{row['ratio']:.2f}x | {row['share']:.3f} | {row['faces']} | {row['auto']} | "
                    f"{row['loss']:.2f}x |")  # fmt: skip
    run.say()
    summary = {}
    for n in grids:
        here = [r for r in rows if r["grid"] == n]
        if not here:
            continue
        right = sum(r["loss"] == 1.0 for r in here)
        sparse_faster = sum(r["ratio"] > 1 for r in here)
        ratios = [r["ratio"] for r in here]
        summary[n] = {"shapes": len(here), "auto_faster": right, "sparse_faster": sparse_faster,
                      "median_ratio": statistics.median(ratios),
                      "worst_loss": max(r["loss"] for r in here)}  # fmt: skip
        run.say(f"{n}^3: sparse faster for {sparse_faster} of {len(here)} shapes (median dense / "
                f"sparse {statistics.median(ratios):.2f}x); auto picks the faster for {right}, "
                f"at worst {summary[n]['worst_loss']:.2f}x the faster's time")  # fmt: skip
    run.record(rows=rows, summary=summary)
    run.save()


if __name__ == "__main__":
    main()
