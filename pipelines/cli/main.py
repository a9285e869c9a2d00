"""The ``surfgen`` command line: thin wrappers that parse options, call one library function and
print a summary. Every known error becomes one line on stderr and a non-zero exit code."""

from __future__ import annotations

import importlib
import json
import logging
import math
import os
import signal
import sqlite3
import sys
import time
from pathlib import Path
from typing import Annotated, Any

import typer
from typer.exceptions import Abort, TyperException

from surfgen.generator.errors import SpecError, SurfgenError
from surfgen.generator.mesh.formats import MESH_SUFFIXES

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    help="Generate, filter, catalogue and export 3D surfaces from random implicit functions.",
)
# The libraries whose versions `surfgen --version` prints (a bug report wants them): read from
# the installed packages' metadata, without importing them.
VERSIONED = ("numpy", "numba", "llvmlite", "scikit-image", "trimesh", "pymeshlab", "scipy", "typer")


def version_text() -> str:
    """``surfgen 0.1.0`` and, on a second line, Python's and the libraries' versions."""
    import platform
    from importlib import metadata

    from surfgen.generator import __version__

    def installed(name: str) -> str:
        try:
            return metadata.version(name)
        except metadata.PackageNotFoundError:
            return "not installed"

    libraries = ", ".join(f"{name} {installed(name)}" for name in VERSIONED)
    return f"surfgen {__version__}\npython {platform.python_version()}, {libraries}"


def _print_version(value: bool) -> None:
    if value:
        typer.echo(version_text())
        raise typer.Exit()


@app.callback()
def _options(
    version: Annotated[
        bool,
        typer.Option(
            "--version",
            callback=_print_version,
            is_eager=True,
            help="Print surfgen's version and its libraries', then exit.",
        ),
    ] = False,
) -> None:
    """Generate, filter, catalogue and export 3D surfaces from random implicit functions."""


plot_app = typer.Typer(no_args_is_help=True, help="Plots of the paper's figures.")
app.add_typer(plot_app, name="plot")
config_app = typer.Typer(no_args_is_help=True, help="The sampling configuration.")
app.add_typer(config_app, name="config")


# ----------------------------------------------------------------------------- option parsing


def parse_numbers(text: str, what: str, counts: tuple[int, ...], integer: bool = False) -> list:
    """``"a,b,c"`` → numbers; ``counts`` are the allowed lengths."""
    if len(text) > 200:
        raise SpecError(f"{what} takes at most 6 numbers, got {len(text)} characters")
    parts = [p.strip() for p in text.split(",")]
    try:
        values = [int(p) if integer else float(p) for p in parts]
    except ValueError:
        kind = "whole numbers" if integer else "numbers"
        raise SpecError(f"{what} must be {kind} separated by commas, got '{text}'") from None
    if len(values) not in counts:
        allowed = " or ".join(str(c) for c in counts)
        raise SpecError(f"{what} takes {allowed} values, got {len(values)} ('{text}')")
    return values


def parse_params(items: list[str] | None) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise SpecError(f"--param takes NAME=VALUE, got '{item}'")
        try:
            number = float(value)
        except ValueError:
            raise SpecError(f"--param {name.strip()}: '{value}' is not a number") from None
        if not math.isfinite(number):
            raise SpecError(f"--param {name.strip()}: must be a finite number, got '{value}'")
        out[name.strip()] = number
    return out


SHOWN_SETUP = 5.0  # seconds: a sampling run's setup is mentioned from this long on


def echo_err(text: str) -> None:
    """A line on stderr: notices that are not the command's output."""
    typer.echo(text, err=True)


def emit_json(obj: Any) -> None:
    typer.echo(json.dumps(obj, indent=2, sort_keys=False, default=str))


MaxMemoryOption = Annotated[
    str | None,
    typer.Option(
        "--max-memory",
        help="Refuse work estimated to need more memory than this (e.g. 4G; "
        "default: the machine's available memory).",
    ),
]


