"""What every page of the gallery shares: its templates, its static files, JSON that is safe
inside ``<script>`` and the atomic write of a page meant to be published."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path
from typing import Any

import jinja2

from surfgen.generator.files import write_atomic


def templates() -> jinja2.Environment:
    """The page templates (``surfgen/pipelines/web/templates``), HTML autoescaped."""
    return jinja2.Environment(
        loader=jinja2.PackageLoader("surfgen.pipelines.web", "templates"),
        autoescape=jinja2.select_autoescape(["html"]),
    )


def static_dir() -> Path:
    """The folder of the pages' scripts and styles (``surfgen/pipelines/web/static``)."""
    return Path(str(resources.files("surfgen.pipelines.web").joinpath("static")))


def script_json(data: Any) -> str:
    """JSON safe inside ``<script>``: no ``</script>`` or HTML comment can close it."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False, default=str)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def write_page(path: Path, text: str) -> Path:
    """Write an HTML page atomically, readable by all (it is meant to be published)."""
    write_atomic(path, text.encode("utf-8"))
    path.chmod(0o644)
    return path
