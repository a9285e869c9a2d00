"""The pymeshlab adapter: the only module of surfgen that imports pymeshlab.

pymeshlab renames filters and parameters between releases, so this module speaks exactly one
version (:data:`PYMESHLAB_VERSION`, pinned in ``pyproject.toml``) and keeps every filter name it
uses in :data:`FILTERS`.  Functions take and return :class:`~surfgen.generator.mesh.mesh.Mesh` or
plain numbers; every repair returns a new mesh without unreferenced vertices.

Never call ``MeshSet.save_snapshot``: it aborts the process (SIGABRT) without a display.
"""

from __future__ import annotations

import logging
import time
from importlib import metadata
from typing import Any

import numba
import numpy as np
import pymeshlab

from surfgen.filters.geometry import join_sets
from surfgen.generator.errors import MeshError
from surfgen.generator.jit.options import CHECKED
from surfgen.generator.mesh.mesh import Mesh, bbox_diagonal, compact_mesh, face_areas

logger = logging.getLogger(__name__)

PYMESHLAB_VERSION = "2025.7.post1"


def installed_version() -> str:
    """The installed pymeshlab's version (pymeshlab itself has no ``__version__``)."""
    return metadata.version("pymeshlab")


# Our name -> pymeshlab 2025.7 filter name (checked with pymeshlab.print_filter_list()).
FILTERS: dict[str, str] = {
    "topology": "get_topological_measures",
    "merge_close_vertices": "meshing_merge_close_vertices",
    "remove_duplicate_faces": "meshing_remove_duplicate_faces",
    "remove_null_faces": "meshing_remove_null_faces",
    "remove_unreferenced_vertices": "meshing_remove_unreferenced_vertices",
    "repair_nonmanifold_edges": "meshing_repair_non_manifold_edges",
    "repair_nonmanifold_vertices": "meshing_repair_non_manifold_vertices",
    "close_holes": "meshing_close_holes",
    "orient_coherently": "meshing_re_orient_faces_coherently",
    "isotropic_remesh": "meshing_isotropic_explicit_remeshing",
    "taubin_smooth": "apply_coord_taubin_smoothing",
}

# Values of the enum parameter ``method`` of meshing_repair_non_manifold_edges.
NONMANIFOLD_EDGE_METHODS: dict[str, str] = {
    "remove_faces": "Remove Faces",
    "split_vertices": "Split Vertices",
}

# get_topological_measures key -> our key; -1 from pymeshlab means "undefined" (becomes None).
_TOPOLOGY_KEYS: dict[str, str] = {
    "vertices_number": "vertices",
    "edges_number": "edges",
    "faces_number": "faces",
    "connected_components_number": "components",
    "boundary_edges": "boundary_edges",
    "non_two_manifold_edges": "nonmanifold_edges",
    "non_two_manifold_vertices": "nonmanifold_vertices",
    "unreferenced_vertices": "unreferenced_vertices",
    "is_mesh_two_manifold": "two_manifold",
    "genus": "genus",
    "number_holes": "holes",
}

Step = tuple[str, dict[str, Any]]


def _meshset(mesh: Mesh) -> pymeshlab.MeshSet:
    if mesh.n_faces == 0 or mesh.n_vertices == 0:
        raise MeshError("the mesh is empty (no faces)")
    ms = pymeshlab.MeshSet()
    # pymeshlab wants float64 vertices and int32 faces.
    ms.add_mesh(pymeshlab.Mesh(mesh.vertices, mesh.faces.astype(np.int32)))
    return ms


def _from_meshset(ms: pymeshlab.MeshSet) -> Mesh:
    m = ms.current_mesh()
    return Mesh(m.vertex_matrix(), m.face_matrix())