def catalogued_spec(root: Path, key: str):
    """The spec of a catalogued shape for ``render --from``: refused for a draw that was never
    evaluated (timeout, crash), with a warning for one the filters rejected."""
    from surfgen.generator.model.spec import SurfaceSpec
    from surfgen.pipelines.catalogue.store import CatalogueError, open_catalogue

    with open_catalogue(root, readonly=True) as cat:
        row = cat.shape(key)
    spec = SurfaceSpec.from_json(row["spec"])
    reasons = json.loads(row.get("reasons") or "[]")
    if "failed" in spec.provenance:
        raise CatalogueError(
            f"shape {row['key']} was never evaluated ({spec.provenance['failed']}): its spec "
            "has no d, so it cannot be rendered"
        )
    if row.get("verdict") != "accepted":
        typer.echo(
            f"warning: shape {row['key']} was rejected by the filters "
            f"({', '.join(reasons) or 'no reason recorded'}); rendering it anyway",
            err=True,
        )
    return spec


# ----------------------------------------------------------------------------- render


@app.command()
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
    evaluator: Annotated[str, typer.Option(help="fast or reference.")] = "fast",
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
    from surfgen.generator.formula.limits import parse_size
    from surfgen.generator.model.presets import get_preset
    from surfgen.pipelines.export.render import build_spec, render_spec
    from surfgen.pipelines.run.warmup import compile_first

    limit = parse_size(max_memory) if max_memory is not None else None
    if mathmod is not None:
        from surfgen.pipelines.export.mathmod_scripts import read_model, render_model

        if save_field is not None:
            raise SpecError(
                "--save-field does not go with --mathmod (a model may have several grids)"
            )
        model = read_model(mathmod, name, slider=slider, params=parse_params(param))
        for notice in model.notices:
            typer.echo(f"notice: {notice}", err=True)
        if evaluator == "fast":
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
    if evaluator == "fast":
        compile_first(echo_err)
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


# ----------------------------------------------------------------------------- check


