"""One shape at a time: ``surfgen render``, ``surfgen check`` (a mesh file) and ``surfgen presets``.

The evaluator, the mesher and the metrics (numba, trimesh, scikit-image) are imported when a
command runs, so that ``--help`` and the other commands do not load them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from surfgen import Catalogue
from surfgen.generator.allocator import one_shot_memory_policy
from surfgen.generator.errors import SpecError
from surfgen.generator.formula.limits import parse_size
from surfgen.generator.mesh.formats import MESH_SUFFIXES
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.store import CatalogueError
from surfgen.pipelines.cli.common import (
    EvaluatorOption,
    MaxMemoryOption,
    echo_err,
    emit_json,
    parse_numbers,
    parse_params,
    stage_bar,
)
from surfgen.pipelines.cli.interop import render_mathmod


def render(
    preset: Annotated[
        str | None, typer.Option(help="A preset name (see `surfgen presets`).")
    ] = None,
    formula: Annotated[
        str | None, typer.Option(help="A formula in K3DSurf/MathMod syntax.")
    ] = None,
    spec: Annotated[Path | None, typer.Option(help="A spec JSON file.")] = None,
    param: Annotated[list[str] | None, typer.Option(help="NAME=VALUE, repeatable.")] = None,
    box: Annotated[str | None, typer.Option(help="LO,HI or XMIN,XMAX,YMIN,YMAX,ZMIN,ZMAX.")] = None,
    grid: Annotated[
        str | None, typer.Option(help="N or NX,NY,NZ (points per axis, both ends).")
    ] = None,
    level: Annotated[float | None, typer.Option(help="Iso level (inside is F < level).")] = None,
    cap: Annotated[
        bool | None,
        typer.Option(
            "--cap/--no-cap", help="Close surfaces cut by the box (default: the preset's)."
        ),
    ] = None,
    output: Annotated[
        Path | None, typer.Option("-o", "--output", help=f"Mesh file {'/'.join(MESH_SUFFIXES)}.")
    ] = None,
    save_field: Annotated[
        Path | None, typer.Option(help="Write the float64 field to FIELD.npy.")
    ] = None,
    png: Annotated[Path | None, typer.Option(help="Write a shaded picture (PNG).")] = None,
    evaluator: EvaluatorOption = "auto",
    from_catalogue: Annotated[
        tuple[Path, str] | None,
        typer.Option("--from", help="CATALOGUE KEY: regenerate a catalogued shape."),
    ] = None,
    walls: Annotated[
        str,
        typer.Option(
            help="keep (the solid's whole boundary), remove (only the zero set: open sheets) "
            "or mark (label poles and jumps: colours in PLY/GLB and the picture)."
        ),
    ] = "keep",
    force: Annotated[
        bool, typer.Option("--force", help="Write an STL even with --walls remove (open).")
    ] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    max_memory: MaxMemoryOption = None,
    mathmod: Annotated[
        Path | None, typer.Option(help="A MathMod script: render its Iso3D model.")
    ] = None,
    name: Annotated[str | None, typer.Option(help="With --mathmod: the model's Name.")] = None,
    component: Annotated[
        str | None, typer.Option(help="With --mathmod: only this component.")
    ] = None,
    slider: Annotated[int | None, typer.Option(help="With --mathmod: slider set K.")] = None,
) -> None:
    """Evaluate one shape on its grid, extract F = level and write what is asked."""
    # Deferred (see the module's docstring): these load numba and trimesh.
    from surfgen.generator.model.presets import get_preset
    from surfgen.pipelines.export.render import build_spec, render_spec
    from surfgen.pipelines.run.warmup import compile_first

    one_shot_memory_policy()  # one shape, each step's arrays made once: its peak, no more
    limit = parse_size(max_memory) if max_memory is not None else None
    if mathmod is not None:
        render_mathmod(
            mathmod,
            name=name,
            component=component,
            slider=slider,
            param=param,
            box=box,
            grid=grid,
            level=level,
            cap=cap,
            evaluator=evaluator,
            output=output,
            png=png,
            save_field=save_field,
            as_json=as_json,
        )
        return
    if name is not None or component is not None or slider is not None:
        raise SpecError("--name, --component and --slider go with --mathmod")

    catalogued = None
    if from_catalogue is not None:
        catalogued = catalogued_spec(*from_catalogue)
    spec_obj = build_spec(
        preset=preset,
        formula=formula,
        spec_file=spec,
        base=catalogued,
        params=parse_params(param),
        box=parse_numbers(box, "--box", (2, 6)) if box is not None else None,
        grid=parse_numbers(grid, "--grid", (1, 3), integer=True) if grid is not None else None,
        level=level,
    )
    if evaluator != "reference":  # fast, sparse and auto use the numba kernels
        compile_first(echo_err)
    with stage_bar("render") as progress:
        result = render_spec(
            spec_obj,
            cap=cap if cap is not None else bool(preset) and get_preset(preset).cap,
            evaluator=evaluator,
            mesh_path=output,
            field_path=save_field,
            png_path=png,
            max_memory=limit,
            walls=walls,
            force=force,
            progress=progress,
        )
    s = result.summary()
    if as_json:
        emit_json(s)
        return
    typer.echo(f"{s['formula']}")
    typer.echo(
        f"grid {'x'.join(map(str, s['grid']))}, box {s['box']}: "
        + (f"{s['vertices']} vertices, {s['faces']} faces" if s["faces"] is not None else "no mesh")
        + f", {s['nonfinite']} non-finite samples, {s['seconds']:.3f} s"
    )
    if s["wall_fraction"] is not None:
        c = s["crossings"]
        typer.echo(
            f"walls ({s['walls']}): {100 * s['wall_fraction']:.1f}% of the area; crossings: "
            f"{c['roots']} roots, {c['poles']} poles, {c['jumps']} jumps"
        )
    for kind, path in s["files"].items():
        typer.echo(f"wrote {kind}: {path}")


def check(
    mesh: Annotated[Path, typer.Argument(help=f"A mesh file ({'/'.join(MESH_SUFFIXES)}).")],
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Topology and geometry of a mesh: components, Euler characteristic, genus, manifoldness;
    for a catalogue's mesh file, its resolution figures (the twice-as-fine grid's)."""
    from surfgen.filters.metrics import measure_mesh  # deferred: see the module's docstring
    from surfgen.generator.mesh.exchange import load_mesh
    from surfgen.generator.mesh.mesh import wall_fraction
    from surfgen.pipelines.catalogue.check import stored_resolution

    loaded = load_mesh(mesh)
    m = measure_mesh(loaded).to_dict()
    # Known only for files written with --walls mark (their faces carry a kind).
    m["wall_fraction"] = wall_fraction(loaded)
    m.update(stored_resolution(mesh) or {})  # a catalogued shape's (meshes/KEY.ply)
    if as_json:
        emit_json(m)
        return
    width = max(len(k) for k in m)
    for k, v in m.items():
        typer.echo(f"{k:<{width}}  {v}")


