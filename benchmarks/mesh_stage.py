"""Benchmark: the mesh stage (``extract_with_edges``) now against the numpy version before it.

The fields are the sampler's own: the first ``--draws`` draws of ``--seed`` go through
``make_shape`` (default config, no pictures) and every field it meshes is kept (at the config's
grid, 64³, capped as the sampler does).  On each, in the same run, best of ``--repeats``:

- ``old``: the step-by-step numpy version (``tests/support/mesh_reference.py``: offsets,
  separation, pad, marching cubes on every cell, placement, merge);
- ``new``: :func:`surfgen.generator.mesh.mesh.extract_with_edges` (numba kernels, marching
  cubes by the numba port of skimage's Lewiner on the cells with both signs only);
- ``mc``/``mc mask``: scikit-image's marching cubes alone on the same input, all cells and
  masked.

Checks that both give bit-identical vertices, faces and edges, and prints totals, the median
per-field ratio old/new and the split of the new stage.  Shared machines are noisy: ratios
measured in one run are what to quote.

    python -m benchmarks.mesh_stage [--draws 100] [--seed 7] [--repeats 3] [--json PATH]
"""

from __future__ import annotations

import statistics
import tempfile
from pathlib import Path

import numpy as np
from skimage.measure import marching_cubes

import surfgen.generator.mesh.marching as marching
import surfgen.generator.mesh.mesh as mesh_module
import surfgen.pipelines.run.shapes as shapes
from benchmarks import harness
from surfgen.generator.errors import EmptySurface
from surfgen.pipelines.run.config import load_config
from tests.support.mesh_reference import reference_extract_with_edges, skimage_mask


def sampler_fields(draws: int, seed: int) -> list[tuple]:
    """(field, level, cap) of every mesh the sampler makes in its first ``draws`` draws."""
    config = load_config(None)
    kept = []
    inner = shapes.extract_with_edges

    def recording(field, level, cap=False):
        kept.append((field, level, cap))
        return inner(field, level, cap=cap)

    shapes.extract_with_edges = recording
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for index in range(draws):
                shapes.make_shape(
                    index, seed=seed, config=config, staging=Path(tmp), pictures=False
                )
    finally:
        shapes.extract_with_edges = inner
    return kept


def best(repeat: int, fn, *args, **kwargs) -> float:
    """Least wall time of ``fn(*args, **kwargs)`` over ``repeat`` calls."""
    return harness.best_of(lambda: fn(*args, **kwargs), repeat, warmup=0).best


def same(a, b) -> bool:
    return (
        a[0].vertices.tobytes() == b[0].vertices.tobytes()
        and np.array_equal(a[0].faces, b[0].faces)
        and np.array_equal(a[1], b[1])
    )


def main(argv: list[str] | None = None) -> None:
    parser = harness.parser(__doc__, repeats=3)
    parser.add_argument("--draws", type=int, default=100)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args(argv)
    run = harness.Run("mesh_stage", args)
    fields = sampler_fields(args.draws, args.seed)
    rows, identical, meshed = [], 0, 0
    for field, level, cap in fields:
        try:
            old = reference_extract_with_edges(field, level, cap)
        except EmptySurface:
            continue
        meshed += 1
        identical += same(old, mesh_module.extract_with_edges(field, level, cap))
        values = np.ascontiguousarray(field.values, dtype=np.float64)
        work = marching._offsets(values, level, pad=cap)[0]
        mask = skimage_mask(work)
        r = args.repeats
        t_old = best(r, reference_extract_with_edges, field, level, cap)
        t_new = best(r, mesh_module.extract_with_edges, field, level, cap)
        t_mc = best(r, marching_cubes, work, 0.0, gradient_direction="descent")
        t_mask = best(r, marching_cubes, work, 0.0, gradient_direction="descent", mask=mask)
        rows.append((t_old, t_new, t_mc, t_mask, old[0].n_faces))
    a = np.array(rows)
    run.say(f"{len(fields)} fields meshed by the sampler in {args.draws} draws of seed {args.seed}")
    run.say(f"bit-identical vertices, faces and edges: {identical} of {meshed}")
    run.say(
        f"best of {args.repeats}, ms per field (mean): old {1000 * a[:, 0].mean():.1f}, "
        f"new {1000 * a[:, 1].mean():.1f}; faces {a[:, 4].mean():.0f}"
    )
    ratio = a[:, 0] / a[:, 1]
    run.say(
        f"old / new: total {a[:, 0].sum() / a[:, 1].sum():.2f}, median per field "
        f"{statistics.median(ratio):.2f} (p10 {np.percentile(ratio, 10):.2f}, "
        f"p90 {np.percentile(ratio, 90):.2f})"
    )
    run.say(
        f"skimage's marching cubes alone (ms, mean): every cell {1000 * a[:, 2].mean():.1f}, "
        f"mixed cells only {1000 * a[:, 3].mean():.1f} "
        f"(x{a[:, 2].sum() / a[:, 3].sum():.2f}); the old stage is "
        f"{a[:, 2].sum() / a[:, 0].sum():.0%} marching cubes; the whole new stage takes "
        f"{a[:, 1].sum() / a[:, 3].sum():.2f}x the time of skimage's masked marching cubes alone"
    )
    run.record(
        identical=identical,
        meshed=meshed,
        seconds={"old": a[:, 0], "new": a[:, 1], "mc": a[:, 2], "mc_mask": a[:, 3]},
        faces=a[:, 4],
    )
    run.save()


if __name__ == "__main__":
    main()
