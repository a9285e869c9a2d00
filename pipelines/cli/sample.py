"""``surfgen sample``: draw random shapes until N pass the filters, with a live progress bar.

The run is :func:`surfgen.sample`'s; it loads the sampler (numba, trimesh, pymeshlab) when it
runs, so that ``--help`` and the other commands do not load it.
"""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path
from typing import Annotated, Any

import typer

import surfgen
from surfgen.generator.errors import SpecError
from surfgen.generator.eval.grid import MAX_POINTS, MIN_POINTS
from surfgen.generator.formula.limits import MAX_COUNT, check_count, check_seed, parse_size
from surfgen.generator.model.families import family_help
from surfgen.pipelines.cli.common import (
    MaxMemoryOption,
    echo_err,
    from_interrupt,
    quiet_after_interrupt,
)
from surfgen.settings import run_config

SHOWN_SETUP = 5.0  # seconds: a sampling run's setup is mentioned from this long on


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
        typer.Option(help=family_help()),
    ] = None,
) -> None:
    """Draw random instances of equation (13) until N shapes pass the filters."""
    # Deferred: the sampling run loads numba, trimesh and pymeshlab; rich only draws the bar.
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

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
    cfg = run_config(config, grid=grid, family=family, dedupe=dedupe, thumbnails=thumbnails)
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
            summary = surfgen.sample(
                n,
                seed,
                config=cfg,
                out=out,
                workers=workers,
                max_draws=max_draws,
                resume=resume,
                progress=progress,
                executor=executor,
                scheduler=scheduler,
                max_memory=limit,
                notice=echo_err,  # above the live bar (rich redirects stderr)
            ).summary
        except (KeyboardInterrupt, RuntimeError) as exc:
            if not from_interrupt(exc):
                raise
            quiet_after_interrupt()
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


def _interrupt(signum: int, _frame: Any) -> None:
    signal.signal(signum, signal.SIG_DFL)  # a second signal ends the process at once
    raise KeyboardInterrupt
