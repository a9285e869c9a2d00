"""Export: catalogued shapes (or spec and mesh files) as cleaned, print- or render-ready meshes.

For each input: get its mesh (the catalogue's file, or the spec meshed with caps, or re-evaluated
on a finer grid with ``regrid``), run the cleanup chain of :mod:`surfgen.filters.cleanup`, scale
the longest bbox side to ``size`` millimetres, check that printable formats (STL, 3MF) get a
watertight manifold, and write ``<name>.<format>`` plus a sidecar ``<name>.json`` (key, formula,
spec, metrics before and after, each step's report, versions, options, the command that
reproduces the file).  All inputs are resolved and processed before anything is written, so an
unknown key or a refused shape leaves the output folder untouched.  The library side of
``surfgen export``.
"""

from __future__ import annotations

import importlib.util
import json
import logging
import math
import os
import shlex
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from surfgen.filters.cleanup import (
    MAX_TARGET_FACES,
    CleanupOptions,
    CleanupResult,
    StepReport,
    refine_mesh,
    repair_mesh,
)
from surfgen.filters.metrics import Metrics, measure_mesh
from surfgen.generator.errors import SurfgenError
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.files import write_all_atomic
from surfgen.generator.formula.limits import (
    MAX_JSON_DEPTH,
    MAX_SPEC_FILE_BYTES,
    check_memory,
    estimate_memory,
    json_depth_ok,
    read_text_file,
)
from surfgen.generator.mesh.exchange import encode_mesh, load_mesh
from surfgen.generator.mesh.formats import EXPORT_FORMATS, FORMATS, MARKABLE, PRINTABLE
from surfgen.generator.mesh.mesh import CAP, WALL_KINDS, Mesh, face_areas, wall_fraction
from surfgen.generator.mesh.realise import EVALUATOR_CHOICES, realise, resolve_evaluator
from surfgen.generator.mesh.walls import WALL_MODES
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.store import DEFAULT_CATALOGUE, now, open_catalogue
from surfgen.pipelines.run.sampling import versions

log = logging.getLogger(__name__)

MAX_INPUTS = 10_000
GRID_WARNING = (
    "shapes whose look depends on the grid (the paper's Figure 3: one formula and box give "
    "different shapes on 34^3 and 33^3) will change"
)


class ExportError(SurfgenError):
    """An export that cannot be done as asked (bad option, refused shape, clashing names...)."""


@dataclass(frozen=True)
class ExportOptions:
    """How to export.  ``cleanup.target_edge`` is in output units: millimetres with ``size``,
    box units without.  ``size`` is the longest bbox side wanted; ``regrid`` re-evaluates the
    formula on ``regrid``³ points; ``force`` writes printable formats that fail the checks.
    ``walls``: keep (the solid), remove (only the zero set: open sheets, no caps, holes left
    open) or mark (walls labelled; PLY and GLB only).  ``evaluator``: how a formula is meshed
    (``auto`` is sparse on large grids); every evaluator makes the same mesh, so it is not
    part of :meth:`to_dict`."""

    format: str = "stl"
    cleanup: CleanupOptions = field(default_factory=CleanupOptions)
    size: float | None = None
    regrid: int | None = None
    force: bool = False
    walls: str = "keep"
    evaluator: str = "auto"

    def __post_init__(self) -> None:
        fmt = self.format.lower().lstrip(".")
        if fmt not in EXPORT_FORMATS:
            raise ExportError(
                f"unknown format '{self.format}' (allowed: {', '.join(EXPORT_FORMATS)})"
            )
        object.__setattr__(self, "format", fmt)
        if self.walls not in WALL_MODES:
            raise ExportError(
                f"unknown --walls mode '{self.walls}' (allowed: {', '.join(WALL_MODES)})"
            )
        if self.walls == "mark" and fmt not in MARKABLE:
            raise ExportError(
                f"--walls mark labels faces, which {fmt} cannot store: use --format "
                f"{' or '.join(MARKABLE)}"
            )
        if self.walls == "remove":  # the zero set is open on purpose: do not fill its holes
            object.__setattr__(self, "cleanup", replace(self.cleanup, max_hole_edges=0))
        if self.size is not None and not (math.isfinite(self.size) and self.size > 0):
            raise ExportError(f"--size must be a positive number of millimetres, got {self.size}")
        if self.regrid is not None:
            Grid(Box.cube(1.0), (self.regrid,) * 3)  # GridError for a size out of range
        if self.evaluator not in EVALUATOR_CHOICES:
            raise ExportError(
                f"unknown --evaluator '{self.evaluator}' (allowed: {', '.join(EVALUATOR_CHOICES)})"
            )

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": self.format,
            "size": self.size,
            "regrid": self.regrid,
            "force": self.force,
            "walls": self.walls,
            "cleanup": self.cleanup.to_dict(),
        }