@app.command()
def check(
    mesh: Annotated[Path, typer.Argument(help=f"A mesh file ({'/'.join(MESH_SUFFIXES)}).")],
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Topology and geometry of a mesh: components, Euler characteristic, genus, manifoldness."""
    from surfgen.filters.metrics import measure_mesh
    from surfgen.generator.mesh.exchange import load_mesh
    from surfgen.generator.mesh.mesh import wall_fraction

    loaded = load_mesh(mesh)
    m = measure_mesh(loaded).to_dict()
    # Known only for files written with --walls mark (their faces carry a kind).
    m["wall_fraction"] = wall_fraction(loaded)
    if as_json:
        emit_json(m)
        return
    width = max(len(k) for k in m)
    for k, v in m.items():
        typer.echo(f"{k:<{width}}  {v}")


# ----------------------------------------------------------------------------- presets, plots


@app.command()
def presets(as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False) -> None:
    """List the paper's examples and the classic surfaces."""
    from surfgen.generator.model.presets import PRESETS

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


@plot_app.command("constituents")
def plot_constituents_cmd(
    output: Annotated[Path, typer.Option("-o", "--output", help="PNG file.")] = Path(
        "out/constituents.png"
    ),
) -> None:
    """Redraw Figure 1.1 and the four panels of Figure 1.2."""
    from surfgen.pipelines.export.render import check_output_path
    from surfgen.pipelines.pictures.plots import plot_constituents

    check_output_path(output, (".png",), "picture")
    typer.echo(f"wrote {plot_constituents(output)}")


# ----------------------------------------------------------------------------- sample


@app.command()
def sample(
    n: Annotated[int, typer.Option("--n", help="How many accepted shapes to catalogue.")] = 100,
    seed: Annotated[int, typer.Option(help="Seed of the run: same seed, same shapes.")] = 0,
    grid: Annotated[
        int | None, typer.Option(help="Points per axis (default from the config).")
    ] = None,
    workers: Annotated[
        int | None, typer.Option(help="Worker processes (default: all cores).")
    ] = None,
    out: Annotated[Path, typer.Option(help="Catalogue folder.")] = Path("out/catalogue"),
    config: Annotated[
        Path | None, typer.Option(help="A TOML config (see `surfgen config show`).")
    ] = None,
    max_draws: Annotated[
        int | None, typer.Option(help="Stop after this many draws (default max(1000, 50 n)).")
    ] = None,
    resume: Annotated[
        bool, typer.Option(help="Continue the run with the same seed, grid and config.")
    ] = False,
    dedupe: Annotated[
        bool | None,
        typer.Option(
            "--dedupe/--no-dedupe",
            help="Reject near duplicates of accepted shapes on the fly (default: [run] dedupe, on).",
        ),
    ] = None,
    thumbnails: Annotated[
        bool,
        typer.Option(
            help="Render thumbnails (--no-thumbnails to skip); turntables are rendered when first shown."
        ),
    ] = True,
    executor: Annotated[
        str, typer.Option(help="local (worker processes here) or dask (a Dask cluster).")
    ] = "local",
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="Dask scheduler address (default $SURFGEN_SCHEDULER; none: a local cluster)."
        ),
    ] = None,
    max_memory: MaxMemoryOption = None,
    family: Annotated[
        str | None,
        typer.Option(help="sculpture, lattice, free or mix (default from the config: mix)."),
    ] = None,
) -> None:
    """Draw random instances of equation (13) until N shapes pass the filters."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from surfgen.generator.eval.grid import MAX_POINTS, MIN_POINTS
    from surfgen.generator.formula.limits import MAX_COUNT, check_count, check_seed, parse_size
    from surfgen.pipelines.run.config import load_config
    from surfgen.pipelines.run.sampling import run_sample

    # Every number is checked before anything is created (a catalogue folder, a run row).
    check_count(n, "--n")
    check_seed(seed)
    if grid is not None:
        check_count(grid, "--grid", MIN_POINTS, MAX_POINTS)
    if workers is not None:
        check_count(workers, "--workers", 1, 256)
    if max_draws is not None:
        check_count(max_draws, "--max-draws", 1, MAX_COUNT)
    limit = parse_size(max_memory) if max_memory is not None else None
    if executor == "dask" and not scheduler:
        scheduler = os.environ.get("SURFGEN_SCHEDULER") or None
    cfg = load_config(config).with_grid(grid)
    if family is not None:
        cfg = cfg.with_family(family)
    if dedupe is not None:
        cfg = cfg.with_run(dedupe=dedupe)
    if not thumbnails:
        cfg = cfg.with_run(thumbnails=False)
    columns = (
        TextColumn("accepted"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("drawn {task.fields[drawn]}"),
        TextColumn("{task.fields[rate]:.1f}/min"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    )
    # A plain `kill` (SIGTERM) ends the run like Ctrl-C: the run is marked interrupted and the
    # workers are stopped (they also die with this process: see executor.py).
    signal.signal(signal.SIGTERM, _interrupt)
    with Progress(*columns, transient=False, disable=not sys.stderr.isatty()) as bar:
        task = bar.add_task("sample", total=n, drawn=0, rate=0.0)
        started = time.perf_counter()

        def progress(accepted: int, drawn: int, total: int) -> None:
            minutes = (time.perf_counter() - started) / 60
            bar.update(
                task,
                completed=min(accepted, total),
                drawn=drawn,
                rate=accepted / minutes if minutes else 0.0,
            )

        try:
            summary = run_sample(
                n=n,
                seed=seed,
                config=cfg,
                catalogue=out,
                workers=workers,
                max_draws=max_draws,
                resume=resume,
                progress=progress,
                executor=executor,
                scheduler=scheduler,
                max_memory=limit,
                notice=echo_err,  # above the live bar (rich redirects stderr)
            )
        except KeyboardInterrupt:
            _quiet_after_interrupt()
            bar.stop()
            typer.echo(
                "interrupted: what was catalogued is kept; run the same command with --resume "
                "to continue",
                err=True,
            )
            raise typer.Exit(130) from None
    rejected = summary.drawn - summary.accepted
    setup = summary.setup_seconds
    # a first run's compile is no part of the sampling rate: say how much of the time it took
    ready = f" ({setup:.0f} s of it getting the workers ready)" if setup >= SHOWN_SETUP else ""
    typer.echo(
        f"{summary.accepted} accepted, {rejected} rejected of {summary.drawn} drawn "
        f"({100 * summary.accepted / max(summary.drawn, 1):.0f}% acceptance) in {summary.seconds:.0f} s"
        f"{ready} — {summary.shapes_per_minute:.0f} shapes/min"
    )
    if summary.counts:
        typer.echo(
            "rejection reasons (a shape may have several): "
            + ", ".join(
                f"{k} {v}" for k, v in sorted(summary.counts.items(), key=lambda kv: -kv[1])
            )
        )
    typer.echo(
        f"catalogue: {summary.catalogue / 'catalogue.sqlite'} (run {summary.run_id}, {summary.status})"
    )
    if summary.status == "exhausted":
        raise SpecError(
            f"only {summary.accepted} of {n} shapes accepted after {summary.drawn} draws (--max-draws); "
            "loosen the [filters] thresholds or raise --max-draws"
        )


def _quiet_after_interrupt() -> None:
    """After a Ctrl-C, what is torn down may be half-built: the interrupt can land inside any
    constructor (one of llvmlite's, say, while numba loads a kernel), and that object's
    destructor then fails. Its error would print "Exception ignored in ..." lines after the
    one-line message; they are logged (debug) instead."""

    def hook(unraisable: Any) -> None:
        logging.getLogger(__name__).debug(
            "after the interrupt: %r in %r", unraisable.exc_value, unraisable.object
        )

    sys.unraisablehook = hook


def _interrupt(signum: int, _frame: Any) -> None:
    signal.signal(signum, signal.SIG_DFL)  # a second signal ends the process at once
    raise KeyboardInterrupt


@config_app.command("show")
def config_show() -> None:
    """Print the built-in default configuration (TOML, with comments)."""
    from surfgen.pipelines.run.config import default_config_text

    typer.echo(default_config_text(), nl=False)


# ----------------------------------------------------------------------------- commands from other modules
# Each module below defines its commands and adds them with ``register(app)``.
_REGISTER: list[str] = [
    "surfgen.pipelines.catalogue.curation",
    "surfgen.pipelines.pictures.gallery",
    "surfgen.pipelines.studies.report",
    "surfgen.pipelines.cli.export",
    "surfgen.pipelines.export.dataset",
    "surfgen.pipelines.catalogue.check",
    "surfgen.pipelines.studies.sweep",
    "surfgen.pipelines.studies.reproduce",
    "surfgen.pipelines.export.mathmod_scripts",
]

for _module in _REGISTER:
    importlib.import_module(_module).register(app)


# ----------------------------------------------------------------------------- entry point


def one_line(text: str, limit: int = 2000) -> str:
    """An error message as one line of bounded length."""
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def describe_os_error(exc: OSError) -> str:
    """``cannot write out/x.png: No space left on device`` from any ``OSError``."""
    where = exc.filename if exc.filename is not None else "a file"
    return f"{where}: {exc.strerror or exc}"


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; known errors print one line (``error: ...``) and exit non-zero."""
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        rv = app(args=argv, standalone_mode=False)
    except SurfgenError as exc:
        typer.echo(f"error: {one_line(str(exc))}", err=True)
        return 1
    # The boundaries raise SurfgenError; these are the safety net for what slips past them,
    # still one line and no traceback (the message names the path or the database).
    except sqlite3.Error as exc:
        from surfgen.pipelines.catalogue.store import sqlite_error

        typer.echo(f"error: {one_line(str(sqlite_error(exc, 'the catalogue database')))}", err=True)
        return 1
    except OSError as exc:
        typer.echo(f"error: {one_line(describe_os_error(exc))}", err=True)
        return 1
    except MemoryError:
        typer.echo(
            "error: out of memory (lower --grid, or set --max-memory to be refused early)",
            err=True,
        )
        return 1
    except RecursionError:
        typer.echo("error: the input is nested too deeply", err=True)
        return 1
    except TyperException as exc:  # usage errors: bad option, missing argument, ...
        if type(exc).__name__ == "NoArgsIsHelpError":  # `surfgen` or a group alone: its help
            typer.echo(exc.format_message())
            return 0
        message = exc.format_message()
        ctx = getattr(exc, "ctx", None)
        if (
            "No such command" in message
            and ctx is not None
            and hasattr(ctx.command, "list_commands")
        ):
            message += f" (commands: {', '.join(ctx.command.list_commands(ctx))})"
        typer.echo(f"error: {message}", err=True)
        return exc.exit_code or 2
    except Abort:
        _quiet_after_interrupt()
        typer.echo("aborted", err=True)
        return 130
    except KeyboardInterrupt:
        _quiet_after_interrupt()
        typer.echo("interrupted", err=True)
        return 130
    return rv if isinstance(rv, int) else 0
