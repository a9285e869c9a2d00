"""Benchmark: cleanup + isotropic remesh of a ~200k-face marching-cubes mesh (target < 5 s).

The mesh is a capped gyroid made the way the catalogue makes shapes (evaluate, then
``extract_mesh(cap=True)``).  Times are the best of ``--repeats`` runs of

- ``repair_mesh``: merge, duplicate/degenerate faces, non-manifold repairs, small components,
  holes, orientation;
- ``refine_mesh``: isotropic remeshing to the edge length that keeps the face count;

and, measured in the same run as baselines, the marching-cubes extraction of the same field and
trimesh's own processing of the same mesh (``process=True, validate=True`` plus its
watertightness check).  Shared machines are noisy: the ratios are more reliable than the times.

    python -m benchmarks.cleanup_remesh [--grid 102] [--repeats 3] [--iterations 1] [--json PATH]
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import trimesh

from benchmarks import harness
from surfgen.filters.cleanup import CleanupOptions, edge_lengths, refine_mesh, repair_mesh
from surfgen.filters.metrics import measure_mesh
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Field, Grid
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import Mesh, extract_mesh

GYROID = "sin(x)*cos(y)+sin(y)*cos(z)+sin(z)*cos(x)"
TARGET_SECONDS = 5.0


def timed(fn: Callable[[], object], repeat: int) -> tuple[float, float, object]:
    """Best and median wall-clock seconds of ``repeat`` calls, and the last result."""
    timing = harness.best_of(fn, repeat, warmup=0)
    return timing.best, timing.median, timing.result


def slivers(mesh: Mesh, degrees: float = 10.0) -> float:
    """Percentage of triangles with an angle below ``degrees``."""
    v, f = mesh.vertices, mesh.faces
    smallest = np.full(len(f), 180.0)
    for i in range(3):
        p, q, r = v[f[:, i]], v[f[:, (i + 1) % 3]], v[f[:, (i + 2) % 3]]
        u, w = q - p, r - p
        cos = (u * w).sum(1) / (np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1) + 1e-300)
        smallest = np.minimum(smallest, np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    return 100.0 * float(np.mean(smallest < degrees))


def trimesh_process(mesh: Mesh) -> bool:
    tm = trimesh.Trimesh(np.array(mesh.vertices), np.array(mesh.faces), process=True, validate=True)
    return bool(tm.is_watertight)


def main(argv: list[str] | None = None) -> None:
    parser = harness.parser(__doc__, repeats=3)
    parser.add_argument("--grid", type=int, default=102, help="points per axis (102: ~197k faces)")
    parser.add_argument("--half", type=float, default=4.0, help="box is [-half, half]^3")
    parser.add_argument("--iterations", type=int, default=1, help="remeshing iterations")
    args = parser.parse_args(argv)
    run = harness.Run("cleanup_remesh", args)

    field: Field = evaluate(parse(GYROID), Grid(Box.cube(args.half), (args.grid,) * 3))
    mc_best, mc_med, mesh = timed(lambda: extract_mesh(field, 0.0, cap=True), args.repeats)
    assert isinstance(mesh, Mesh)
    run.say(
        f"mesh: capped gyroid {args.grid}³, {mesh.n_faces:,} faces, {mesh.n_vertices:,} vertices"
    )

    options = CleanupOptions(remesh=True, remesh_iterations=args.iterations)
    rep_best, rep_med, repaired = timed(lambda: repair_mesh(mesh, options), args.repeats)
    ref_best, ref_med, refined = timed(lambda: refine_mesh(repaired.mesh, options), args.repeats)
    tm_best, tm_med, _ = timed(lambda: trimesh_process(mesh), args.repeats)

    out = refined.mesh
    m = measure_mesh(out)
    target = refined.steps[0].details["target_edge"]
    edges = edge_lengths(out) / target
    total = rep_best + ref_best
    run.say(f"cleanup (repair_mesh)             : {rep_best:.2f} s (median {rep_med:.2f})")
    run.say(
        f"remesh ({args.iterations} iterations, edge {target:.4f}): {ref_best:.2f} s "
        f"(median {ref_med:.2f}) -> {out.n_faces:,} faces, edge/target median "
        f"{np.median(edges):.2f}, p10 {np.percentile(edges, 10):.2f}, p90 {np.percentile(edges, 90):.2f}"
    )
    run.say(
        f"result: watertight {m.watertight}, non-manifold vertices {m.nonmanifold_vertices}, "
        f"genus {m.genus}, components {m.components}; triangles with an angle < 10°: "
        f"{slivers(mesh):.1f}% -> {slivers(out):.2f}%"
    )
    run.say(f"cleanup + remesh                  : {total:.2f} s (target < {TARGET_SECONDS:g} s)")
    run.say(f"baseline marching cubes (skimage) : {mc_best:.2f} s (median {mc_med:.2f})")
    run.say(f"baseline trimesh process+validate : {tm_best:.2f} s (median {tm_med:.2f})")
    run.say(
        f"ratio: cleanup + remesh = {total / mc_best:.1f}x marching cubes, "
        f"{total / tm_best:.1f}x trimesh processing; cleanup alone = "
        f"{rep_best / tm_best:.1f}x trimesh processing"
    )
    run.record(
        faces=mesh.n_faces,
        seconds={"repair": rep_best, "remesh": ref_best, "marching_cubes": mc_best},
        trimesh_seconds=tm_best,
        remeshed_faces=out.n_faces,
        watertight=m.watertight,
    )
    run.save()


if __name__ == "__main__":
    main()
