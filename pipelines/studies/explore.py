"""Explore a shape by changing its numbers: the library behind the viewer's sliders,
``POST /api/explore`` and ``surfgen sweep``.

A change set (``changes``) is a flat JSON object applied to a base :class:`SurfaceSpec` by
:func:`~surfgen.pipelines.studies.knobs.apply_changes` (literals, change sets and sliders are in
:mod:`surfgen.pipelines.studies.knobs`):

==================  ==============================================================================
``NAME``            a named parameter of the formula (``m`` of eq. C), a number
``box``             the box half-width (a positive number: the box becomes ``[-h, h]^3``) or the
                    6 bounds ``[xmin, xmax, ymin, ymax, zmin, zmax]``
``grid``            points per axis (whole number, 4..:data:`~.knobs.MAX_GRID`) or ``[nx, ny, nz]``
``level``           the iso level (inside is F < level)
``d``               the constant d of an eq. (13) shape (``F = S - d``): the literal subtracted at
                    the top of the formula
``#K``              the K-th numeric literal of the formula, counted parents first from 0 (eq. (13)'s
                    λ, μ, coefficients and exponents are literals of the printed formula)
==================  ==============================================================================

:func:`explore` evaluates a spec with the fast evaluator, meshes it and encodes a GLB, refusing
grids over :data:`~.knobs.MAX_POINTS` samples (one request cannot take the machine).
:func:`~.knobs.knobs_of` lists the sliders a page shows for a spec. :func:`save_variant` writes an explored
variant into the catalogue through :func:`surfgen.pipelines.catalogue.curation.apply_action` (action
``derive``), the same single writer as every curation action.
"""

from __future__ import annotations

import json
import logging
import shutil
import tempfile
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from surfgen.generator.errors import SpecError, SurfgenError
from surfgen.generator.files import renaming
from surfgen.generator.formula.expr import format_number
from surfgen.generator.model.presets import get_preset
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue import curation
from surfgen.pipelines.catalogue.curation import get_shape
from surfgen.pipelines.studies.knobs import (
    MAX_CHANGES,
    NAME_RE,
    ExploreError,
    apply_changes,
    box_of,
    check_changes,
    d_of,
    grid_of,
    number_of,
)

if TYPE_CHECKING:  # the mesh module (trimesh, scikit-image, numba) loads when a mesh does
    from surfgen.generator.mesh.mesh import Mesh
    from surfgen.pipelines.catalogue.store import Catalogue

log = logging.getLogger(__name__)

MAX_FORMULA = 4000  # characters of a pasted formula

# One explore evaluation at a time per process: concurrent requests queue instead of each
# taking its own field's memory and both cores.
_LOCK = threading.Lock()


# ----------------------------------------------------------------------------- evaluate + mesh


@dataclass(frozen=True)
class Explored:
    """One explore step: the spec, its mesh (None when the surface left the box), the GLB bytes,
    mesh statistics and seconds per stage."""

    spec: SurfaceSpec
    mesh: Mesh | None
    glb: bytes
    stats: dict[str, Any]
    seconds: dict[str, float] = field(default_factory=dict)
    empty: str | None = None

    @property
    def faces(self) -> int:
        return 0 if self.mesh is None else self.mesh.n_faces


def check_grid(spec: SurfaceSpec) -> None:
    """Refuse a spec whose grid is over the explore limits (:func:`grid_of`'s message)."""
    grid_of(list(spec.grid))


