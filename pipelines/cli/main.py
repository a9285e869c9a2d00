"""The ``surfgen`` command line: the root app, ``--version`` and :func:`main`, which turns every
known error into one line on stderr and a non-zero exit code.

Each command group is a module of this package (``render``, ``sample``, ``pictures``, ``web``,
``studies``, ``export``, ``catalogue``, ``dataset``, ``interop``, ``config``); each command
parses its options, calls one library function and prints a summary. They are added below in
the order ``surfgen --help`` lists them.
"""

from __future__ import annotations

import logging
import platform
import sqlite3
from importlib import metadata
from typing import Annotated

import typer
from typer.exceptions import Abort, TyperException

from surfgen.generator import __version__
from surfgen.generator.errors import SurfgenError
from surfgen.pipelines.catalogue.store import sqlite_error
from surfgen.pipelines.cli import (
    catalogue,
    config,
    dataset,
    export,
    interop,
    pictures,
    render,
    sample,
    studies,
    web,
)
from surfgen.pipelines.cli.common import (
    describe_os_error,
    from_interrupt,
    one_line,
    quiet_after_interrupt,
)

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


# Commands first, then the groups: the order of `surfgen --help` and of its "commands:" list.
app.command("render")(render.render)
app.command("check")(render.check)
app.command("presets")(render.presets)
app.command("sample")(sample.sample)
app.command("thumbnails")(pictures.thumbnails_cmd)
app.command("contact-sheet")(pictures.contact_sheet_cmd)
app.command("serve")(web.serve_cmd)
app.command("gallery")(web.gallery_cmd)
app.command("report")(studies.report_cmd)
app.command("export")(export.export_command)
app.command("sweep")(studies.sweep_cmd)
app.command("reproduce")(studies.reproduce_cmd)
app.add_typer(studies.plot_app, name="plot")
app.add_typer(config.config_app, name="config")
app.add_typer(catalogue.catalogue_app, name="catalogue")
app.add_typer(dataset.dataset_app, name="dataset")
app.add_typer(interop.import_app, name="import")


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
        quiet_after_interrupt()
        typer.echo("aborted", err=True)
        return 130
    except (KeyboardInterrupt, RuntimeError) as exc:  # RuntimeError: a Ctrl-C Python wrapped
        if not from_interrupt(exc):
            raise
        quiet_after_interrupt()
        typer.echo("interrupted", err=True)
        return 130
    return rv if isinstance(rv, int) else 0
