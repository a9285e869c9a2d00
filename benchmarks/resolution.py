"""Benchmark: the resolution check's cost per shape, by stage, and the fine field's paths.

For the shapes of a catalogue (``--catalogue DIR``: its first ``--n`` shapes that were
measured) the check is timed stage by stage on the same coarse field: the fine field filled on
the whole fine grid with the band evaluated at its points (``band points``) or through the whole
fine grid (``band via grid``: the grid evaluator hoists what depends on x, y or z alone), the
dense reference (``dense``), its mesh (``fine mesh``); the sampler's sparse path, the band's
leaves built and meshed (``sparse band+mesh``, :mod:`surfgen.filters.fine_band`); and the
comparison. In turns, so load changes hit every path alike. Prints per stage the median and
total, the ratio points / grid that sets ``POINT_COST`` in :mod:`surfgen.filters.resolution`,
the ratio of the filled field and its mesh over the sparse path (the same mesh, checked), and
the check's share of the shapes' other stages (the catalogue's stored timings).

    python -m benchmarks.resolution --catalogue out/catalogue [--n 40] [--repeats 2]
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import numpy as np

from benchmarks import harness
from surfgen.filters import resolution as res
from surfgen.filters.fine_band import band_cells, fine_band
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.mesh.mesh import extract_mesh
from surfgen.generator.mesh.sparse_marching import extract_sparse
from surfgen.generator.model.spec import SurfaceSpec


def main(argv: list[str] | None = None) -> None:
    p = harness.parser(__doc__, repeats=2)
    p.add_argument("--catalogue", type=Path, required=True)
    p.add_argument("--n", type=int, default=40)
    args = p.parse_args(argv)
    run = harness.Run("resolution", args)
    conn = sqlite3.connect(args.catalogue / "catalogue.sqlite")
    rows = conn.execute(
        "SELECT spec, timings FROM shapes WHERE metrics LIKE '%resolution_points%' "
        "ORDER BY idx LIMIT ?",
        (args.n,),
    ).fetchall()
    times: dict[str, list[float]] = {}
    others = []
    for spec_text, timings in rows:
        spec = SurfaceSpec.from_json(spec_text)
        tree = spec.tree()
        coarse = evaluate(tree, spec.to_grid(), spec.params, threads=1)
        mesh = extract_mesh(coarse, spec.level, cap=True)
        level = spec.level

        def band(via_grid: bool, tree=tree, coarse=coarse, level=level):
            return res.fine_field(tree, coarse, level, via_grid=via_grid)[0]

        turns = harness.take_turns(
            {
                "band points": lambda band=band: band(False),
                "band via grid": lambda band=band: band(True),
                "dense": lambda tree=tree, coarse=coarse, level=level: res.fine_field(
                    tree, coarse, level, method="dense"
                ),
            },
            args.repeats,
        )
        fine = turns["band points"].result
        mesh_t = harness.best_of(
            lambda fine=fine, level=level: extract_mesh(fine, level, cap=True), args.repeats
        )
        compare_t = harness.best_of(
            lambda mesh=mesh, other=mesh_t.result, grid=coarse.grid: res.compare_meshes(
                mesh, other, grid
            ),
            args.repeats,
        )

        def sparse(tree=tree, coarse=coarse, level=level):
            sf = fine_band(tree, coarse, band_cells(coarse, level), level, faces=True)[0]
            return extract_sparse(sf, cap=True)

        sparse_t = harness.best_of(sparse, args.repeats)
        want = mesh_t.result
        got = sparse_t.result
        if (got.vertices.tobytes(), got.faces.tobytes()) != (
            want.vertices.tobytes(),
            want.faces.tobytes(),
        ):
            raise SystemExit(f"{spec.key}: the sparse path's mesh differs from the dense one")
        stages = (*turns.items(), ("fine mesh", mesh_t), ("sparse band+mesh", sparse_t))
        for name, timing in (*stages, ("compare", compare_t)):
            times.setdefault(name, []).append(timing.best)
        stored = json.loads(timings or "{}")
        others.append(sum(v for k, v in stored.items() if k != "resolution"))
    if not rows:
        run.say("no measured shapes in that catalogue")
        return
    run.say(f"{len(rows)} shapes of {args.catalogue}")
    for name, values in times.items():
        run.say(f"  {name:<14} median {np.median(values):.3f} s  total {np.sum(values):.2f} s")
    ratios = np.array(times["band points"]) / np.array(times["band via grid"])
    run.say(
        f"band at its points / via the grid: median {np.median(ratios):.2f} "
        f"(quartiles {np.percentile(ratios, 25):.2f}-{np.percentile(ratios, 75):.2f})"
    )
    filled = np.minimum(times["band points"], times["band via grid"]) + np.array(times["fine mesh"])
    ratio = filled / np.array(times["sparse band+mesh"])
    run.say(
        f"the filled fine field and its mesh / the sparse path: median {np.median(ratio):.2f}x "
        f"(quartiles {np.percentile(ratio, 25):.2f}-{np.percentile(ratio, 75):.2f}), the same meshes"
    )
    check = np.array(times["sparse band+mesh"]) + np.array(times["compare"])
    run.say(
        f"the check (sparse band and mesh + compare): median {np.median(check):.3f} s; "
        f"the shapes' other stages (stored): median {np.median(others):.3f} s"
    )
    run.record(**{k.replace(" ", "_"): v for k, v in times.items()}, others=others)
    run.save()


if __name__ == "__main__":
    main()