def _apply(mesh: Mesh, *steps: Step) -> Mesh:
    """Run ``steps`` (our filter name, parameters) on a copy of ``mesh``, then drop unreferenced
    vertices.  Raises :class:`MeshError` when a filter fails or the mesh is empty."""
    ms = _meshset(mesh)
    for name, params in (*steps, ("remove_unreferenced_vertices", {})):
        try:
            ms.apply_filter(FILTERS[name], **params)
        except pymeshlab.PyMeshLabException as exc:
            raise MeshError(f"meshlab {FILTERS[name]} failed: {exc}") from None
    out = _from_meshset(ms)
    logger.debug(
        "meshlab %s: %d -> %d faces",
        "+".join(name for name, _ in steps),
        mesh.n_faces,
        out.n_faces,
    )
    return out


def topology(mesh: Mesh) -> dict[str, int | bool | None]:
    """pymeshlab's topological measures under our names (plain ints and bools).

    Keys: vertices, edges, faces, components, boundary_edges, nonmanifold_edges,
    nonmanifold_vertices, unreferenced_vertices, two_manifold, genus, holes.  ``genus`` and
    ``holes`` are None when pymeshlab leaves them undefined (a non-manifold mesh).  Note that
    pymeshlab's ``nonmanifold_edges`` is its own count, not always the number of distinct edges
    with more than two faces.  Raises :class:`MeshError` for an empty mesh.
    """
    ms = _meshset(mesh)
    raw = ms.apply_filter(FILTERS["topology"])
    out: dict[str, int | bool | None] = {}
    for theirs, ours in _TOPOLOGY_KEYS.items():
        value = raw[theirs]
        if isinstance(value, bool | np.bool_):
            out[ours] = bool(value)
        else:
            out[ours] = None if ours in ("genus", "holes") and value < 0 else int(value)
    return out


def merge_close_vertices(mesh: Mesh, threshold: float | None = None) -> Mesh:
    """Merge vertices closer than ``threshold`` (box units; default 1e-6 of the bbox diagonal)."""
    if threshold is None:
        threshold = 1e-6 * bbox_diagonal(mesh)
    return _apply(mesh, ("merge_close_vertices", {"threshold": pymeshlab.PureValue(threshold)}))


def remove_duplicate_faces(mesh: Mesh) -> Mesh:
    """Drop faces that repeat another face's three vertices."""
    return _apply(mesh, ("remove_duplicate_faces", {}))


def remove_degenerate_faces(mesh: Mesh) -> Mesh:
    """Drop null faces (zero area, including faces that repeat a vertex)."""
    return _apply(mesh, ("remove_null_faces", {}))


def repair_nonmanifold_edges(mesh: Mesh, method: str = "remove_faces") -> Mesh:
    """Make every edge have at most two faces, by ``remove_faces`` or ``split_vertices``.

    Raises :class:`MeshError` for an unknown method.
    """
    if method not in NONMANIFOLD_EDGE_METHODS:
        raise MeshError(
            f"unknown non-manifold edge repair '{method}' "
            f"(allowed: {', '.join(NONMANIFOLD_EDGE_METHODS)})"
        )
    params = {"method": NONMANIFOLD_EDGE_METHODS[method]}
    return _apply(mesh, ("repair_nonmanifold_edges", params))


def repair_nonmanifold_vertices(mesh: Mesh, displacement: float = 0.0) -> Mesh:
    """Split non-manifold vertices, one copy per fan; copies move by ``displacement`` (a ratio
    of the local edge length) towards their fan."""
    return _apply(mesh, ("repair_nonmanifold_vertices", {"vertdispratio": float(displacement)}))


def remove_small_components(mesh: Mesh, min_fraction_of_area: float) -> Mesh:
    """Drop connected components (faces joined through shared vertices) whose area is below
    ``min_fraction_of_area`` times the total area.  May return an empty mesh."""
    labels = face_components(mesh)
    areas = face_areas(mesh)
    component_area = np.bincount(labels, weights=areas)
    keep = component_area[labels] >= min_fraction_of_area * areas.sum()
    out = compact_mesh(mesh.vertices, mesh.faces[keep])
    logger.debug(
        "remove_small_components: %d of %d components kept",
        int(np.count_nonzero(component_area >= min_fraction_of_area * areas.sum())),
        len(component_area),
    )
    return out