def presets(as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False) -> None:
    """List the paper's examples and the classic surfaces."""
    from surfgen.generator.model.presets import PRESETS  # deferred: see the module's docstring

    rows = [p.to_dict() for p in PRESETS.values()]
    if as_json:
        emit_json(rows)
        return
    for r in rows:
        params = ", ".join(f"{k}={v:g}" for k, v in r["params"].items())
        b = r["box"]
        box = f"[{b[0]:g},{b[1]:g}]" if len(set(map(abs, b))) == 1 else str(b)
        typer.echo(
            f"{r['name']:<8} grid {r['grid'][0]}x{r['grid'][1]}x{r['grid'][2]}  box {box}"
            f"{'  ' + params if params else ''}  — {r['source']}"
        )
        typer.echo(f"         {r['formula']}")


def catalogued_spec(root: Path, key: str) -> SurfaceSpec:
    """The spec of a catalogued shape for ``render --from``: refused for a draw that was never
    evaluated (timeout, crash), with a warning for one the filters rejected."""
    record = Catalogue(root)[key]
    spec = record.spec
    if "failed" in spec.provenance:
        raise CatalogueError(
            f"shape {record.key} was never evaluated ({spec.provenance['failed']}): its spec "
            "has no d, so it cannot be rendered"
        )
    if not record.accepted:
        typer.echo(
            f"warning: shape {record.key} was rejected by the filters "
            f"({', '.join(record.reasons) or 'no reason recorded'}); rendering it anyway",
            err=True,
        )
    return spec
