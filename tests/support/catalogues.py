"""Small catalogues for the tests: shapes catalogued the way a sampling run catalogues them."""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

from surfgen.filters.verdict import shape_metrics
from surfgen.generator.mesh.exchange import save_mesh
from surfgen.generator.mesh.mesh import Mesh
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
