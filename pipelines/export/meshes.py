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
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.files import write_all_atomic
from surfgen.generator.formula.limits import (
    CLEANUP_MESH_COPIES,
    MemoryBudget,
    check_memory,
    estimate_memory,
)
from surfgen.generator.mesh.exchange import encode_mesh, load_mesh
from surfgen.generator.mesh.formats import EXPORT_FORMATS, FORMATS, MARKABLE, PRINTABLE
from surfgen.generator.mesh.mesh import CAP, WALL_KINDS, Mesh, face_areas, wall_fraction
from surfgen.generator.mesh.realise import (
    EVALUATOR_CHOICES,
    StageProgress,
    realise,
    resolve_evaluator,
)
from surfgen.generator.mesh.walls import WALL_MODES
from surfgen.pipelines.catalogue.store import DEFAULT_CATALOGUE, now
from surfgen.pipelines.export.sources import (
    ExportError,
    Source,
    has_mesh,
    resolve_sources,
)
from surfgen.pipelines.run.sampling import versions

log = logging.getLogger(__name__)

MAX_INPUTS = 10_000
GRID_WARNING = (
    "shapes whose look depends on the grid (the paper's Figure 3: one formula and box give "
    "different shapes on 34^3 and 33^3) will change"
)


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
        if s.spec is not None and (options.regrid is not None or not has_mesh(s)):
            n = options.regrid if options.regrid is not None else None
            grid = Grid(Box.from_bounds(s.spec.box), (n,) * 3) if n else s.spec.to_grid()
            sparse = resolve_evaluator(options.evaluator, grid) == "sparse"
            check_memory(
                estimate_memory(grid.size, mesh=True, cleanup=True, sparse=sparse),
                max_memory,
                f"exporting {s.name} on a {n or 'x'.join(map(str, s.spec.grid))}"
                f"{'^3' if n else ''} grid",
            )
    budget = MemoryBudget.begin(max_memory, "export", CLEANUP_MESH_COPIES)
    prepared = []
    for i, s in enumerate(sources):
        stage = None
        if progress is not None:
            progress(i, len(sources), s.name)
            stage = _stages(progress, i, len(sources), s.name)
        prepared.append(prepare_export(s, options, budget, stage))
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


def _stages(progress: Callable[[int, int, str], None], i: int, n: int, name: str) -> StageProgress:
    """The export's progress for input ``i`` of ``n``, its stage after its name."""
    return lambda stage, done: progress(i, n, f"{name}: {stage}")


def load_source(
    source: Source,
    regrid: int | None = None,
    walls: str = "keep",
    evaluator: str = "auto",
    budget: MemoryBudget | None = None,
    progress: StageProgress | None = None,
) -> tuple[Mesh, list[str]]:
    """The mesh to clean and any warnings: the stored mesh, or the spec meshed with caps.

    With ``walls`` other than keep a formula is meshed again with its crossings classified
    (:func:`surfgen.generator.mesh.walls.extract_labelled`); a mesh file must then carry the labels
    of ``--walls mark``. ``budget``: the export's memory, checked again as a sparse run learns
    the surface's size (:class:`~surfgen.generator.formula.limits.MemoryBudget`); ``progress``:
    the stages of meshing a formula (:func:`~surfgen.generator.mesh.realise.realise`).
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
    if budget is not None:
        shape = f"{regrid}^3" if regrid is not None else "x".join(map(str, spec.grid))
        budget = replace(budget, what=f"exporting {source.name} on a {shape} grid")
    made = realise(spec, grid=grid, evaluator=evaluator, cap=True, walls=walls, keep_samples=False,
                   budget=budget, progress=progress)  # fmt: skip
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


def prepare_export(
    source: Source,
    options: ExportOptions,
    budget: MemoryBudget | None = None,
    progress: StageProgress | None = None,
) -> Prepared:
    """Load, clean, remesh, smooth and scale one input; measure before and after (``budget``,
    ``progress``: :func:`load_source`; then ``cleaning``)."""
    start = time.perf_counter()
    mesh, warnings = load_source(source, options.regrid, options.walls, options.evaluator,
                                 budget, progress)  # fmt: skip
    if progress is not None:
        progress("cleaning", None)
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
