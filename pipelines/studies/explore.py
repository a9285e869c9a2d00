"""Explore a shape by changing its numbers: the library behind the viewer's sliders,
``POST /api/explore`` and ``surfgen sweep``.

A change set (``changes``) is a flat JSON object applied to a base :class:`SurfaceSpec` by
:func:`apply_changes`:

==================  ==============================================================================
``NAME``            a named parameter of the formula (``m`` of eq. C), a number
``box``             the box half-width (a positive number: the box becomes ``[-h, h]^3``) or the
                    6 bounds ``[xmin, xmax, ymin, ymax, zmin, zmax]``
``grid``            points per axis (whole number, 4..:data:`MAX_GRID`) or ``[nx, ny, nz]``
``level``           the iso level (inside is F < level)
``d``               the constant d of an eq. (13) shape (``F = S - d``): the literal subtracted at
                    the top of the formula
``#K``              the K-th numeric literal of the formula, counted parents first from 0 (eq. (13)'s
                    λ, μ, coefficients and exponents are literals of the printed formula)
==================  ==============================================================================

:func:`explore` evaluates a spec with the fast evaluator, meshes it and encodes a GLB, refusing
grids over :data:`MAX_POINTS` samples (one request cannot take the machine).
:func:`knobs_of` lists the sliders a page shows for a spec. :func:`save_variant` writes an explored
variant into the catalogue through :func:`surfgen.pipelines.catalogue.curation.apply_action` (action
``derive``), the same single writer as every curation action.
"""

from __future__ import annotations

import json
import logging
import math
import re
import shutil
import struct
import tempfile
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from surfgen.generator.errors import SpecError, SurfgenError
from surfgen.generator.eval.grid import MIN_POINTS, Box, Grid
from surfgen.generator.files import renaming
from surfgen.generator.formula.expr import Expr, format_number, to_string, walk
from surfgen.generator.model.spec import SurfaceSpec

if TYPE_CHECKING:  # the mesh module (trimesh, scikit-image, numba) loads when a mesh does
    from surfgen.generator.mesh.mesh import Mesh
    from surfgen.pipelines.catalogue.store import Catalogue

log = logging.getLogger(__name__)

MAX_GRID = 160  # points per axis an explore request may ask for
MAX_POINTS = 128**3  # samples per request: 2.1 M float64 = 17 MB of field, < 1 s to evaluate
MAX_CHANGES = 64  # entries in one change set
MAX_FORMULA = 4000  # characters of a pasted formula
MAX_CONSTANT_KNOBS = 24  # literal sliders listed for one formula
_CONSTANT = re.compile(r"^#(\d{1,4})$")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,31}$")

# One explore evaluation at a time per process: concurrent requests queue instead of each
# taking its own field's memory and both cores.
_LOCK = threading.Lock()


class ExploreError(SurfgenError):
    """An explore request or change set that is malformed or out of range."""


# ----------------------------------------------------------------------------- literals


@dataclass(frozen=True)
class Literal:
    """A numeric literal of a formula: its position (parents first), value and where it sits."""

    index: int
    value: float
    context: str


def literals_of(tree: Expr) -> list[Literal]:
    """The numeric literals of ``tree`` in parents-first order. A literal under a unary minus
    counts as negative; ``context`` is the smallest enclosing call or power, printed."""
    out: list[Literal] = []

    def visit(node: Expr, parent: Expr | None, context: Expr) -> None:
        if node.op == "num":
            sign = -1.0 if parent is not None and parent.op == "neg" else 1.0
            out.append(Literal(len(out), sign * float(node.value), _short(context)))  # type: ignore[arg-type]
            return
        here = node if node.op not in ("+", "-", "*", "/", "neg") else context
        for a in node.args:
            visit(a, node, here)

    visit(tree, None, tree)
    return out


def _short(node: Expr, width: int = 48) -> str:
    text = to_string(node)
    return text if len(text) <= width else text[: width - 1] + "…"


def replace_literals(tree: Expr, values: Mapping[int, float]) -> Expr:
    """``tree`` with the literals at the given positions (as :func:`literals_of` counts them)
    set to new values; a negative value becomes a unary minus (or drops one)."""
    counter = [0]

    def rebuild(node: Expr) -> Expr:
        if node.op == "neg" and node.args[0].op == "num":
            i = counter[0]
            counter[0] += 1
            if i in values:
                return _signed(values[i])
            return node
        if node.op == "num":
            i = counter[0]
            counter[0] += 1
            return _signed(values[i]) if i in values else node
        if not node.args:
            return node
        return Expr(node.op, tuple(rebuild(a) for a in node.args), node.value)

    return rebuild(tree)


