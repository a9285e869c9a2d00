"""The gallery in a browser: ``surfgen serve`` (live, curating) and ``surfgen gallery`` (static
files to publish).

The web app (Flask, the explorer's evaluator) and rich's progress bar are imported when a command runs, so that
``--help`` and the other commands do not load it.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import Annotated

import typer

from surfgen.pipelines.catalogue.store import DEFAULT_CATALOGUE
from surfgen.pipelines.cli.common import CatalogueOption, WorkersOption, check_workers, echo_err

log = logging.getLogger(__name__)


def serve_cmd(
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    port: Annotated[int, typer.Option(help="Port (0: any free one).")] = 8000,
    host: Annotated[
        str, typer.Option(help="Address to bind; anything but loopback exposes the catalogue.")
    ] = "127.0.0.1",
) -> None:
    """Browse and curate the catalogue in a web browser (writes at once)."""
    # Deferred (see the module's docstring).
    from surfgen.pipelines.pictures.thumbnails import GalleryError
    from surfgen.pipelines.run.warmup import compile_notice
    from surfgen.pipelines.web.app import LOOPBACK, make_server, server_url

    if not 0 <= port <= 65535:
        raise GalleryError(f"--port must be 0-65535, got {port}")
    if host not in LOOPBACK:
        log.warning("serving on %s: anyone who can reach it can edit the catalogue", host)
    server = make_server(catalogue, host, port)
    compile_notice(echo_err, background=True)  # the explorer compiles in a thread
    typer.echo(f"gallery of {catalogue} at {server_url(server)} (Ctrl+C to stop)")
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        typer.echo("stopped")
    finally:
        server.server_close()


def gallery_cmd(
    output: Annotated[Path, typer.Option("-o", "--output", help="Folder to write.")],
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    where: Annotated[
        str | None, typer.Option(help="Only these shapes (see `catalogue list`).")
    ] = None,
    meshes: Annotated[bool, typer.Option(help="Copy the meshes too, for download.")] = False,
    workers: WorkersOption = None,
) -> None:
    """Write the gallery as static, read-only files to publish or share."""
    # Deferred (see the module's docstring).
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeRemainingColumn,
    )

    from surfgen.pipelines.web.site import export_gallery

    columns = (TextColumn("turntables"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
    with Progress(*columns, disable=not sys.stderr.isatty(), transient=True) as bar:
        task = bar.add_task("turntables", total=None)
        index, n = export_gallery(
            catalogue,
            output,
            where=where,
            meshes=meshes,
            workers=check_workers(workers),
            progress=lambda i, total: bar.update(task, completed=i, total=total),
        )
    typer.echo(f"wrote {index} ({n} shapes); open it in a browser")