def explore(
    spec: SurfaceSpec, cap: bool = True, threads: int | None = None, topology: bool = True
) -> Explored:
    """Evaluate ``spec`` (fast evaluator), extract its surface and encode it as GLB.

    ``stats`` holds :func:`mesh_stats` (with ``topology``) or only the free counts (faces,
    vertices, bounding box): a slider step leaves the topology for later (:func:`mesh_stats`
    costs as much as the GLB on large meshes). An empty surface (all inside or all outside) is
    not an error here: the step gives an empty GLB and says why in ``empty``. Raises
    :class:`ExploreError` for a grid over the limits.
    """
    # The mesh modules (trimesh, scikit-image, numba) load when a mesh is made: the server and
    # the CLI import this module without making one.
    from surfgen.generator.mesh.exchange import glb_bytes
    from surfgen.generator.mesh.realise import realise

    check_grid(spec)
    with _LOCK:
        c0 = time.thread_time()  # CPU time of this thread: what the step costs on a quiet machine
        made = realise(
            spec, evaluator="auto", threads=threads, cap=cap, allow_empty=True, keep_samples=False
        )
    mesh = made.mesh
    t2 = time.perf_counter()
    glb = glb_bytes(mesh, web=True)
    t3 = time.perf_counter()
    cpu = time.thread_time() - c0
    stats = (mesh_stats(mesh) if topology else mesh_counts(mesh)) | {
        "nonfinite": made.field.nonfinite
    }
    t4 = time.perf_counter()
    seconds = made.seconds | {"glb": t3 - t2, "stats": t4 - t3, "cpu": cpu}
    return Explored(spec, mesh, glb, stats, seconds, made.empty)


def warm_up() -> None:
    """Load the fast evaluator (numba's cache) and meshing once, so a server's first slider step
    is as quick as the others. Meant for a background thread."""
    try:
        explore(SurfaceSpec("x^2+y^2+z^2-1", (-1.5, 1.5) * 3, (8, 8, 8)))
    except SurfgenError as exc:  # never fatal: the first real request will say what is wrong
        log.warning("explore warm-up failed: %s", exc)


def mesh_counts(mesh: Mesh | None) -> dict[str, Any]:
    """Faces, vertices and bounding box (6 numbers; None when empty): no topology."""
    if mesh is None or mesh.n_faces == 0:
        return {"vertices": 0, "faces": 0, "bbox": None}
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    bbox = [float(v) for pair in zip(lo, hi, strict=True) for v in pair]
    return {"vertices": mesh.n_vertices, "faces": mesh.n_faces, "bbox": bbox}


def mesh_stats(mesh: Mesh | None) -> dict[str, Any]:
    """Cheap statistics for the viewer: vertices, faces, edges, Euler characteristic,
    components, boundary edges and (for a closed mesh) genus; numpy and scipy only."""
    if mesh is None or mesh.n_faces == 0:
        return {"vertices": 0, "faces": 0, "bbox": None, "edges": 0, "euler": 0, "components": 0,
                "boundary_edges": 0, "genus": None}  # fmt: skip
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    f = mesh.faces
    nv = mesh.n_vertices
    a = f.reshape(-1)
    b = f[:, [1, 2, 0]].reshape(-1)
    key = np.minimum(a, b) * np.int64(nv) + np.maximum(a, b)
    _, counts = np.unique(key, return_counts=True)
    used = np.bincount(a, minlength=nv) > 0
    euler = int(np.count_nonzero(used)) - len(counts) + mesh.n_faces
    graph = coo_matrix((np.ones(len(a), dtype=np.int8), (a, b)), shape=(nv, nv))
    n_comp, labels = connected_components(graph, directed=False)
    components = int(len(np.unique(labels[used]))) if n_comp else 0
    boundary = int(np.count_nonzero(counts == 1))
    closed = boundary == 0 and not np.any(counts > 2)
    lo, hi = mesh.vertices[used].min(axis=0), mesh.vertices[used].max(axis=0)
    return {
        "vertices": mesh.n_vertices,
        "faces": mesh.n_faces,
        "bbox": [float(v) for pair in zip(lo, hi, strict=True) for v in pair],
        "edges": int(len(counts)),
        "euler": euler,
        "components": components,
        "boundary_edges": boundary,
        "genus": (2 * components - euler) // 2 if closed else None,
    }


