"""What the commands promise and load: the keys of ``surfgen check --json`` and the heavy
libraries a command imports (run in a fresh process)."""

from __future__ import annotations

import json
import subprocess
import sys

# The keys `surfgen check --json` promises (the list, in its order).
CHECK_KEYS = [
    "vertices", "faces", "components", "euler", "genus", "watertight", "boundary_edges",
    "nonmanifold_edges", "nonmanifold_vertices", "area", "volume", "bbox",
]  # fmt: skip

# What the commands that compute nothing must not load: numba and llvmlite (and scipy with
# them), trimesh (with scipy and networkx), pymeshlab, scikit-image: about 1.5 s before `--help`
# printed anything until generator/jit/setup.py and the lazy imports (README, "Performance").
HEAVY_MODULES = ("numba", "llvmlite", "scipy", "trimesh", "pymeshlab", "skimage", "networkx")

_LOADED = """
import json, sys
from surfgen.pipelines.cli.main import main
try:
    main(sys.argv[1:])
except SystemExit:
    pass
print(json.dumps(sorted(m for m in {heavy!r} if m in sys.modules)), file=sys.stderr)
"""


def heavy_modules_loaded(*args: str) -> list[str]:
    """The :data:`HEAVY_MODULES` that ``surfgen ARGS`` loaded, run in a fresh process."""
    code = _LOADED.format(heavy=HEAVY_MODULES)
    done = subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120
    )
    return json.loads(done.stderr.strip().splitlines()[-1])
