"""Does a mesh survive the way other tools load it?  :func:`merge_problems`.

Downstream tools merge vertices: trimesh's default load merges coincident ones, MeshLab's
"merge close vertices", Blender's "merge by distance" and slicers merge within a tolerance, and
binary PLY/STL store float32.  A mesh whose distinct vertices lie within those tolerances of
each other pinches there.  This module runs the three merges surfgen promises to survive and
compares the topology before and after.
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np
import trimesh

from surfgen.filters import meshlab
from surfgen.filters.metrics import measure_mesh
from surfgen.generator.mesh.mesh import Mesh, bbox_diagonal

MERGE_FRACTION = 1e-6  # MeshLab's merge threshold, as a fraction of the bbox diagonal
_KEYS = ("components", "euler", "genus", "watertight", "nonmanifold_edges", "nonmanifold_vertices")


def _topology(mesh: Mesh) -> dict[str, Any]:
    m = measure_mesh(mesh)
    return {k: getattr(m, k) for k in _KEYS}


def merged_meshes(mesh: Mesh) -> dict[str, Mesh]:
    """``mesh`` after each merge: ``trimesh`` (binary PLY written and read back with trimesh's
    defaults, which merge coincident vertices), ``meshlab`` (merge close vertices at
    :data:`MERGE_FRACTION` of the bbox diagonal) and ``float32`` (coordinates rounded to float32,
    then bit-identical vertices merged)."""
    out: dict[str, Mesh] = {}
    data = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).export(
        file_type="ply", encoding="binary"
    )
    loaded = trimesh.load(io.BytesIO(data), file_type="ply")  # process=True: merges
    out["trimesh"] = Mesh(loaded.vertices, loaded.faces)
    out["meshlab"] = meshlab.merge_close_vertices(mesh, MERGE_FRACTION * bbox_diagonal(mesh))
    rounded = mesh.vertices.astype(np.float32).astype(np.float64)
    unique, inverse = np.unique(rounded, axis=0, return_inverse=True)
    out["float32"] = Mesh(unique, inverse.reshape(-1)[mesh.faces])
    return out


def merge_problems(mesh: Mesh) -> list[str]:
    """What changes when ``mesh`` goes through each merge of :func:`merged_meshes`.

    Empty when the mesh keeps its components, Euler characteristic, genus, watertightness and
    its (absence of) non-manifold edges and vertices after every merge; else one line per
    difference, e.g. ``"trimesh: nonmanifold_edges 0 -> 12"``.
    """
    before = _topology(mesh)
    problems = []
    for name, merged in merged_meshes(mesh).items():
        after = _topology(merged)
        for key in _KEYS:
            if after[key] != before[key]:
                problems.append(f"{name}: {key} {before[key]} -> {after[key]}")
    return problems
