"""The environment of a child Python that imports from the checkout (``tests.support``, a test
module by its dotted name) without editing ``sys.path`` in the child's code."""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def python_env(**extra: str) -> dict[str, str]:
    """``os.environ`` with ``extra`` set and the checkout's root first on ``PYTHONPATH``."""
    env = dict(os.environ, **extra)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return env