# ----------------------------------------------------------------------------- requests


def spec_from_request(
    body: Any, catalogue_spec: Any = None
) -> tuple[SurfaceSpec, bool, str | None]:
    """The spec an explore request describes, whether to cap it, and the catalogued key.

    ``body`` is ``{"formula": STR, "params": {...}, "box": [6 numbers] | h, "grid": N, "cap":
    bool, "level": x, "changes": {...}}`` or ``{"key": KEY, "changes": {...}}`` (or ``{"preset": NAME, "changes":
    {...}}``). ``catalogue_spec(key)`` returns ``(full key, spec)`` of a catalogued shape.
    Raises :class:`ExploreError`, :class:`SpecError` or a formula error with the CLI's message.
    """

    if not isinstance(body, dict):
        raise ExploreError("the body must be a JSON object")
    if "key" in body or "preset" in body:
        _only(body, {"key", "preset", "changes", "cap"})
        changes = check_changes(body.get("changes", {}))
        cap = _flag(body, "cap", True)
        if "key" in body and "preset" in body:
            raise ExploreError("give 'key' or 'preset', not both")
        if "key" in body:
            key = body["key"]
            if not isinstance(key, str) or not 1 <= len(key) <= 64:
                raise ExploreError("'key' must be a shape key (hex digits)")
            if catalogue_spec is None:
                raise ExploreError("no catalogue to look the key up in")
            full, base = catalogue_spec(key)
            return apply_changes(base, changes), cap, full
        name = body["preset"]
        if not isinstance(name, str) or len(name) > 40:
            raise ExploreError("'preset' must be a preset name")
        preset = get_preset(name)
        cap = _flag(body, "cap", preset.cap)
        return apply_changes(preset.spec(), changes), cap, None
    _only(body, {"formula", "params", "box", "grid", "level", "cap", "changes"})
    changes = check_changes(body.get("changes", {}))
    formula = body.get("formula")
    if not isinstance(formula, str) or not formula.strip():
        raise ExploreError("'formula' must be a non-empty string (or give 'key')")
    if len(formula) > MAX_FORMULA:
        raise ExploreError(f"'formula' is {len(formula)} characters, at most {MAX_FORMULA}")
    params = body.get("params", {})
    if not isinstance(params, dict) or len(params) > MAX_CHANGES:
        raise ExploreError(f"'params' must be an object of at most {MAX_CHANGES} numbers")
    for name in params:
        if not NAME_RE.match(name):
            raise ExploreError(f"bad parameter name '{name[:40]}'")
    values = {k: number_of(k, v) for k, v in params.items()}
    box = box_of(body.get("box", 2.0))
    grid = grid_of(body.get("grid", 64))
    level = number_of("level", body.get("level", 0.0))
    spec = SurfaceSpec(formula, box, grid, params=values, level=level)
    return apply_changes(spec, changes), _flag(body, "cap", True), None


def _only(body: dict, allowed: set[str]) -> None:
    unknown = sorted(set(body) - allowed)
    if unknown:
        raise ExploreError(
            f"unknown field '{unknown[0][:40]}' (allowed: {', '.join(sorted(allowed))})"
        )


def _flag(body: dict, name: str, default: bool) -> bool:
    value = body.get(name, default)
    if not isinstance(value, bool):
        raise ExploreError(f"'{name}' must be true or false")
    return value


# ----------------------------------------------------------------------------- saving variants


def derived_spec(base: SurfaceSpec, key: str, changes: Mapping[str, Any]) -> SurfaceSpec:
    """The spec of a variant of catalogued shape ``key``: the changes applied, and provenance
    ``{"derived_from": key, "changes": {...}}`` (so the same variant always has the same key)."""
    changes = check_changes(dict(changes))
    if not changes:
        raise ExploreError("nothing changed: move a slider before saving a variant")
    spec = apply_changes(base, changes)
    return spec.replace(provenance={"derived_from": key, "changes": dict(sorted(changes.items()))})