def _signed(value: float) -> Expr:
    v = float(value)
    leaf = Expr("num", (), abs(v))
    return Expr("neg", (leaf,)) if v < 0 else leaf


def d_literal(tree: Expr) -> int | None:
    """Position of eq. (13)'s d: the literal subtracted (or added) at the top of ``F = S - d``."""
    if tree.op in ("+", "-") and len(tree.args) == 2:
        right = tree.args[1]
        if right.op == "num" or (right.op == "neg" and right.args[0].op == "num"):
            return sum(1 for n in walk(tree.args[0]) if n.op == "num")
    return None


# ----------------------------------------------------------------------------- change sets


def _number(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ExploreError(f"'{name}' must be a number, got {json.dumps(value)[:40]}")
    v = float(value)
    if not math.isfinite(v) or abs(v) > 1e12:
        raise ExploreError(f"'{name}' must be a finite number of magnitude up to 1e12, got {v}")
    return v


def _whole(name: str, value: Any) -> int:
    v = _number(name, value)
    if v != int(v):
        raise ExploreError(f"'{name}' must be a whole number, got {v}")
    return int(v)


def grid_of(value: Any, capped: bool = True) -> tuple[int, int, int]:
    """A grid from ``N`` or ``[nx, ny, nz]``: within the CLI's limits, and with ``capped`` within
    :data:`MAX_GRID` per axis and :data:`MAX_POINTS` in all. Raises :class:`ExploreError` (or the
    CLI's ``GridError``) naming the limits."""
    sizes = value if isinstance(value, list | tuple) else [value]
    if len(sizes) not in (1, 3):
        raise ExploreError(f"'grid' takes 1 or 3 whole numbers, got {len(sizes)}")
    shape = [_whole("grid", s) for s in sizes] * (3 if len(sizes) == 1 else 1)
    Grid.from_sizes(Box.cube(1.0), shape)  # the CLI's own limits and message first
    if not capped:
        return tuple(shape)  # type: ignore[return-value]
    for n in shape:
        if not MIN_POINTS <= n <= MAX_GRID:
            raise ExploreError(
                f"grid: {n} points per axis is out of range (allowed: {MIN_POINTS} to {MAX_GRID})"
            )
    if math.prod(shape) > MAX_POINTS:
        raise ExploreError(
            f"grid: {'x'.join(map(str, shape))} is {math.prod(shape)} samples, more than the "
            f"{MAX_POINTS} (128³) one explore step may evaluate"
        )
    return tuple(shape)  # type: ignore[return-value]


def box_of(value: Any) -> tuple[float, ...]:
    """A box from a half-width ``h`` (``[-h, h]^3``) or 6 bounds. Raises :class:`ExploreError`."""
    if isinstance(value, list | tuple):
        if len(value) != 6:
            raise ExploreError(f"'box' takes a half-width or 6 numbers, got {len(value)} numbers")
        bounds = [_number("box", v) for v in value]
    else:
        h = _number("box", value)
        if h <= 0:
            raise ExploreError(f"'box' half-width must be positive, got {h}")
        bounds = [-h, h] * 3
    try:
        return Box.from_bounds(bounds).bounds()
    except SurfgenError as exc:
        raise ExploreError(str(exc)) from None


def check_changes(changes: Any) -> dict[str, Any]:
    """Validate the shape of a change set (an object of at most :data:`MAX_CHANGES` entries
    with known kinds of names) without a spec. Raises :class:`ExploreError`."""
    if not isinstance(changes, dict):
        raise ExploreError('\'changes\' must be a JSON object such as {"m": 0.5, "grid": 64}')
    if len(changes) > MAX_CHANGES:
        raise ExploreError(f"'changes' has {len(changes)} entries, at most {MAX_CHANGES} allowed")
    for name in changes:
        if not (_NAME.match(name) or _CONSTANT.match(name)):
            raise ExploreError(
                f"unknown change '{name[:40]}' (allowed: a parameter name, box, grid, level, d, #K)"
            )
    return dict(changes)


def apply_changes(
    spec: SurfaceSpec, changes: Mapping[str, Any], capped: bool = True
) -> SurfaceSpec:
    """``spec`` with a change set applied (see the module docstring); the provenance is kept.
    ``capped``: a ``grid`` change must stay within the explore limits (:func:`grid_of`).

    Raises :class:`ExploreError` for an unknown name or a bad value, and the spec's own errors
    (:class:`SpecError`, ``FormulaSyntaxError``) when the result is not a valid spec.
    """
    changes = check_changes(dict(changes))
    tree = spec.tree()
    literals = literals_of(tree)
    new_params = dict(spec.params)
    new_literals: dict[int, float] = {}
    new_d: float | None = None
    update: dict[str, Any] = {}
    for name, value in changes.items():
        m = _CONSTANT.match(name)
        if name == "box":
            update["box"] = box_of(value)
        elif name == "grid":
            update["grid"] = grid_of(value, capped)
        elif name == "level":
            update["level"] = _number(name, value)
        elif name == "d" and "d" not in spec.params:
            k = d_literal(tree)
            if k is None:
                raise ExploreError("this formula has no d: it does not end in '- number'")
            new_d = _number(name, value)
        elif m:
            k = int(m.group(1))
            if k >= len(literals):
                raise ExploreError(
                    f"'{name}': the formula has {len(literals)} numeric literals (#0 to "
                    f"#{len(literals) - 1})"
                )
            new_literals[k] = _number(name, value)
        elif name in spec.params:
            new_params[name] = _number(name, value)
        else:
            allowed = ", ".join([*sorted(spec.params), "box", "grid", "level", "d", "#K"])
            raise ExploreError(f"unknown change '{name}' (allowed: {allowed})")
    if new_literals or new_d is not None:
        changed = replace_literals(tree, new_literals)
        if new_d is not None:  # S - d, written S + |d| when d < 0
            top = "-" if new_d >= 0 else "+"
            changed = Expr(top, (changed.args[0], Expr("num", (), abs(new_d))))
        update["formula"] = to_string(changed)
    if new_params != dict(spec.params):
        update["params"] = new_params
    return spec.replace(**update) if update else spec


def d_of(spec: SurfaceSpec) -> float | None:
    """The d of ``F = S - d`` if the formula has that form (parameter ``d`` first)."""
    if "d" in spec.params:
        return float(spec.params["d"])
    tree = spec.tree()
    k = d_literal(tree)
    if k is None:
        return None
    value = literals_of(tree)[k].value
    return value if tree.op == "-" else -value


# ----------------------------------------------------------------------------- knobs


@dataclass(frozen=True)
class Knob:
    """One slider: the change-set ``name``, a label, the current value, range and step."""

    name: str
    label: str
    value: float
    lo: float
    hi: float
    step: float
    kind: str  # param, d, box, grid, level, literal
    hint: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "label": self.label,
            "value": self.value,
            "lo": self.lo,
            "hi": self.hi,
            "step": self.step,
            "kind": self.kind,
            "hint": self.hint,
        }