def close_holes(mesh: Mesh, max_hole_edges: int) -> Mesh:
    """Fill boundary loops of at most ``max_hole_edges`` edges with new faces.

    pymeshlab skips fills that would self-intersect and needs a two-manifold mesh (else
    :class:`MeshError`).
    """
    params = {"maxholesize": int(max_hole_edges), "selfintersection": True}
    return _apply(mesh, ("close_holes", params))


def reorient_outward(mesh: Mesh) -> Mesh:
    """Orient faces coherently, then flip each component whose signed volume is negative.

    For open components the volume sign (taken about the component's centroid) is only a hint.
    """
    coherent = _apply(mesh, ("orient_coherently", {}))
    labels = face_components(coherent)
    v = coherent.vertices
    f = coherent.faces
    centroid = np.zeros((labels.max() + 1, 3))
    counts = np.bincount(labels).astype(np.float64)
    for k in range(3):
        centroid[:, k] = np.bincount(labels, weights=v[f[:, 0], k]) / counts
    a, b, c = (v[f[:, i]] - centroid[labels] for i in range(3))
    volume = np.bincount(labels, weights=np.einsum("ij,ij->i", a, np.cross(b, c)))
    flip = volume[labels] < 0
    faces = f.copy()
    faces[flip] = faces[flip][:, ::-1]
    return Mesh(v, faces)


def isotropic_remesh(mesh: Mesh, target_edge_length: float, iterations: int = 3) -> Mesh:
    """Remesh towards edges of ``target_edge_length`` (box units).  Slow on big meshes."""
    params = {
        "targetlen": pymeshlab.PureValue(float(target_edge_length)),
        "iterations": int(iterations),
    }
    return _apply(mesh, ("isotropic_remesh", params))


def taubin_smooth(mesh: Mesh, steps: int = 10) -> Mesh:
    """Taubin lambda|mu smoothing (lambda 0.5, mu -0.53): smooths without shrinking much."""
    return _apply(mesh, ("taubin_smooth", {"stepsmoothnum": int(steps)}))


# --- numpy helpers shared by the repairs ------------------------------------------------------


def face_components(mesh: Mesh) -> np.ndarray:
    """Component label ``(F,)`` int of each face, faces joined through shared vertices.

    Components are numbered in the order of their lowest vertex index (as scipy's
    ``connected_components`` numbers them).
    """
    faces = np.ascontiguousarray(mesh.faces)
    first = _vertex_roots(faces, mesh.n_vertices)[faces[:, 0]]
    # Renumber the roots 0..k-1 in their order (np.unique's, without its sort), over faces
    # only, so unreferenced vertices leave no gaps: as compact_mesh renumbers vertices.
    used = np.zeros(mesh.n_vertices, dtype=bool)
    used[first] = True
    return (np.cumsum(used) - 1)[first]


