"""Render one shape: spec → field → mesh → files. The library side of ``surfgen render``."""

from __future__ import annotations

import io
import logging
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from surfgen.generator.errors import SpecError, SurfgenError
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Field, Grid
from surfgen.generator.eval.sparse import SparseField
from surfgen.generator.files import write_all_atomic, write_atomic
from surfgen.generator.formula.limits import (
    MAX_SPEC_FILE_BYTES,
    MemoryBudget,
    estimate_memory,
    read_text_file,
)
from surfgen.generator.mesh.exchange import encode_mesh, mesh_format
from surfgen.generator.mesh.formats import FORMATS, MESH_SUFFIXES
from surfgen.generator.mesh.mesh import Mesh
from surfgen.generator.mesh.realise import StageProgress, realise, resolve_evaluator
from surfgen.generator.mesh.walls import WallReport, check_walls_mode
from surfgen.generator.model.presets import get_preset
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.pictures.raster import png_bytes, render_image

log = logging.getLogger(__name__)

DEFAULT_BOX = (-2.0, 2.0)
DEFAULT_GRID = 64
# Mesh files meant for printing (they must hold a closed solid), and the others.
PRINTABLE_SUFFIXES = tuple(s for s in MESH_SUFFIXES if FORMATS[s[1:]].printable)
OPEN_SUFFIXES = tuple(s for s in MESH_SUFFIXES if s not in PRINTABLE_SUFFIXES)


@dataclass(frozen=True)
class RenderResult:
    spec: SurfaceSpec
    field: Field | SparseField
    mesh: Mesh | None
    seconds: float
    files: Mapping[str, str]
    walls: str = "keep"
    crossings: WallReport | None = None
    evaluator: str = "fast"

    def summary(self) -> dict[str, Any]:
        """The JSON object ``surfgen render --json`` prints."""
        return {
            "key": self.spec.key,
            "formula": self.spec.formula,
            "box": list(self.spec.box),
            "grid": list(self.spec.grid),
            "level": self.spec.level,
            "params": dict(self.spec.params),
            "vertices": None if self.mesh is None else self.mesh.n_vertices,
            "faces": None if self.mesh is None else self.mesh.n_faces,
            "nonfinite": self.field.nonfinite,
            "evaluator": self.evaluator,
            "walls": self.walls,
            "wall_fraction": None if self.crossings is None else self.crossings.wall_fraction,
            "crossings": None if self.crossings is None else self.crossings.to_dict(),
            "seconds": round(self.seconds, 6),
            "files": dict(self.files),
        }


def build_spec(
    *,
    preset: str | None = None,
    formula: str | None = None,
    spec_file: Path | None = None,
    base: SurfaceSpec | None = None,
    params: Mapping[str, float] | None = None,
    box: Sequence[float] | None = None,
    grid: Sequence[int] | None = None,
    level: float | None = None,
) -> SurfaceSpec:
    """The spec a ``render`` call describes: exactly one source (a preset, a formula, a spec
    file, or ``base``: a spec already at hand, e.g. from the catalogue), then overrides."""
    sources = [s for s in (preset, formula, spec_file, base) if s is not None]
    if len(sources) != 1:
        raise SpecError("give exactly one of --preset, --formula, --spec or --from")
    params = dict(params or {})
    if preset is not None:
        spec = get_preset(preset).spec(params)
    elif spec_file is not None or base is not None:
        spec = base if base is not None else read_spec(spec_file)  # type: ignore[arg-type]
        if params:
            unknown = sorted(set(params) - set(spec.params))
            if unknown:
                raise SpecError(f"the spec has no parameter '{unknown[0]}'")
            spec = spec.replace(params={**spec.params, **params})
    else:
        spec = SurfaceSpec(
            formula=formula,  # type: ignore[arg-type]
            box=Box.from_bounds(box or DEFAULT_BOX).bounds(),
            grid=Grid.from_sizes(Box.cube(1), list(grid or [DEFAULT_GRID])).shape,
            params=params,
        )
    changes: dict[str, Any] = {}
    if box is not None:
        changes["box"] = Box.from_bounds(box).bounds()
    if grid is not None:
        changes["grid"] = Grid.from_sizes(Box.cube(1), list(grid)).shape
    if level is not None:
        changes["level"] = float(level)
    return spec.replace(**changes) if changes else spec


def read_spec(path: Path) -> SurfaceSpec:
    """The spec in a JSON file (at most :data:`MAX_SPEC_FILE_BYTES`). Raises :class:`SpecError`."""
    return SurfaceSpec.from_json(read_text_file(path, MAX_SPEC_FILE_BYTES, "spec file"))


