"""MathMod and K3DSurf interop: ``render --mathmod``, ``surfgen import mathmod``, and scripts for
``export --format mathmod|k3dsurf`` (the format is :mod:`surfgen.generator.interop.mathmod`)."""

from __future__ import annotations

import json
import logging
import re
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from surfgen.generator.errors import EmptySurface, SpecError
from surfgen.generator.files import write_all_atomic
from surfgen.generator.formula.expr import substitute_params, to_string
from surfgen.generator.interop.builtins import expand_builtins
from surfgen.generator.interop.mathmod import (
    Model,
    build_model,
    load_model,
    model_names,
    read_script,
    to_script,
)
from surfgen.generator.mesh.formats import MESH_SUFFIXES
from surfgen.generator.model.spec import SurfaceSpec

if TYPE_CHECKING:  # the mesh module (trimesh, scikit-image, numba) loads when a mesh does
    from surfgen.generator.mesh.mesh import Mesh

log = logging.getLogger(__name__)

SCRIPT_FORMATS = ("mathmod", "k3dsurf")


def read_model(
    path: Path,
    name: str | None = None,
    *,
    slider: int | None = None,
    params: Mapping[str, float] | None = None,
    grid: int | None = None,
) -> Model:
    """The model ``name`` of the MathMod script at ``path``; notices go to the log."""
    model = load_model(read_script(path), name, slider_set=slider, params=params, grid=grid)
    for notice in model.notices:
        log.warning("%s: %s", model.name, notice)
    return model


def render_model(
    model: Model,
    *,
    component: str | None = None,
    box: Sequence[float] | None = None,
    grid: Sequence[int] | None = None,
    level: float | None = None,
    cap: bool = False,
    evaluator: str = "fast",
    mesh_path: Path | None = None,
    png_path: Path | None = None,
) -> dict[str, Any]:
    """Evaluate each component (or the chosen one) in its own box, mesh them into one mesh,
    write what is asked; returns the JSON summary ``render --json`` prints."""
    from surfgen.generator.mesh.exchange import encode_mesh, mesh_format
    from surfgen.generator.mesh.realise import realise
    from surfgen.pipelines.export.render import build_spec, check_output_path

    if mesh_path is not None:
        check_output_path(Path(mesh_path), MESH_SUFFIXES, "mesh file")
    if png_path is not None:
        check_output_path(Path(png_path), (".png",), "picture")
    chosen = [model.component(component)] if component is not None else list(model.components)
    start = time.perf_counter()
    parts: list[Mesh] = []
    summaries = []
    nonfinite = 0
    for comp in chosen:
        spec = build_spec(base=comp.spec, box=box, grid=grid, level=level)
        made = realise(
            spec, evaluator=evaluator, cap=cap, allow_empty=len(chosen) > 1, keep_samples=False
        )
        nonfinite += made.field.nonfinite
        mesh = made.mesh
        if made.empty is not None:
            log.warning("component %s: %s", comp.name, made.empty)
        if mesh is not None:
            parts.append(mesh)
        summaries.append(
            {
                "component": comp.name,
                "key": spec.key,
                "formula": spec.formula,
                "box": list(spec.box),
                "grid": list(spec.grid),
                "params": dict(spec.params),
                "faces": None if mesh is None else mesh.n_faces,
            }
        )
    if not parts:
        raise EmptySurface(f"model {model.name}: no component has a surface in its box")
    mesh = merge_meshes(parts)
    # Both files made in memory, then written all or nothing (an older mesh is kept if the
    # picture cannot be written).
    outputs: dict[str, tuple[Path, bytes]] = {}
    if mesh_path is not None:
        outputs["mesh"] = (Path(mesh_path), encode_mesh(mesh, mesh_format(mesh_path)))
    if png_path is not None:
        from surfgen.pipelines.pictures.raster import png_bytes, render_image

        outputs["png"] = (Path(png_path), png_bytes(render_image(mesh, size=512)))
    write_all_atomic(list(outputs.values()))
    files = {kind: str(path) for kind, (path, _) in outputs.items()}
    return {
        "model": model.name,
        "description": model.description,
        "components": summaries,
        "vertices": mesh.n_vertices,
        "faces": mesh.n_faces,
        "nonfinite": nonfinite,
        "seconds": round(time.perf_counter() - start, 6),
        "files": files,
    }


def merge_meshes(parts: Sequence[Mesh]) -> Mesh:
    """One mesh holding every part (vertices are not merged: parts stay separate components)."""
    from surfgen.generator.mesh.mesh import Mesh

    offsets = np.cumsum([0] + [p.n_vertices for p in parts[:-1]])
    vertices = np.concatenate([p.vertices for p in parts])
    faces = np.concatenate([p.faces + o for p, o in zip(parts, offsets, strict=True)])
    return Mesh(vertices, faces)


