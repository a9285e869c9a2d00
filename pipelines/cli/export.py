"""``surfgen export``: the command line of :mod:`surfgen.pipelines.export.meshes`.

The export itself (cleanup with pymeshlab, trimesh's writers, re-evaluation) is imported when
the command runs, so that the other commands, ``--help`` included, do not load it.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated

import typer

from surfgen.generator.allocator import one_shot_memory_policy
from surfgen.generator.formula.limits import parse_size
from surfgen.generator.mesh.formats import EXPORT_FORMATS, MARKABLE, PRINTABLE
from surfgen.pipelines.catalogue.store import DEFAULT_CATALOGUE
from surfgen.pipelines.cli.common import CatalogueOption, EvaluatorOption, MaxMemoryOption

# ``CleanupOptions.min_component`` (surfgen.filters.cleanup), here without importing pymeshlab;
# tests/pipelines/test_export.py checks that the two agree.
MIN_COMPONENT = 1e-3


def export_command(
    inputs: Annotated[
        list[str],
        typer.Argument(
            metavar="KEY|PREFIX|FILE",
            help="Catalogue keys or unique key prefixes, spec .json files or mesh files.",
        ),
    ],
    output: Annotated[Path, typer.Option("-o", "--output", help="Output folder.")],
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    fmt: Annotated[
        str,
        typer.Option(
            "--format", help=f"{', '.join(EXPORT_FORMATS)}; or mathmod, k3dsurf (scripts)."
        ),
    ] = "stl",
    remesh: Annotated[
        bool, typer.Option("--remesh", help="Isotropic remeshing (same face count by default).")
    ] = False,
    target_edge: Annotated[
        float | None,
        typer.Option(help="Remesh to this edge length (mm with --size, else box units)."),
    ] = None,
    target_faces: Annotated[
        int | None, typer.Option(help="Remesh to about this many faces.")
    ] = None,
    smooth: Annotated[int, typer.Option(help="Taubin smoothing steps (volume kept).")] = 0,
    min_component: Annotated[
        float, typer.Option(help="Drop components below this fraction of the total area.")
    ] = MIN_COMPONENT,
    size: Annotated[
        float | None, typer.Option(help="Scale the longest bbox side to SIZE millimetres.")
    ] = None,
    regrid: Annotated[
        int | None, typer.Option(help="Re-evaluate the formula on N^3 points first.")
    ] = None,
    evaluator: EvaluatorOption = "auto",
    force: Annotated[
        bool,
        typer.Option(
            "--force",
            help=f"Write {'/'.join(map(str.upper, PRINTABLE))} even if not watertight and manifold.",
        ),
    ] = False,
    walls: Annotated[
        str,
        typer.Option(
            help="keep (the solid), remove (only the zero set: open) or mark (label poles and "
            f"jumps; {'/'.join(MARKABLE)})."
        ),
    ] = "keep",
    as_json: Annotated[bool, typer.Option("--json", help="Print a JSON list.")] = False,
    max_memory: MaxMemoryOption = None,
) -> None:
    """Clean up (and optionally remesh and smooth) shapes and write print- or render-ready files."""
    # Deferred (see the module's docstring); rich only draws the bar.
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from surfgen.filters.cleanup import CleanupOptions
    from surfgen.pipelines.export.mathmod_scripts import SCRIPT_FORMATS, export_scripts
    from surfgen.pipelines.export.meshes import (
        ExportOptions,
        export_shapes,
        jsonable,
        longest_side,
    )

    one_shot_memory_policy()  # one pass over the shapes: a fine regrid's steps freed at once
    limit = parse_size(max_memory) if max_memory is not None else None

    if fmt.lower() in SCRIPT_FORMATS:  # the formula itself, for MathMod or K3DSurf
        for path in export_scripts(inputs, output, fmt, catalogue):
            typer.echo(f"wrote {path}")
        return
    cleanup = CleanupOptions(
        min_component=min_component,
        remesh=remesh,
        target_edge=target_edge,
        target_faces=target_faces,
        smooth=smooth,
    )
    options = ExportOptions(
        format=fmt,
        cleanup=cleanup,
        size=size,
        regrid=regrid,
        force=force,
        walls=walls,
        evaluator=evaluator,
    )
    with Progress(
        TextColumn("export"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[name]}"),
        TimeElapsedColumn(),
        disable=not sys.stderr.isatty(),
        transient=True,
    ) as bar:
        task = bar.add_task("export", total=len(inputs), name="")
        results = export_shapes(
            inputs,
            output,
            options,
            catalogue,
            progress=lambda i, n, name: bar.update(task, completed=i, total=n, name=name),
            max_memory=limit,
        )
    for r in results:
        for w in r.prepared.warnings:
            typer.echo(f"warning: {w}", err=True)
    if as_json:
        typer.echo(json.dumps([r.summary() for r in results], indent=2, default=jsonable))
        return
    for r in results:
        p, a = r.prepared, r.prepared.after
        state = "watertight" if a.watertight else f"open ({a.boundary_edges} boundary edges)"
        genus = "" if a.genus is None else f", genus {a.genus}"
        typer.echo(
            f"{p.source.name}: {p.before.faces} -> {a.faces} faces, {state}{genus}, "
            f"longest side {longest_side(p.mesh):.6g}{' mm' if options.format in PRINTABLE else ''}, "
            f"{p.seconds:.2f} s -> {r.file}"
        )
        for step in p.cleanup.steps:
            typer.echo(f"  {step.describe()}")
        for problem in p.problems:
            typer.echo(f"  forced despite: {problem}")
