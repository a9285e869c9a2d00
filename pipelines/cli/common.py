"""What the commands share: option types, parsing of comma-separated numbers and ``NAME=VALUE``
pairs, JSON output, notices on stderr and the one-line form of an error."""

from __future__ import annotations

import json
import logging
import math
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer

from surfgen.generator.errors import SpecError
from surfgen.generator.formula.limits import check_count

CatalogueOption = Annotated[
    Path,
    typer.Option("--catalogue", "-C", envvar="SURFGEN_CATALOGUE", help="Catalogue folder."),
]
MaxMemoryOption = Annotated[
    str | None,
    typer.Option(
        "--max-memory",
        help="Refuse work estimated to need more memory than this (e.g. 4G; "
        "default: the machine's available memory).",
    ),
]
EvaluatorOption = Annotated[
    str,
    typer.Option(
        help="auto (default: sparse from 160^3 points on, else dense), sparse (only the "
        "blocks the surface may cross), dense or fast (every grid point) or reference; "
        "all make the same mesh."
    ),
]
WorkersOption = Annotated[
    int | None,
    typer.Option(help="Processes drawing the missing pictures (default: all cores)."),
]


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
    """``--param NAME=VALUE`` pairs → ``{name: value}``. Raises :class:`SpecError`."""
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


def check_workers(workers: int | None) -> int | None:
    """``--workers``: 1 to 256, as for ``sample``. Raises :class:`LimitError`."""
    return None if workers is None else check_count(workers, "--workers", 1, 256)


def echo_err(text: str) -> None:
    """A line on stderr: notices that are not the command's output."""
    typer.echo(text, err=True)


@contextmanager
def stage_bar(label: str) -> Iterator[Callable[[str, float | None], None]]:
    """A progress bar on stderr for one long run in stages (a terminal only: redirected
    output stays clean), and the callback that moves it: ``(stage, share done or None)``. The
    bar goes when the run ends."""
    from rich.console import Console  # deferred: the CLI's start loads no more than it needs
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(
        TextColumn(f"{label}: {{task.description}}"),
        BarColumn(),
        TimeElapsedColumn(),
        console=Console(stderr=True),
        disable=not sys.stderr.isatty(),
        transient=True,
    ) as bar:
        task, shown = None, None  # the bar's task, and the stage it shows

        def move(stage: str, done: float | None) -> None:
            nonlocal task, shown
            if stage != shown:  # each stage a task of its own: a share, or a pulse
                if task is not None:
                    bar.remove_task(task)
                task, shown = bar.add_task(stage, total=None if done is None else 1.0), stage
            if done is not None:
                bar.update(task, completed=done)

        yield move


def emit_json(obj: Any) -> None:
    """``obj`` as indented JSON on stdout (what JSON cannot hold written with ``str``)."""
    typer.echo(json.dumps(obj, indent=2, sort_keys=False, default=str))


def one_line(text: str, limit: int = 2000) -> str:
    """An error message as one line of bounded length."""
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def describe_os_error(exc: OSError) -> str:
    """``cannot write out/x.png: No space left on device`` from any ``OSError``."""
    where = exc.filename if exc.filename is not None else "a file"
    return f"{where}: {exc.strerror or exc}"


def from_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` is a Ctrl-C that Python wrapped on its way up: a ``KeyboardInterrupt``
    landing in a class body's ``__set_name__`` (a lazy import of numba's, say) comes out as a
    ``RuntimeError`` caused by it (Python 3.11), and a command must still end on its one-line
    message rather than a traceback."""
    seen: set[int] = set()
    cause: BaseException | None = exc
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return True
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return False


def quiet_after_interrupt() -> None:
    """After a Ctrl-C, what is torn down may be half-built: the interrupt can land inside any
    constructor (one of llvmlite's, say, while numba loads a kernel), and that object's
    destructor then fails. Its error would print "Exception ignored in ..." lines after the
    one-line message; they are logged (debug) instead."""

    def hook(unraisable: Any) -> None:
        logging.getLogger(__name__).debug(
            "after the interrupt: %r in %r", unraisable.exc_value, unraisable.object
        )

    sys.unraisablehook = hook
