"""``surfgen config``: the sampling configuration.

The configuration module (the sampler's settings) is imported when the command runs, so that
``--help`` loads as little as it can.
"""

from __future__ import annotations

import typer

config_app = typer.Typer(no_args_is_help=True, help="The sampling configuration.")


@config_app.command("show")
def config_show() -> None:
    """Print the built-in default configuration (TOML, with comments)."""
    from surfgen.pipelines.run.config import default_config_text  # deferred: see the docstring

    typer.echo(default_config_text(), nl=False)
