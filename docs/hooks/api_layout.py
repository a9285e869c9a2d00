"""MkDocs hook: the surfgen package laid out as it is installed, for the API reference.

The API's folder ``api/`` is installed as the package ``surfgen``, with ``generator/``,
``filters/`` and ``pipelines/`` beneath it (``package-dir`` in ``pyproject.toml``). griffe, which
reads the sources for mkdocstrings, finds a package by its folder's name, so an editable
install's mapping of ``api/`` to ``surfgen`` is invisible to it. This hook links that layout
into a temporary folder and puts it first on ``sys.path``, where mkdocstrings' python handler
looks (it reads ``sys.path`` when it starts, after ``on_startup``).
"""

from __future__ import annotations

import atexit
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LAYERS = ("generator", "filters", "pipelines")


def on_startup(command: str, dirty: bool) -> None:
    tree = Path(tempfile.mkdtemp(prefix="surfgen-docs-"))
    atexit.register(shutil.rmtree, tree, ignore_errors=True)
    package = tree / "surfgen"
    package.mkdir()
    for path in (ROOT / "api").glob("*.py"):
        (package / path.name).symlink_to(path)
    for layer in LAYERS:
        (package / layer).symlink_to(ROOT / layer, target_is_directory=True)
    sys.path.insert(0, str(tree))