def _around(value: float, spread: float = 1.0) -> tuple[float, float, float]:
    """A slider range around ``value``: ±spread·|value| (±1 at 0), 200 steps."""
    width = spread * (abs(value) or 1.0)
    lo, hi = value - width, value + width
    return lo, hi, _nice_step((hi - lo) / 200)


def _nice_step(raw: float) -> float:
    exp = math.floor(math.log10(raw))
    return float(f"{10.0**exp:.0e}")


def knobs_of(spec: SurfaceSpec) -> list[Knob]:
    """The sliders for ``spec``: its parameters, d (eq. (13) shapes), the box half-width, the
    grid, the level, then up to :data:`MAX_CONSTANT_KNOBS` numeric literals."""
    knobs: list[Knob] = []
    for name, value in sorted(spec.params.items()):
        knobs.append(Knob(name, name, value, *_around(value), "param", "named parameter"))
    tree = spec.tree()
    k_d = d_literal(tree) if "d" not in spec.params else None
    d = d_of(spec)
    if k_d is not None and d is not None:
        knobs.append(Knob("d", "d", d, *_around(d), "d", "F = S − d: the level set of the sum"))
    lo, hi = spec.box[0::2], spec.box[1::2]
    half = max(max(abs(a), abs(b)) for a, b in zip(lo, hi, strict=True))
    knobs.append(
        Knob("box", "box half-width", half, half / 4, half * 2, _nice_step(half / 100), "box")
    )
    n = max(spec.grid)
    knobs.append(Knob("grid", "grid", float(n), 16, 128, 1, "grid", "points per axis"))
    knobs.append(
        Knob(
            "level", "level", spec.level, *_around(spec.level, 1.0), "level", "inside is F < level"
        )
    )
    for lit in literals_of(tree)[:MAX_CONSTANT_KNOBS]:
        if lit.index == k_d:
            continue
        knobs.append(
            Knob(f"#{lit.index}", f"#{lit.index}", lit.value, *_around(lit.value, 0.75), "literal",
                 lit.context)
        )  # fmt: skip
    return knobs


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
    from surfgen.generator.errors import EmptySurface
    from surfgen.generator.eval.evaluate import evaluate
    from surfgen.generator.mesh.mesh import extract_mesh

    check_grid(spec)
    with _LOCK:
        c0 = time.thread_time()  # CPU time of this thread: what the step costs on a quiet machine
        t0 = time.perf_counter()
        field_ = evaluate(
            spec.tree(), spec.to_grid(), spec.params, evaluator="fast", threads=threads
        )
        t1 = time.perf_counter()
        mesh: Mesh | None
        empty = None
        try:
            mesh = extract_mesh(field_, spec.level, cap=cap)
        except EmptySurface as exc:
            mesh, empty = None, str(exc)
        t2 = time.perf_counter()
    glb = encode_glb(mesh)
    t3 = time.perf_counter()
    cpu = time.thread_time() - c0
    stats = (mesh_stats(mesh) if topology else mesh_counts(mesh)) | {"nonfinite": field_.nonfinite}
    t4 = time.perf_counter()
    seconds = {"evaluate": t1 - t0, "mesh": t2 - t1, "glb": t3 - t2, "stats": t4 - t3, "cpu": cpu}
    return Explored(spec, mesh, glb, stats, seconds, empty)


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


