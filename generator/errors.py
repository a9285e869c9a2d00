"""The one exception family of surfgen.

The library raises these; the sampler turns them into rejected verdicts and the CLI
turns them into one-line messages with a non-zero exit code.
"""

from __future__ import annotations


class SurfgenError(Exception):
    """Base of every error surfgen raises on purpose."""


class FormulaSyntaxError(SurfgenError):
    """A formula string that does not parse; the message names the column."""

    def __init__(self, message: str, column: int | None = None, hint: str = "") -> None:
        self.column = column
        where = f" at column {column}" if column is not None else ""
        super().__init__(f"{message}{where}{hint}")


class FormulaError(SurfgenError):
    """A formula that parses but cannot be evaluated (bad argument, unknown parameter...)."""


class GridError(SurfgenError):
    """A box or grid that is not usable (too few points, empty interval...)."""


class SpecError(SurfgenError):
    """A surface spec or preset that is malformed or unknown."""


class EmptySurface(SurfgenError):
    """The field has no crossing of the iso level inside the box."""


class MeshError(SurfgenError):
    """A mesh that cannot be read, written or measured."""