@dataclass(frozen=True)
class Source:
    """One resolved input: a catalogue entry, a spec file or a mesh file."""

    argument: str
    kind: str  # "catalogue" | "spec" | "mesh"
    name: str  # file stem of the outputs
    key: str | None = None
    spec: SurfaceSpec | None = None
    mesh_file: Path | None = None
    catalogue: Path | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "argument": self.argument,
            "catalogue": None if self.catalogue is None else str(self.catalogue),
            "mesh_file": None if self.mesh_file is None else str(self.mesh_file),
        }


@dataclass(frozen=True)
class Prepared:
    """A cleaned mesh ready to write, and everything the sidecar says about it."""

    source: Source
    mesh: Mesh
    cleanup: CleanupResult
    before: Metrics
    after: Metrics
    scale: float
    problems: tuple[str, ...]
    warnings: tuple[str, ...]
    seconds: float
    walls: str = "keep"


@dataclass(frozen=True)
class ExportResult:
    prepared: Prepared
    file: Path
    sidecar: Path

    def summary(self) -> dict[str, Any]:
        """The JSON object ``surfgen export --json`` prints for this file."""
        p = self.prepared
        return {
            "input": p.source.argument,
            "key": p.source.key,
            "file": str(self.file),
            "sidecar": str(self.sidecar),
            "faces_before": p.before.faces,
            "faces_after": p.after.faces,
            "watertight": p.after.watertight,
            "manifold": p.after.nonmanifold_edges == 0 and p.after.nonmanifold_vertices == 0,
            "genus": p.after.genus,
            "components": p.after.components,
            "bbox": list(p.after.bbox),
            "scale": p.scale,
            "walls": p.walls,
            "wall_fraction": wall_fraction(p.mesh),
            "problems": list(p.problems),
            "warnings": list(p.warnings),
            "steps": p.cleanup.to_dict(),
            "seconds": round(p.seconds, 3),
        }


# --- the library entry point ------------------------------------------------------------------