def encode_glb(mesh: Mesh | None) -> bytes:
    """A binary glTF 2.0 file of ``mesh``: one indexed triangle primitive, float32 positions
    (with their bounds, which glTF requires) and uint32 indices, no normals (the viewer computes
    them, flat or smooth). ``None`` gives a valid GLB with an empty scene."""
    doc: dict[str, Any] = {"asset": {"version": "2.0", "generator": "surfgen"}, "scene": 0}
    binary = b""
    if mesh is None or mesh.n_faces == 0:
        doc["scenes"] = [{"nodes": []}]
    else:
        pos = np.ascontiguousarray(mesh.vertices, dtype="<f4")
        idx = np.ascontiguousarray(mesh.faces, dtype="<u4")
        pos_bytes, idx_bytes = pos.tobytes(), idx.tobytes()
        binary = pos_bytes + idx_bytes  # both multiples of 4 bytes
        doc |= {
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "mode": 4}]}],
            "buffers": [{"byteLength": len(binary)}],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": len(pos_bytes), "target": 34962},
                {
                    "buffer": 0,
                    "byteOffset": len(pos_bytes),
                    "byteLength": len(idx_bytes),
                    "target": 34963,
                },
            ],
            "accessors": [
                {
                    "bufferView": 0,
                    "componentType": 5126,
                    "count": int(len(pos)),
                    "type": "VEC3",
                    "min": [float(v) for v in pos.min(axis=0)],
                    "max": [float(v) for v in pos.max(axis=0)],
                },
                {
                    "bufferView": 1,
                    "componentType": 5125,
                    "count": int(idx.size),
                    "type": "SCALAR",
                },
            ],
        }
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text
    if binary:
        chunks += struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(chunks)) + chunks


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
    from surfgen.generator.model.presets import get_preset

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
        if not _NAME.match(name):
            raise ExploreError(f"bad parameter name '{name[:40]}'")
    values = {k: _number(k, v) for k, v in params.items()}
    box = box_of(body.get("box", 2.0))
    grid = grid_of(body.get("grid", 64))
    level = _number("level", body.get("level", 0.0))
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
    from surfgen.generator.mesh.mesh import extract_mesh, save_mesh
    from surfgen.pipelines.catalogue.curation import get_shape
    from surfgen.pipelines.pictures.raster import render_thumbnail, render_turntable

    full = cat.resolve(key)
    spec = derived_spec(cat.spec(full), full, changes)
    check_grid(spec)
    new = spec.key
    if cat.conn.execute("SELECT 1 FROM shapes WHERE key=?", (new,)).fetchone():
        return get_shape(cat, new, full=False)
    from surfgen.generator.eval.evaluate import evaluate

    with _LOCK:
        field_ = evaluate(spec.tree(), spec.to_grid(), spec.params, evaluator="fast")
        mesh = extract_mesh(field_, spec.level, cap=True)
    metrics = shape_metrics(mesh, spec.box)
    metrics["nonfinite"] = field_.nonfinite
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
    from surfgen.pipelines.catalogue.curation import apply_action

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
    apply_action(cat, full, "derive", row)


def formula_with(spec: SurfaceSpec) -> str:
    """The formula with its parameters written out, as K3DSurf/MathMod would need it."""
    if not spec.params:
        return spec.formula
    values = ", ".join(f"{k}={format_number(v) if v >= 0 else '-' + format_number(-v)}"
                       for k, v in sorted(spec.params.items()))  # fmt: skip
    return f"{spec.formula}   [{values}]"


__all__ = [
    "Explored",
    "ExploreError",
    "Knob",
    "SpecError",
    "apply_changes",
    "encode_glb",
    "explore",
    "knobs_of",
    "save_variant",
]
