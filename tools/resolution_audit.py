"""How many accepted shapes of a catalogue are not resolved by their grid? (issue 40's measure)

    python -m tools.resolution_audit CATALOGUE [--sample 120] [--seed 0] [--csv out.csv]

For a random sample of the accepted shapes (a fixed seed), the shape is rendered again on the
nested grid of ``2N - 1`` points per axis with the box caps (what ``surfgen render --from CAT KEY
--grid 127 --cap`` does for a 64-point shape: every coarse sample is a fine one), by the dense
path (:func:`surfgen.generator.mesh.realise.realise`: every fine point evaluated, nothing of the
sampler's band evaluation), and compared with the catalogue's stored mesh file:

- ``p95 to fine`` / ``p95 to coarse``: the 95th percentile of the distance from points drawn on
  one mesh (area-uniform) to the nearest vertex or face centre of the other, in coarse cells
  (a k-d tree; a resolved surface gives 0.15-0.5 here, the nearest-point error included; on a
  stretched box, whose cells are longer along an axis, in cells of each axis);
- ``area``: fine area / stored area.

A shape *moved* when either percentile exceeds ``--max-shift`` cells (default 1.0) or its area
changed by more than ``--max-area`` (default 0.13): the measure of issue 40, where resolved
shapes moved 0.15-0.95 cells with their area within 13 % and unresolved ones 0.7-12.5 cells
and +8-131 %. It prints one line per shape, the share that moved (overall and per family) and,
where the catalogue stores them, the sampler's own ``resolution_*`` figures beside the audit's.
A fine grid of odd size samples the planes x, y, z = 0, where many formulas have a pole (``1/x``,
``|x|^-p``) that the even coarse grid never sees: a plane of non-finite samples, outside by
convention, cuts a slit through the fine surface. Such shapes are measured a second time with
those new non-finite samples given their coarse neighbours' mean (as the sampler's check does),
and the summary gives both shares.
Independent of the sampler's check: another mesher path, other distances, the stored files.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from collections import Counter
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from surfgen.filters.resolution import fine_field
from surfgen.generator.errors import SurfgenError
from surfgen.generator.eval.grid import Field, Grid
from surfgen.generator.mesh.exchange import load_mesh
from surfgen.generator.mesh.mesh import Mesh, extract_mesh, face_areas
from surfgen.generator.mesh.realise import realise
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.store import open_catalogue

POINTS = 20000  # points drawn per mesh
POINT_SEED = 40


def _points(mesh: Mesh, n: int = POINTS) -> np.ndarray:
    areas = face_areas(mesh)
    rng = np.random.default_rng(POINT_SEED)
    faces = np.minimum(
        np.searchsorted(np.cumsum(areas), rng.random(n) * areas.sum(), side="right"),
        mesh.n_faces - 1,
    )
    r1, r2 = rng.random((2, n))
    s = np.sqrt(r1)[:, None]
    v, f = mesh.vertices, mesh.faces[faces]
    return (1 - s) * v[f[:, 0]] + s * (1 - r2[:, None]) * v[f[:, 1]] + s * r2[:, None] * v[f[:, 2]]


def _tree(mesh: Mesh) -> cKDTree:
    v, f = mesh.vertices, mesh.faces
    return cKDTree(np.concatenate([v, v[f].mean(axis=1)]))


def _compare(stored: Mesh, fine: Mesh, cell: np.ndarray) -> tuple[float, float, float]:
    """Distances in cells of each axis (``cell``: the coarse spacing per axis; a stretched
    shape's box has longer cells along its stretched axis), the area ratio in world units."""
    a, b = Mesh(stored.vertices / cell, stored.faces), Mesh(fine.vertices / cell, fine.faces)
    to_fine = float(np.percentile(_tree(b).query(_points(a))[0], 95))
    to_coarse = float(np.percentile(_tree(a).query(_points(b))[0], 95))
    return to_fine, to_coarse, float(face_areas(fine).sum() / face_areas(stored).sum())


def audit_shape(root: Path, row: dict, cap: bool) -> dict:
    """The audit's figures for one catalogue row (module doc)."""
    spec = SurfaceSpec.from_json(row["spec"])
    stored = load_mesh(root / row["mesh_path"])
    coarse = spec.to_grid()
    fine_grid = Grid(coarse.box, tuple(2 * n - 1 for n in coarse.shape))
    realised = realise(spec, grid=fine_grid, cap=cap, threads=1)
    cell = np.array(coarse.spacing, dtype=np.float64)
    to_fine, to_coarse, area = _compare(stored, realised.mesh, cell)
    # The same with the fine field's new non-finite samples between finite coarse ones given
    # their mean, as the sampler's check does: poles on the planes x, y, z = 0, which only an
    # odd grid samples, cut slits that say nothing of the zero set's resolution.
    coarse_values = realised.field.values[::2, ::2, ::2]
    singular = int(np.count_nonzero(~np.isfinite(realised.field.values))) - int(
        np.count_nonzero(~np.isfinite(coarse_values))
    )
    patched = (to_fine, to_coarse, area)
    if singular:
        tree = spec.tree()
        coarse_field = Field(coarse, np.ascontiguousarray(coarse_values))
        field, _, _ = fine_field(tree, coarse_field, spec.level, spec.params, method="dense")
        patched = _compare(stored, extract_mesh(field, spec.level, cap=cap), cell)
    metrics = json.loads(row["metrics"] or "{}")
    return {
        "key": row["key"],
        "family": json.loads(row["model"] or "{}").get("family", "free"),
        "p95_to_fine": to_fine,
        "p95_to_coarse": to_coarse,
        "area": area,
        "new_nonfinite": singular,
        "patched_shift": max(patched[0], patched[1]),
        "patched_area": patched[2],
        "sampler_shift": metrics.get("resolution_shift"),
        "sampler_area": metrics.get("resolution_area"),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("catalogue", type=Path)
    parser.add_argument("--sample", type=int, default=120, help="shapes audited (default 120)")
    parser.add_argument("--seed", type=int, default=0, help="which shapes (default 0)")
    parser.add_argument("--max-shift", type=float, default=1.0, help="cells (default 1.0)")
    parser.add_argument("--max-area", type=float, default=0.13, help="|area change| (0.13)")
    parser.add_argument("--no-cap", action="store_true", help="compare uncapped meshes")
    parser.add_argument("--csv", type=Path, help="write the per-shape figures here")
    args = parser.parse_args(argv)
    try:
        with open_catalogue(args.catalogue, readonly=True) as cat:
            rows = [dict(r) for r in cat.shapes(verdict="accepted") if r["mesh_path"]]
    except SurfgenError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    rows.sort(key=lambda r: r["key"])
    rng = np.random.default_rng(args.seed)
    chosen = [rows[i] for i in sorted(rng.permutation(len(rows))[: args.sample])]
    results = []
    for i, row in enumerate(chosen, 1):
        r = audit_shape(args.catalogue, row, cap=not args.no_cap)
        r["moved"] = (
            max(r["p95_to_fine"], r["p95_to_coarse"]) > args.max_shift
            or abs(r["area"] - 1.0) > args.max_area
        )
        r["moved_patched"] = (
            r["patched_shift"] > args.max_shift or abs(r["patched_area"] - 1.0) > args.max_area
        )
        results.append(r)
        sampler = (
            f"  sampler shift {r['sampler_shift']:.2f} area {r['sampler_area']:.3f}"
            if r["sampler_shift"] is not None
            else ""
        )
        print(
            f"{i:4d} {r['key'][:12]} {r['family']:<9} p95 to fine {r['p95_to_fine']:6.2f}"
            f"  to coarse {r['p95_to_coarse']:6.2f}  area {r['area']:6.3f}"
            f"  {'MOVED' if r['moved'] else 'ok':<5}"
            + (
                f" (new non-finite samples {r['new_nonfinite']}: without them "
                f"{r['patched_shift']:.2f} cells, area {r['patched_area']:.3f}"
                f"{', moved' if r['moved_patched'] else ''})"
                if r["new_nonfinite"]
                else ""
            )
            + sampler,
            flush=True,
        )
    if not results:
        print("no accepted shapes with a mesh file")
        return 1
    _summary(results, args)
    if args.csv:
        with args.csv.open("w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(results[0]))
            writer.writeheader()
            writer.writerows(results)
    return 0


def _summary(results: list[dict], args: argparse.Namespace) -> None:
    moved = [r for r in results if r["moved"]]
    print(
        f"\n{len(moved)} of {len(results)} moved ({100 * len(moved) / len(results):.0f}%): "
        f"p95 > {args.max_shift} cells or area changed > {100 * args.max_area:.0f}%"
    )
    for name, group in (("moved", moved), ("resolved", [r for r in results if not r["moved"]])):
        if group:
            shift = [max(r["p95_to_fine"], r["p95_to_coarse"]) for r in group]
            area = [100 * (r["area"] - 1) for r in group]
            print(
                f"  {name}: p95 {min(shift):.2f}-{max(shift):.2f} cells, "
                f"area {min(area):+.0f}% to {max(area):+.0f}%"
            )
    patched = [r for r in results if r["moved_patched"]]
    print(
        f"{len(patched)} of {len(results)} moved ({100 * len(patched) / len(results):.0f}%) once "
        "the fine grid's new non-finite samples (poles on the planes x, y, z = 0 that only an "
        "odd grid samples) take their coarse neighbours' mean, as the sampler's check does"
    )
    families = Counter(r["family"] for r in results)
    moved_by = Counter(r["family"] for r in moved)
    print(
        "  by family: " + ", ".join(f"{f} {moved_by[f]}/{n}" for f, n in sorted(families.items()))
    )


if __name__ == "__main__":
    sys.exit(main())