def save_variant(cat: Catalogue, key: str, changes: Mapping[str, Any]) -> dict[str, Any]:
    """Evaluate the variant of ``key`` that ``changes`` describe on its full grid, write its mesh,
    thumbnail and turntable, and catalogue it as an accepted shape with provenance
    ``derived_from: key`` — through :func:`~surfgen.pipelines.catalogue.curation.apply_action` (``derive``),
    which also logs the action on ``key``. Saving the same variant twice changes nothing.

    Returns the new shape's record. Raises :class:`ExploreError`, ``CatalogueError`` for an
    unknown key, and ``EmptySurface`` when the variant has no surface.
    """
    from surfgen.filters.verdict import shape_metrics
    from surfgen.generator.mesh.exchange import save_mesh
    from surfgen.generator.mesh.realise import realise
    from surfgen.pipelines.pictures.raster import render_thumbnail, render_turntable

    full = cat.resolve(key)
    spec = derived_spec(cat.spec(full), full, changes)
    check_grid(spec)
    new = spec.key
    if cat.conn.execute("SELECT 1 FROM shapes WHERE key=?", (new,)).fetchone():
        return get_shape(cat, new, full=False)
    with _LOCK:
        made = realise(spec, evaluator="auto", cap=True, keep_samples=False)
    mesh = made.mesh
    metrics = shape_metrics(mesh, spec.box)
    metrics["nonfinite"] = made.field.nonfinite
    cat.make_dirs()
    mesh_rel, thumb_rel, turn_rel = (f"meshes/{new}.ply", f"thumbs/{new}.png",
                                     f"turntables/{new}.png")  # fmt: skip
    # The three files are made in a temporary folder of the catalogue, then moved in with the
    # row as one (generator/files.renaming): a full disk leaves neither files nor row.
    work = Path(tempfile.mkdtemp(prefix=".derive-", suffix=".tmp", dir=cat.root))
    try:
        save_mesh(mesh, work / "mesh.ply")
        render_thumbnail(mesh, work / "thumb.png", size=256)
        render_turntable(mesh, work / "turntable.png", views=12, size=256)
        with renaming() as tx:
            tx.move(work / "mesh.ply", cat.root / mesh_rel)
            tx.move(work / "thumb.png", cat.root / thumb_rel)
            tx.move(work / "turntable.png", cat.root / turn_rel)
            _record_derived(cat, full, new, spec, metrics, mesh_rel, thumb_rel, turn_rel)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return get_shape(cat, new, full=False)


def _record_derived(
    cat: Catalogue,
    full: str,
    new: str,
    spec: SurfaceSpec,
    metrics: dict[str, Any],
    mesh_rel: str,
    thumb_rel: str,
    turn_rel: str,
) -> None:

    columns = ("faces", "vertices", "components", "genus", "euler", "area", "volume")
    row = {
        "key": new,
        "spec": spec.to_json(),
        "formula": spec.formula,
        "identity": spec.identity,
        "d": d_of(spec),
        "verdict": "accepted",
        "reasons": "[]",
        "metrics": json.dumps(metrics, default=float),
        "mesh_path": mesh_rel,
        "thumb_path": thumb_rel,
        "turntable_path": turn_rel,
        **{k: metrics.get(k) for k in columns},
    }
    curation.apply_action(cat, full, "derive", row)


def formula_with(spec: SurfaceSpec) -> str:
    """The formula with its parameters written out, as K3DSurf/MathMod would need it."""
    if not spec.params:
        return spec.formula
    values = ", ".join(f"{k}={format_number(v) if v >= 0 else '-' + format_number(-v)}"
                       for k, v in sorted(spec.params.items()))  # fmt: skip
    return f"{spec.formula}   [{values}]"


__all__ = [
    "Explored",
    "SpecError",
    "explore",
    "save_variant",
]
