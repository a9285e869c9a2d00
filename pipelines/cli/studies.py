"""The studies of the paper: ``surfgen sweep``, ``surfgen reproduce``, ``surfgen report`` and
``surfgen plot ...``.

Each study (numba, trimesh, matplotlib) is imported when its command runs, so that ``--help``
and the other commands do not load them.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from surfgen.generator.errors import SpecError
from surfgen.generator.formula.limits import parse_size
from surfgen.pipelines.catalogue.store import DEFAULT_CATALOGUE, open_catalogue
from surfgen.pipelines.cli.common import CatalogueOption, MaxMemoryOption, echo_err, parse_numbers

plot_app = typer.Typer(no_args_is_help=True, help="Plots of the paper's figures.")


def sweep_cmd(
    param: Annotated[
        str, typer.Option(help="NAME=START:STOP:STEP (NAME: a parameter, box, grid, level, d, #K).")
    ],
    output: Annotated[Path, typer.Option("-o", "--output", help="Folder for the sweep's files.")],
    preset: Annotated[
        str | None, typer.Option(help="A preset name (see `surfgen presets`).")
    ] = None,
    formula: Annotated[
        str | None, typer.Option(help="A formula in K3DSurf/MathMod syntax.")
    ] = None,
    from_catalogue: Annotated[
        tuple[Path, str] | None,
        typer.Option("--from", help="CATALOGUE KEY: sweep a catalogued shape."),
    ] = None,
    box: Annotated[str | None, typer.Option(help="LO,HI or XMIN,XMAX,YMIN,YMAX,ZMIN,ZMAX.")] = None,
    grid: Annotated[int | None, typer.Option(help="Points per axis.")] = None,
    cap: Annotated[
        bool | None,
        typer.Option(
            "--cap/--no-cap",
            help="Close surfaces cut by the box (default: the preset's; catalogued shapes are capped).",
        ),
    ] = None,
    max_memory: MaxMemoryOption = None,
) -> None:
    """Sweep one number of a shape over a range: meshes, contact sheet, GIF, sweep.json, a plot."""
    # Deferred (see the module's docstring).
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    from surfgen.generator.model.presets import get_preset
    from surfgen.pipelines.export.render import build_spec
    from surfgen.pipelines.run.warmup import compile_first
    from surfgen.pipelines.studies.sweep import SweepError, parse_range, run_sweep, uses_param

    name, values = parse_range(param)
    limit = parse_size(max_memory) if max_memory is not None else None
    catalogued = None
    if from_catalogue is not None:
        with open_catalogue(from_catalogue[0], must_exist=True) as cat:
            catalogued = cat.spec(from_catalogue[1])
    # A pasted formula's swept parameter needs no separate value: the sweep starts it.
    bound = {name: values[0]} if uses_param(formula, name) else {}
    base = build_spec(
        preset=preset,
        formula=formula,
        params=bound,
        base=catalogued,
        box=parse_numbers(box, "--box", (2, 6)) if box else None,
        grid=[grid] if grid is not None else None,
    )
    if cap is None:
        cap = get_preset(preset).cap if preset else catalogued is not None
    if output.exists() and not output.is_dir():
        raise SweepError(f"-o {output}: not a folder")
    compile_first(echo_err)
    with Progress(BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                  disable=not sys.stderr.isatty()) as bar:  # fmt: skip
        task = bar.add_task("sweep", total=len(values))
        res = run_sweep(
            base, name, values, output, cap=cap,
            progress=lambda i, n: bar.update(task, completed=i, total=n), max_memory=limit,
        )  # fmt: skip
    for s in res.steps:
        d = "-" if s.distance_prev is None else f"{s.distance_prev:.4g}"
        j = "-" if s.iou_prev is None else f"{s.iou_prev:.3f}"
        typer.echo(
            f"{name}={s.value:<10g} faces {s.stats['faces']:>7}  components {s.stats['components']:>3}  "
            f"genus {'-' if s.stats['genus'] is None else s.stats['genus']:>4}  IoU prev {j:>5}  distance prev {d}"
        )
    typer.echo(f"wrote {len(res.steps)} steps to {output} ({', '.join(res.files.values())})")


def reproduce_cmd(
    output: Annotated[Path, typer.Option("-o", "--output", help="Folder for everything.")] = Path(
        "out/paper"
    ),
    grid_scale: Annotated[
        float, typer.Option(help="Multiply the paper's grids by this (0 < S <= 4).")
    ] = 1.0,
    figure: Annotated[
        list[int] | None, typer.Option(help="Only this figure (1-4), repeatable.")
    ] = None,
) -> None:
    """Redraw the paper's Figures 1-4 and measure its sensitivity claims (report.html)."""
    # Deferred (see the module's docstring).
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    from surfgen.pipelines.run.warmup import compile_first
    from surfgen.pipelines.studies.reproduce import FIGURES, reproduce

    if output.exists() and not output.is_dir():
        raise SpecError(f"--output {output} exists and is not a folder")
    if set(figure or FIGURES) - {1}:  # Figures 2-4 evaluate surfaces (Figure 1 plots curves)
        compile_first(echo_err)
    columns = (SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn())
    with Progress(*columns, transient=True, disable=not sys.stderr.isatty()) as bar:
        task = bar.add_task("reproducing", total=None)
        result = reproduce(
            output,
            grid_scale=grid_scale,
            figures=figure or FIGURES,
            progress=lambda msg: bar.update(task, description=msg),
        )
    for p in result.sensitivity["pairs"]:
        h = "—" if p["hausdorff_rel"] is None else f"{p['hausdorff_rel']:.3f}"
        typer.echo(
            f"figure {p['figure']}  {p['a']:>8} / {p['b']:<8} paper: {p['paper']:<4} "
            f"IoU {p['iou']:.3f}  sensitivity {p['sensitivity']:.2f}  Hausdorff {h}  "
            f"-> {p['verdict']}"
        )
    typer.echo(f"wrote {result.folder / 'report.html'} ({result.seconds:.0f} s)")


def report_cmd(
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    output: Annotated[
        Path | None,
        typer.Option("-o", "--output", help="HTML file (default CATALOGUE/report.html)."),
    ] = None,
    run: Annotated[int | None, typer.Option(help="Only this run (default: all).")] = None,
) -> None:
    """Histograms of genus, components, faces and acceptance, per family with contact sheets."""
    from surfgen.pipelines.studies.report import write_report  # deferred: see the docstring

    typer.echo(f"wrote {write_report(catalogue, output, run)}")


@plot_app.command("constituents")
def plot_constituents_cmd(
    output: Annotated[Path, typer.Option("-o", "--output", help="PNG file.")] = Path(
        "out/constituents.png"
    ),
) -> None:
    """Redraw Figure 1.1 and the four panels of Figure 1.2."""
    # Deferred (see the module's docstring).
    from surfgen.pipelines.export.render import check_output_path
    from surfgen.pipelines.pictures.plots import plot_constituents

    check_output_path(output, (".png",), "picture")
    typer.echo(f"wrote {plot_constituents(output)}")