def export_shapes(
    inputs: Sequence[str],
    out_dir: Path,
    options: ExportOptions | None = None,
    catalogue: Path = DEFAULT_CATALOGUE,
    progress: Callable[[int, int, str], None] | None = None,
    max_memory: int | None = None,
) -> list[ExportResult]:
    """Export every input (key, unique key prefix, spec ``.json`` or mesh file) into ``out_dir``.

    Nothing is written unless every input resolves and, for STL and 3MF, every result is
    watertight and manifold (or ``options.force``).  Raises :class:`ExportError`,
    ``CatalogueError`` (unknown key, ambiguous prefix), ``MeshError``, ``SpecError``...
    """
    options = options or ExportOptions()
    if not inputs:
        raise ExportError("give at least one key, key prefix, spec file or mesh file")
    needs = FORMATS[options.format].needs
    if needs is not None and importlib.util.find_spec(needs) is None:
        raise ExportError(
            f"{options.format.upper()} export needs the {needs} package (pip install {needs})"
        )
    if len(inputs) > MAX_INPUTS:
        raise ExportError(f"at most {MAX_INPUTS} inputs per export, got {len(inputs)}")
    sources = resolve_sources(inputs, Path(catalogue))
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ExportError(f"output folder {out_dir} is a file")
    _check_names(sources, out_dir, options.format)
    for s in sources:  # refuse before any work, not after the first shapes
        if s.spec is not None and (options.regrid is not None or not _has_mesh(s)):
            n = options.regrid if options.regrid is not None else None
            grid = Grid(Box.from_bounds(s.spec.box), (n,) * 3) if n else s.spec.to_grid()
            sparse = resolve_evaluator(options.evaluator, grid) == "sparse"
            check_memory(
                estimate_memory(grid.size, mesh=True, cleanup=True, sparse=sparse),
                max_memory,
                f"exporting {s.name} on a {n or 'x'.join(map(str, s.spec.grid))}"
                f"{'^3' if n else ''} grid",
            )
    prepared = []
    for i, s in enumerate(sources):
        if progress is not None:
            progress(i, len(sources), s.name)
        prepared.append(prepare_export(s, options))
    if progress is not None:
        progress(len(sources), len(sources), "")
    refused = [p for p in prepared if p.problems]
    if refused and not options.force:
        first = refused[0]
        more = f" ({len(refused) - 1} more refused)" if len(refused) > 1 else ""
        raise ExportError(
            f"{first.source.name}: not printable as {options.format}: "
            f"{'; '.join(first.problems)}{more}; nothing written (--force writes it anyway)"
        )
    files = [_encode(p, out_dir, options) for p in prepared]
    created = not out_dir.exists()
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ExportError(f"cannot create output folder {out_dir}: {exc.strerror}") from None
    try:
        # exported files are for handing on: 0644 whatever the umask
        write_all_atomic([item for pair, _ in files for item in pair], mode=0o644)
    except OSError:
        if created:  # all or nothing: not even an empty folder
            out_dir.rmdir()
        raise
    log.info("wrote %d files into %s", 2 * len(files), out_dir)
    return [result for _, result in files]


def _has_mesh(source: Source) -> bool:
    return source.mesh_file is not None and source.mesh_file.is_file()


def resolve_sources(inputs: Sequence[str], catalogue: Path) -> list[Source]:
    """Classify and resolve the inputs, in order, without duplicates.

    ``*.json`` is a spec file (or an export sidecar); a name with a mesh suffix, a path or an
    existing file is a mesh file; anything else is a catalogue key or unique key prefix.
    """
    sources: list[Source] = []
    keys = [a for a in inputs if _kind(a) == "catalogue"]
    rows: dict[str, Source] = {}
    if keys:
        with open_catalogue(catalogue, readonly=True) as cat:
            for arg in keys:
                key = cat.resolve(arg)
                row = cat.shape(key)
                mesh_path = row.get("mesh_path")
                rows[arg] = Source(
                    argument=arg,
                    kind="catalogue",
                    name=key,
                    key=key,
                    spec=SurfaceSpec.from_json(row["spec"]),
                    mesh_file=cat.root / mesh_path if mesh_path else None,
                    catalogue=cat.root,
                )
    for arg in inputs:
        kind = _kind(arg)
        if kind == "catalogue":
            source = rows[arg]
        elif kind == "spec":
            spec = read_spec_or_sidecar(Path(arg))
            source = Source(arg, "spec", Path(arg).stem, key=spec.key, spec=spec)
        else:
            source = Source(arg, "mesh", Path(arg).stem, mesh_file=Path(arg))
        if all((s.kind, s.name) != (source.kind, source.name) for s in sources):
            sources.append(source)
    return sources


