"""The catalogue's pictures: ``surfgen thumbnails`` and ``surfgen contact-sheet``.

The picture pool and rich's progress bar are imported when a command runs, so that ``--help``
and the other commands start without them.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from surfgen.pipelines.catalogue.store import DEFAULT_CATALOGUE, open_catalogue
from surfgen.pipelines.cli.common import (
    CatalogueOption,
    WorkersOption,
    check_workers,
    echo_err,
)


def thumbnails_cmd(
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    force: Annotated[bool, typer.Option(help="Render again even where pictures exist.")] = False,
    where: Annotated[
        str | None, typer.Option(help="Only these shapes (see `catalogue list`).")
    ] = None,
    workers: WorkersOption = None,
) -> None:
    """Render missing thumbnails and turntables of the accepted shapes."""
    # Deferred (see the module's docstring).
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    from surfgen.pipelines.pictures.thumbnails import GalleryError, render_pictures

    with (
        open_catalogue(catalogue, must_exist=True) as cat,
        Progress(
            BarColumn(),
            MofNCompleteColumn(),
            TimeRemainingColumn(),
            disable=not sys.stderr.isatty(),
        ) as bar,
    ):
        task = bar.add_task("pictures", total=None)
        res = render_pictures(
            cat,
            force=force,
            where=where,
            progress=lambda i, n: bar.update(task, completed=i, total=n),
            workers=check_workers(workers),
        )
    failed = ""
    if res.failed:  # one line for all of them: the count, the first, and where to look
        key, why = res.failed[0]
        failed = (
            f"{len(res.failed)} shape(s) got no pictures (the first, {key}: {why}); "
            f"`surfgen catalogue check -C {catalogue}` lists what is missing and --repair "
            "re-makes it"
        )
    if res.failed and not res.rendered and not res.skipped:
        raise GalleryError(f"no pictures could be rendered: {failed}")
    if failed:
        echo_err(f"warning: {failed}")
    typer.echo(
        f"rendered {res.rendered}, already there {res.skipped}, failed {len(res.failed)} "
        f"(thumbnails in {Path(catalogue) / 'thumbs'})"
    )


def contact_sheet_cmd(
    output: Annotated[Path, typer.Option("-o", "--output", help="The sheet (PNG).")] = Path(
        "out/contact-sheet.png"
    ),
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    where: Annotated[str | None, typer.Option(help="Which shapes (see `catalogue list`).")] = None,
    sort: Annotated[str | None, typer.Option(help="FIELD or -FIELD.")] = None,
    limit: Annotated[int | None, typer.Option(help="At most this many.")] = 48,
    columns: Annotated[int, typer.Option(help="Thumbnails per row.")] = 6,
) -> None:
    """A grid of thumbnails with short keys, for a quick look or a figure."""
    from surfgen.pipelines.pictures.thumbnails import write_contact_sheet  # deferred: see above

    with open_catalogue(catalogue, readonly=True) as cat:
        path, n = write_contact_sheet(cat, output, where, sort, limit, columns)
    typer.echo(f"wrote {path} ({n} shapes)")
