"""Small catalogues for the tests: shapes catalogued the way a sampling run catalogues them."""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

from surfgen.filters.verdict import shape_metrics
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.exchange import save_mesh
from surfgen.generator.mesh.mesh import Mesh, extract_mesh
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.store import open_catalogue


def catalogue_shapes(
    root: Path, items: Iterable[tuple[SurfaceSpec, Mesh]], *, seed: int = 0, grid: int = 40
) -> list[str]:
    """Catalogue ``items`` — ``(spec, mesh)`` pairs — as the accepted shapes of one run, the way
    a sampling run does (mesh file, metrics, columns). Returns their keys in order."""
    keys = []
    with open_catalogue(root) as cat:
        cat.make_dirs()
        run = cat.create_run(seed, len(items), grid, {}, f"test{seed}", 1, {"surfgen": "test"})
        for i, (spec, mesh) in enumerate(items):
            metrics = shape_metrics(mesh, spec.box)
            save_mesh(mesh, cat.meshes / f"{spec.key}.ply")
            columns = ("faces", "vertices", "components", "genus", "euler", "area", "volume")
            row = {
                "key": spec.key,
                "spec": spec.to_json(),
                "formula": spec.formula,
                "identity": spec.key,
                "verdict": "accepted",
                "reasons": "[]",
                "metrics": json.dumps(metrics),
                "mesh_path": f"meshes/{spec.key}.ply",
                **{k: metrics[k] for k in columns},
            }
            cat.record_shape(run.id, i, row, True, {})
            keys.append(spec.key)
    return keys


#: Two shapes many catalogue tests start from: ``{name: (formula, half-width of the box)}``.
SPHERE_AND_TORUS = {
    "sphere": ("x^2+y^2+z^2-1", 1.5),
    "torus": ("(sqrt(x^2+y^2)-1)^2+z^2-0.16", 1.6),
}


def catalogue_formulas(
    root: Path, shapes: dict[str, tuple[str, float]], *, seed: int = 0, grid: int = 24
) -> dict[str, str]:
    """Catalogue ``shapes`` (``{name: (formula, half-width of its cubic box)}``), each meshed
    from the reference field on ``grid``^3 points, its draw index its place, as the accepted
    shapes of one run (:func:`catalogue_shapes`). Returns ``{name: key}``."""
    specs = {
        name: SurfaceSpec(f, (-h, h) * 3, (grid,) * 3, provenance={"index": i})
        for i, (name, (f, h)) in enumerate(shapes.items())
    }
    items = [
        (s, extract_mesh(evaluate_reference(parse(s.formula), s.to_grid()), 0.0))
        for s in specs.values()
    ]
    return dict(zip(specs, catalogue_shapes(root, items, seed=seed, grid=grid), strict=True))