def read_spec_or_sidecar(path: Path) -> SurfaceSpec:
    """A spec from a spec file (``SurfaceSpec.to_json``) or from an export sidecar's ``spec``."""

    text = read_text_file(Path(path), MAX_SPEC_FILE_BYTES, "spec file")
    if not json_depth_ok(text):
        raise ExportError(f"{path}: JSON nested more than {MAX_JSON_DEPTH} levels deep")
    try:
        data = json.loads(text, parse_constant=_no_json_constant)
    except json.JSONDecodeError as exc:
        raise ExportError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    if isinstance(data, dict) and "spec" in data and "box" not in data:  # a sidecar
        if data["spec"] is None:
            raise ExportError(f"{path}: this export came from a mesh file and has no spec")
        data = data["spec"]
    if not isinstance(data, dict):
        raise ExportError(f"{path}: expected a JSON object")
    return SurfaceSpec.from_dict(data)


def _no_json_constant(name: str) -> float:
    raise json.JSONDecodeError(f"{name} is not a JSON number", name, 0)


def load_source(
    source: Source, regrid: int | None = None, walls: str = "keep", evaluator: str = "auto"
) -> tuple[Mesh, list[str]]:
    """The mesh to clean and any warnings: the stored mesh, or the spec meshed with caps.

    With ``walls`` other than keep a formula is meshed again with its crossings classified
    (:func:`surfgen.generator.mesh.walls.extract_labelled`); a mesh file must then carry the labels
    of ``--walls mark``.
    """
    warnings: list[str] = []
    if source.spec is None:
        if regrid is not None:
            raise ExportError(f"--regrid needs a formula: '{source.argument}' is a mesh file")
        mesh = load_mesh(source.mesh_file)  # type: ignore[arg-type]
        if walls == "keep":
            return mesh, warnings
        if mesh.face_kinds is None:
            raise ExportError(
                f"--walls {walls} needs a formula, or a mesh written with --walls mark: "
                f"'{source.argument}' has no wall labels"
            )
        if walls == "mark":
            return mesh, warnings
        return _without_walls(mesh, source.argument), warnings
    spec = source.spec
    grid = spec.to_grid()
    if regrid is not None:
        grid = Grid(Box.from_bounds(spec.box), (regrid,) * 3)
        old = "x".join(map(str, spec.grid))
        coarser = " (a coarser grid)" if regrid < max(spec.grid) else ""
        warnings.append(
            f"{source.name}: re-evaluated on {regrid}^3 instead of {old}{coarser}; {GRID_WARNING}"
        )
    elif source.kind == "catalogue" and source.mesh_file is not None and walls == "keep":
        if source.mesh_file.is_file():
            return load_mesh(source.mesh_file), warnings
        warnings.append(f"{source.name}: mesh file {source.mesh_file} is missing, regenerated")
    for w in warnings:
        log.info("%s", w)  # the CLI prints the warnings it gets back
    made = realise(spec, grid=grid, evaluator=evaluator, cap=True, walls=walls)
    return made.mesh, warnings  # type: ignore[return-value]


def _without_walls(mesh: Mesh, name: str) -> Mesh:
    """A marked mesh without its wall and cap faces (what ``--walls remove`` makes)."""
    keep = ~np.isin(mesh.face_kinds, (*WALL_KINDS, CAP))
    if not keep.any():
        raise ExportError(f"{name}: every face is a wall or a cap: --walls remove leaves nothing")
    used = np.zeros(mesh.n_vertices, dtype=bool)
    faces = mesh.faces[keep]
    used[faces.reshape(-1)] = True
    renumber = np.cumsum(used) - 1
    return Mesh(mesh.vertices[used], renumber[faces], mesh.face_kinds[keep])


def _transfer_kinds(labelled: Mesh, target: Mesh) -> Mesh:
    """``target`` with the face kinds of the nearest face (by centroid) of ``labelled``.

    Cleanup and remeshing make new faces; each takes the kind of the labelled face closest to
    its centroid, which keeps walls and roots apart (they meet only along their common rims).
    """
    from scipy.spatial import cKDTree

    if labelled.face_kinds is None or target.n_faces == 0:
        return target
    source = labelled.vertices[labelled.faces].mean(axis=1)
    centres = target.vertices[target.faces].mean(axis=1)
    _, nearest = cKDTree(source).query(centres)
    return Mesh(target.vertices, target.faces, labelled.face_kinds[nearest])