# ----------------------------------------------------------------------------- import


def _stem(text: str) -> str:
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("._")
    return stem or "model"


def import_script(
    path: Path,
    out_dir: Path,
    *,
    name: str | None = None,
    slider: int | None = None,
    params: Mapping[str, float] | None = None,
) -> list[Path]:
    """Write one spec JSON per component of every Iso3D model (or of model ``name``) of the
    script into ``out_dir``; all files or none. Returns the paths."""

    models = read_script(path)
    names = model_names(models)
    if name is not None and name not in names:
        raise SpecError(f"no model '{name}' in the script (models: {', '.join(names)})")
    chosen = [m for m, n in zip(models, names, strict=True) if (name is None or n == name)]
    implicit = [m for m in chosen if "Iso3D" in m]
    if not implicit:
        load_model(chosen, None)  # raises the "not supported: parametric" message
    written: dict[Path, bytes] = {}
    for raw in implicit:
        model = build_model(raw, slider_set=slider, params=params)
        for notice in model.notices:
            log.warning("%s: %s", model.name, notice)
        single = len(model.components) == 1
        for comp in model.components:
            stem = _stem(model.name if single else f"{model.name}-{comp.name}")
            target = Path(out_dir) / f"{stem}.json"
            if target in written:
                raise SpecError(f"two models would both be written to {target.name}")
            written[target] = (comp.spec.to_json() + "\n").encode()
    return write_all(Path(out_dir), written)


def write_all(out_dir: Path, files: Mapping[Path, bytes]) -> list[Path]:
    """Write every file or none (:func:`write_all_atomic`: a file that was there before and
    would have been replaced is put back if a later one fails)."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        return write_all_atomic(list(files.items()))
    except OSError as exc:
        raise SpecError(f"cannot write {exc.filename or out_dir}: {exc.strerror}") from None


# ----------------------------------------------------------------------------- export


def script_bytes(
    fmt: str, name: str, specs: Sequence[tuple[str, SurfaceSpec]], note: str = ""
) -> bytes:
    """The text of a MathMod script (JSON) or a K3DSurf formula file for ``specs``."""
    if fmt == "mathmod":
        return (json.dumps(to_script(specs, name, note), indent=2) + "\n").encode()
    if fmt == "k3dsurf":
        return k3dsurf_text(name, specs).encode()
    raise SpecError(f"unknown script format '{fmt}' (allowed: {', '.join(SCRIPT_FORMATS)})")


def k3dsurf_text(name: str, specs: Sequence[tuple[str, SurfaceSpec]]) -> str:
    """K3DSurf's implicit-surface fields, one block per component, constants substituted
    (K3DSurf has no named constants)."""

    lines = [f"# K3DSurf implicit surface: {name}", "# written by surfgen"]
    for comp, spec in specs:
        tree = substitute_params(expand_builtins(spec.tree(), spec.params), spec.params)
        xmin, xmax, ymin, ymax, zmin, zmax = spec.box
        nx, ny, nz = spec.grid
        lines += [
            "",
            f"[{comp}]",
            f"F(x,y,z) = {to_string(tree)}",
            f"X = [{xmin!r}, {xmax!r}]",
            f"Y = [{ymin!r}, {ymax!r}]",
            f"Z = [{zmin!r}, {zmax!r}]",
            f"Grid = [{nx}, {ny}, {nz}]",
        ]
    return "\n".join(lines) + "\n"


SCRIPT_SUFFIX = {"mathmod": ".mathmod.json", "k3dsurf": ".k3dsurf.txt"}


def export_scripts(inputs: Sequence[str], out_dir: Path, fmt: str, catalogue: Path) -> list[Path]:
    """One script per input (catalogue key or prefix, or spec file) in ``out_dir``; all or none."""
    from surfgen.pipelines.export.sources import resolve_sources

    fmt = fmt.lower()
    if fmt not in SCRIPT_FORMATS:
        raise SpecError(f"unknown script format '{fmt}' (allowed: {', '.join(SCRIPT_FORMATS)})")
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise SpecError(f"--output {out_dir} exists and is not a folder")
    files: dict[Path, bytes] = {}
    for source in resolve_sources(inputs, catalogue):
        if source.spec is None:
            raise SpecError(
                f"{source.argument}: a mesh file has no formula; --format {fmt} needs catalogue "
                "keys or spec files"
            )
        files[out_dir / f"{source.name}{SCRIPT_SUFFIX[fmt]}"] = script_bytes(
            fmt, source.name, [(source.name, source.spec)]
        )
    return write_all(out_dir, files)


__all__ = [
    "SCRIPT_FORMATS",
    "import_script",
    "k3dsurf_text",
    "merge_meshes",
    "read_model",
    "render_model",
    "script_bytes",
]
