"""Other programs' shapes: ``surfgen import mathmod`` and what ``surfgen render --mathmod`` does.

The MathMod reader and the renderer (numba, trimesh) are imported when a command runs, so that
``--help`` and the other commands do not load them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from surfgen.generator.errors import SpecError
from surfgen.pipelines.cli.common import echo_err, emit_json, parse_numbers, parse_params

import_app = typer.Typer(help="Bring shapes in from other programs.", no_args_is_help=True)


@import_app.command("mathmod")
def import_mathmod_cmd(
    script: Annotated[Path, typer.Argument(help="A MathMod script (JSON).")],
    output: Annotated[
        Path, typer.Option("-o", "--output", help="Folder for the spec files.")
    ] = Path("out/mathmod"),
    name: Annotated[str | None, typer.Option(help="Only the model of this Name.")] = None,
    slider: Annotated[int | None, typer.Option(help="Slider set K (default 0).")] = None,
    param: Annotated[
        list[str] | None, typer.Option(help="NAME=VALUE (t, constants, sliders).")
    ] = None,
) -> None:
    """Write one spec JSON per component of the script's implicit (Iso3D) models."""
    from surfgen.pipelines.export.mathmod_scripts import import_script  # deferred: see above

    for path in import_script(script, output, name=name, slider=slider, params=parse_params(param)):
        typer.echo(f"wrote {path}")


def render_mathmod(
    script: Path,
    *,
    name: str | None,
    component: str | None,
    slider: int | None,
    param: list[str] | None,
    box: str | None,
    grid: str | None,
    level: float | None,
    cap: bool | None,
    evaluator: str,
    output: Path | None,
    png: Path | None,
    save_field: Path | None,
    as_json: bool,
) -> None:
    """``surfgen render --mathmod SCRIPT``: render the script's Iso3D model, print a summary."""
    # Deferred (see above): the renderer and the warm-up load numba and trimesh.
    from surfgen.pipelines.export.mathmod_scripts import read_model, render_model
    from surfgen.pipelines.run.warmup import compile_first

    if save_field is not None:
        raise SpecError("--save-field does not go with --mathmod (a model may have several grids)")
    model = read_model(script, name, slider=slider, params=parse_params(param))
    for notice in model.notices:
        typer.echo(f"notice: {notice}", err=True)
    if evaluator != "reference":  # fast, sparse and auto use the numba kernels
        compile_first(echo_err)
    s = render_model(
        model,
        component=component,
        box=parse_numbers(box, "--box", (2, 6)) if box else None,
        grid=parse_numbers(grid, "--grid", (1, 3), integer=True) if grid else None,
        level=level,
        cap=bool(cap),
        evaluator=evaluator,
        mesh_path=output,
        png_path=png,
    )
    if as_json:
        emit_json(s)
        return
    for c in s["components"]:
        typer.echo(f"{c['component']}: {c['formula']}")
    typer.echo(
        f"{s['model']}: {len(s['components'])} component(s), {s['vertices']} vertices, "
        f"{s['faces']} faces, {s['nonfinite']} non-finite samples, {s['seconds']:.3f} s"
    )
    for kind, path in s["files"].items():
        typer.echo(f"wrote {kind}: {path}")