def prepare_export(source: Source, options: ExportOptions) -> Prepared:
    """Load, clean, remesh, smooth and scale one input; measure before and after."""
    start = time.perf_counter()
    mesh, warnings = load_source(source, options.regrid, options.walls, options.evaluator)
    before = measure_mesh(mesh)
    result = repair_mesh(mesh, options.cleanup)
    cleanup = options.cleanup
    if options.size is not None and cleanup.target_edge is not None:
        # The target is in millimetres: convert with the scale the repaired mesh would get.
        estimate = options.size / longest_side(result.mesh)
        cleanup = replace(cleanup, target_edge=cleanup.target_edge / estimate)
    if cleanup.target_edge is not None:  # a tiny edge would ask for billions of faces
        area = float(face_areas(result.mesh).sum())
        faces = area / (0.433 * cleanup.target_edge**2)  # equilateral triangles of that edge
        if faces > MAX_TARGET_FACES:
            raise ExportError(
                f"{source.name}: --target-edge {options.cleanup.target_edge:g} would make about "
                f"{faces:.3g} faces (at most {MAX_TARGET_FACES}); choose a longer edge"
            )
    result = result.then(refine_mesh(result.mesh, cleanup))
    final, scale = result.mesh, 1.0
    if options.size is not None:
        final, step = _scale_to(final, options.size)
        scale = step.details["factor"]
        result = CleanupResult(final, (*result.steps, step))
    if options.walls == "mark":
        final = _transfer_kinds(Mesh(mesh.vertices * scale, mesh.faces, mesh.face_kinds), final)
    after = measure_mesh(final)
    problems = printability_problems(after) if options.format in PRINTABLE else []
    log.info("%s: %d -> %d faces", source.name, before.faces, after.faces)
    return Prepared(
        source,
        final,
        result,
        before,
        after,
        scale,
        tuple(problems),
        tuple(warnings),
        time.perf_counter() - start,
        options.walls,
    )


def printability_problems(m: Metrics) -> list[str]:
    """Why a mesh is not fit to print (empty when watertight, manifold and oriented)."""
    problems = []
    if m.boundary_edges:
        problems.append(f"not watertight ({m.boundary_edges} boundary edges: the surface is open)")
    if m.nonmanifold_edges:
        problems.append(f"not manifold ({m.nonmanifold_edges} edges with more than two faces)")
    if m.nonmanifold_vertices:
        problems.append(f"not manifold ({m.nonmanifold_vertices} non-manifold vertices)")
    if not problems and not m.closed:
        problems.append("faces not consistently oriented")
    return problems


# --- helpers ------------------------------------------------------------------------------------


def _kind(arg: str) -> str:
    path = Path(arg)
    if path.suffix.lower() == ".json":
        return "spec"
    # Keys are bare hex digits: anything with a suffix, a folder or on disk is a mesh file
    # (load_mesh names the allowed suffixes, MESH_SUFFIXES, when it is not one).
    if path.suffix or os.sep in arg or path.exists():
        return "mesh"
    return "catalogue"


def _check_names(sources: list[Source], out_dir: Path, fmt: str) -> None:
    """Refuse two inputs writing one file, or an output overwriting its own input."""
    seen: dict[str, str] = {}
    for s in sources:
        if s.name in seen:
            raise ExportError(
                f"'{seen[s.name]}' and '{s.argument}' would both write {s.name}.{fmt}: "
                "export them into different folders"
            )
        seen[s.name] = s.argument
        inputs = [Path(s.argument)] + ([s.mesh_file] if s.mesh_file else [])
        for out in (out_dir / f"{s.name}.{fmt}", out_dir / f"{s.name}.json"):
            if any(_same_file(out, i) for i in inputs):
                raise ExportError(f"{out} would overwrite its own input: choose another -o folder")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def longest_side(mesh: Mesh) -> float:
    extent = mesh.vertices.max(axis=0) - mesh.vertices.min(axis=0)
    return float(extent.max())