@numba.njit(**CHECKED)
def _vertex_roots(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Union-find over the faces' edges: each vertex's component as its lowest vertex index.

    Linear time, against scipy's sparse-graph build and sort (10x slower on 80k faces).
    """
    parent = np.arange(n_vertices)
    for t in range(faces.shape[0]):
        for k in range(2):
            join_sets(parent, faces[t, k], faces[t, k + 1])  # roots are component minima
    for i in range(n_vertices):  # parents are lower indices, so theirs are final already
        parent[i] = parent[parent[i]]
    return parent


# --- batched repairs and fast remeshing (used by surfgen.filters.cleanup) ----------------------


def _repair_params(name: str, options: dict[str, Any]) -> dict[str, Any]:
    """Our repair options -> pymeshlab parameters (filter names stay in :data:`FILTERS`)."""
    if name == "merge_close_vertices":
        return {"threshold": pymeshlab.PureValue(float(options["threshold"]))}
    if name == "repair_nonmanifold_edges":
        method = options.get("method", "remove_faces")
        if method not in NONMANIFOLD_EDGE_METHODS:
            raise MeshError(
                f"unknown non-manifold edge repair '{method}' "
                f"(allowed: {', '.join(NONMANIFOLD_EDGE_METHODS)})"
            )
        return {"method": NONMANIFOLD_EDGE_METHODS[method]}
    if name == "repair_nonmanifold_vertices":
        return {"vertdispratio": float(options.get("displacement", 0.0))}
    if name == "close_holes":
        return {"maxholesize": int(options["max_hole_edges"]), "selfintersection": True}
    if name in ("remove_duplicate_faces", "remove_degenerate_faces", "orient_coherently"):
        return {}
    raise MeshError(f"unknown repair '{name}' (allowed: {', '.join(REPAIRS)})")


# Repairs run_repairs knows: our name -> key in FILTERS.
REPAIRS: dict[str, str] = {
    "merge_close_vertices": "merge_close_vertices",
    "remove_duplicate_faces": "remove_duplicate_faces",
    "remove_degenerate_faces": "remove_null_faces",
    "repair_nonmanifold_edges": "repair_nonmanifold_edges",
    "repair_nonmanifold_vertices": "repair_nonmanifold_vertices",
    "close_holes": "close_holes",
    "orient_coherently": "orient_coherently",
}


def run_repairs(
    mesh: Mesh, repairs: list[tuple[str, dict[str, Any]]]
) -> tuple[Mesh, list[dict[str, Any]]]:
    """Run several repairs on one copy of ``mesh`` (one MeshSet: no copy in and out per step).

    ``repairs`` are ``(name, options)`` with names from :data:`REPAIRS` and options
    ``merge_close_vertices: threshold`` (box units), ``repair_nonmanifold_edges: method``,
    ``repair_nonmanifold_vertices: displacement``, ``close_holes: max_hole_edges``.
    Unreferenced vertices are dropped after every step.  Returns the repaired mesh and, per
    step, ``{"name", "vertices", "faces", "seconds"}`` counted after it.  Raises
    :class:`MeshError` for an unknown repair, a failing filter or an empty mesh.
    """
    ms = _meshset(mesh)
    counts: list[dict[str, Any]] = []
    for name, options in repairs:
        if name not in REPAIRS:
            raise MeshError(f"unknown repair '{name}' (allowed: {', '.join(REPAIRS)})")
        filter_name = FILTERS[REPAIRS[name]]
        params = _repair_params(name, options)
        start = time.perf_counter()
        try:
            ms.apply_filter(filter_name, **params)
            ms.apply_filter(FILTERS["remove_unreferenced_vertices"])
        except pymeshlab.PyMeshLabException as exc:
            raise MeshError(f"meshlab {filter_name} failed: {exc}") from None
        m = ms.current_mesh()
        counts.append(
            {
                "name": name,
                "vertices": int(m.vertex_number()),
                "faces": int(m.face_number()),
                "seconds": time.perf_counter() - start,
            }
        )
    return _from_meshset(ms), counts


def remesh_isotropic(
    mesh: Mesh,
    target_edge_length: float,
    iterations: int = 1,
    feature_degrees: float = 30.0,
) -> Mesh:
    """Isotropic explicit remeshing towards edges of ``target_edge_length`` (box units).

    Unlike :func:`isotropic_remesh` it skips pymeshlab's surface-distance check on every
    collapse and flip (3x faster on 200k faces); vertices are still reprojected onto the input
    surface after each iteration, and edges whose faces meet at more than ``feature_degrees``
    (the box caps' rims) are kept as creases.
    """
    params = {
        "targetlen": pymeshlab.PureValue(float(target_edge_length)),
        "iterations": int(iterations),
        "featuredeg": float(feature_degrees),
        "checksurfdist": False,
        "reprojectflag": True,
    }
    return _apply(mesh, ("isotropic_remesh", params))