def check_output_path(path: Path, suffixes: Sequence[str], what: str) -> None:
    """Fail before any work if ``path`` has the wrong suffix or an unwritable folder."""
    if path.suffix.lower() not in suffixes:
        raise SpecError(
            f"{what} {path}: unknown format '{path.suffix}' (allowed: {', '.join(suffixes)})"
        )
    if path.is_dir():
        raise SpecError(f"{what} {path} is a folder, not a file name")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise SpecError(f"{what} {path}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise SpecError(f"{what} {path}: folder {parent} is not writable")


def save_field(field: Field, path: Path) -> None:
    """Write the float64 field (shape (Nx, Ny, Nz)) as .npy, atomically."""
    write_atomic(path, field_bytes(field))


def field_bytes(field: Field) -> bytes:
    """The .npy file of the float64 field, in memory."""
    buf = io.BytesIO()
    np.save(buf, np.asarray(field.values, dtype=np.float64))
    return buf.getvalue()


def render_spec(
    spec: SurfaceSpec,
    *,
    cap: bool = False,
    evaluator: str = "auto",
    mesh_path: Path | None = None,
    field_path: Path | None = None,
    png_path: Path | None = None,
    walls: str = "keep",
    force: bool = False,
    max_memory: int | None = None,
    progress: StageProgress | None = None,
) -> RenderResult:
    """Evaluate, mesh and write what was asked.

    Every mesh's crossings are classified (:mod:`surfgen.generator.mesh.walls`): ``walls="keep"``
    keeps the solid's whole boundary, ``"mark"`` labels walls (colours in PLY/GLB and in the
    picture), ``"remove"`` keeps only the zero set (open, no caps): an STL of it is refused
    unless ``force``.  With ``field_path`` and neither ``mesh_path`` nor ``png_path`` no mesh
    is extracted.  ``max_memory`` (bytes; None: the machine's available memory) refuses a grid
    whose estimated memory is larger, before anything is allocated.  ``evaluator``: ``fast``,
    ``reference``, ``sparse`` or ``auto`` (sparse on large grids:
    :func:`~surfgen.generator.mesh.realise.resolve_evaluator`; a field file needs every sample,
    so ``auto`` evaluates densely then; every evaluator makes the same mesh).  ``progress``:
    each stage as it starts (:func:`~surfgen.generator.mesh.realise.realise`'s, then
    ``writing``).  Raises
    :class:`SurfgenError` subclasses (e.g. ``EmptySurface``, ``LimitError``); on error no file
    is written.
    """
    check_walls_mode(walls)
    if mesh_path is not None:
        check_output_path(Path(mesh_path), MESH_SUFFIXES, "mesh file")
        if walls == "remove" and Path(mesh_path).suffix.lower() in PRINTABLE_SUFFIXES and not force:
            raise SpecError(
                f"mesh file {mesh_path}: --walls remove leaves open sheets, which a printable "
                f"format ({', '.join(PRINTABLE_SUFFIXES)}) cannot hold as a solid; "
                f"write {'/'.join(OPEN_SUFFIXES)}, or --force"
            )
    if field_path is not None:
        check_output_path(Path(field_path), (".npy",), "field file")
    if png_path is not None:
        check_output_path(Path(png_path), (".png",), "picture")
    want_mesh = mesh_path is not None or png_path is not None or field_path is None
    grid = spec.to_grid()
    name = resolve_evaluator(evaluator, grid)
    if field_path is not None and name == "sparse":
        if evaluator == "sparse":
            raise SpecError(
                "--save-field writes every sample, which the sparse evaluator does not make; "
                "use --evaluator auto, fast or reference"
            )
        name = "fast"
    what = f"render on a {'x'.join(map(str, grid.shape))} grid ({name} evaluator)"
    parts = estimate_memory(
        grid.size, mesh=want_mesh, field_copy=field_path is not None, sparse=name == "sparse"
    )
    # the estimate now, then again as the sparse path learns the surface's size
    budget = MemoryBudget.after_estimate(parts, max_memory, what)
    start = time.perf_counter()
    mesh: Mesh | None = None
    crossings: WallReport | None = None
    if want_mesh:
        made = realise(spec, grid=grid, evaluator=name, cap=cap, walls=walls, keep_samples=False,
                       budget=budget, progress=progress)  # fmt: skip
        field, mesh, crossings = made.field, made.mesh, made.walls
    else:
        if progress is not None:
            progress("evaluating", None)
        field = evaluate(spec.tree(), grid, spec.params, evaluator=name)
    seconds = time.perf_counter() - start
    # Every file is made in memory first, then all are written together: a full disk or a
    # bad folder for one of them leaves none of them behind.
    if progress is not None:
        progress("writing", None)
    outputs: dict[str, tuple[Path, bytes]] = {}
    if field_path is not None and isinstance(field, Field):
        outputs["field"] = (Path(field_path), field_bytes(field))
    if mesh is not None and mesh_path is not None:
        outputs["mesh"] = (Path(mesh_path), encode_mesh(mesh, mesh_format(mesh_path)))
    if mesh is not None and png_path is not None:
        outputs["png"] = (Path(png_path), png_bytes(render_image(mesh, size=512)))
    write_all_atomic(list(outputs.values()))
    files = {kind: str(path) for kind, (path, _) in outputs.items()}
    log.info("rendered %s in %.3f s", spec.key, seconds)
    return RenderResult(spec, field, mesh, seconds, files, walls, crossings, name)


__all__ = ["RenderResult", "SurfgenError", "build_spec", "render_spec", "read_spec", "save_field"]