def _scale_to(mesh: Mesh, size: float) -> tuple[Mesh, StepReport]:
    """Multiply coordinates so that the longest bbox side is ``size`` (about the origin)."""
    start = time.perf_counter()
    longest = longest_side(mesh)
    if longest <= 0:
        raise ExportError("cannot scale a flat mesh (its bounding box has no extent)")
    factor = size / longest
    out = Mesh(mesh.vertices * factor, mesh.faces, mesh.face_kinds)
    report = StepReport(
        "scale",
        mesh.n_vertices,
        out.n_vertices,
        mesh.n_faces,
        out.n_faces,
        time.perf_counter() - start,
        {"factor": factor, "longest_side": size},
    )
    return out, report


def _encode(
    p: Prepared, out_dir: Path, options: ExportOptions
) -> tuple[list[tuple[Path, bytes]], ExportResult]:
    """The mesh file and its sidecar, in memory: every export is written all or nothing."""
    name = p.source.name
    path = out_dir / f"{name}.{options.format}"
    sidecar = out_dir / f"{name}.json"
    text = json.dumps(_sidecar(p, path, options, out_dir), indent=2, default=jsonable) + "\n"
    data = encode_mesh(p.mesh, options.format)
    return [(path, data), (sidecar, text.encode())], ExportResult(p, path, sidecar)


def _sidecar(p: Prepared, path: Path, options: ExportOptions, out_dir: Path) -> dict[str, Any]:
    spec = p.source.spec
    return {
        "file": path.name,
        "format": options.format,
        "units": "millimeter" if options.format in PRINTABLE else None,
        "key": p.source.key,
        "formula": None if spec is None else spec.formula,
        "spec": None if spec is None else spec.to_dict(),
        "source": p.source.to_dict(),
        "options": options.to_dict(),
        "scale": p.scale,
        "steps": p.cleanup.to_dict(),
        "metrics": {"before": p.before.to_dict(), "after": p.after.to_dict()},
        "wall_fraction": wall_fraction(p.mesh),
        "problems": list(p.problems),
        "warnings": list(p.warnings),
        "versions": _versions(options.format),
        "command": _command(p.source, options, out_dir),
        "created": now(),
    }


def _versions(fmt: str) -> dict[str, str]:
    from importlib import metadata

    out = versions()
    needs = FORMATS[fmt].needs
    if needs is not None:
        out[needs] = metadata.version(needs)
    return out


def _command(source: Source, options: ExportOptions, out_dir: Path) -> str:
    """The ``surfgen export`` call that makes this file again."""
    c = options.cleanup
    args = ["surfgen", "export", source.argument if source.kind != "catalogue" else source.key]
    if source.kind == "catalogue":
        args += ["--catalogue", str(source.catalogue)]
    args += ["--format", options.format, "--min-component", repr(c.min_component)]
    if c.remeshing:
        args.append("--remesh")
    if c.target_edge is not None:
        args += ["--target-edge", repr(c.target_edge)]
    if c.target_faces is not None:
        args += ["--target-faces", str(c.target_faces)]
    if c.smooth:
        args += ["--smooth", str(c.smooth)]
    if options.size is not None:
        args += ["--size", repr(options.size)]
    if options.regrid is not None:
        args += ["--regrid", str(options.regrid)]
    if options.walls != "keep":
        args += ["--walls", options.walls]
    if options.force:
        args.append("--force")
    args += ["-o", str(out_dir)]
    return shlex.join(str(a) for a in args)


def jsonable(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    return str(value)


# --- the command --------------------------------------------------------------------------------
