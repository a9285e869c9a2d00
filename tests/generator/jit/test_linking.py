"""Cached kernels are loaded without their parsed linking module, which a compile that calls
one parses again (jit/linking.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

from surfgen.generator.jit import linking

_KERNEL = """
from numba import njit

@njit(cache=True)
def twice_plus(x):
    return 2.0 * x + 0.25
"""

# Loads the cached kernel, reports its library's state, then compiles a function that calls
# it (numba links the kernel's code into the new one) and reports again.
_CHECK = """
import json, sys
{imports}
import numba
from numba import njit
import cached_kernel

out = {{"value": cached_kernel.twice_plus(3.0)}}
out["hits"] = sum(cached_kernel.twice_plus.stats.cache_hits.values())
library = next(iter(cached_kernel.twice_plus.overloads.values())).library
out["parsed_on_load"] = library._shared_module is not None
out["kept"] = hasattr(library, "{kept}")

@njit
def caller(x):
    return cached_kernel.twice_plus(x) - 1.0

out["linked"] = caller(3.0)
out["parsed_after_link"] = library._shared_module is not None
out["kept_after_link"] = hasattr(library, "{kept}")
print(json.dumps(out))
"""


def _run(folder: Path, imports: str) -> dict:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(folder / "cache"), "PYTHONPATH": str(folder)}
    code = _CHECK.format(imports=imports, kept=linking.KEPT)
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=180
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_cached_kernel_loads_without_its_linking_module_and_links_after(tmp_path):
    (tmp_path / "cached_kernel.py").write_text(textwrap.dedent(_KERNEL))
    first = _run(tmp_path, "import surfgen.generator")  # compiles and caches the kernel
    assert first["hits"] == 0 and first["value"] == 6.25
    loaded = _run(tmp_path, "import surfgen.generator")
    assert loaded["hits"] == 1, "the kernel came from numba's cache"
    assert loaded["value"] == 6.25
    assert not loaded["parsed_on_load"] and loaded["kept"]
    # the compile that calls it parsed the bitcode again and linked it: the right answer
    assert loaded["linked"] == 5.25
    assert loaded["parsed_after_link"] and not loaded["kept_after_link"]


def test_without_surfgen_numba_keeps_the_parsed_module(tmp_path):
    """What the wrapper changes: numba alone parses the module at load and keeps it."""
    (tmp_path / "cached_kernel.py").write_text(textwrap.dedent(_KERNEL))
    _run(tmp_path, "")
    plain = _run(tmp_path, "")
    assert plain["hits"] == 1
    assert plain["parsed_on_load"] and not plain["kept"]
    assert plain["linked"] == 5.25


def test_installed_once_in_a_process_that_loads_kernels():
    import surfgen.generator.mesh.mesh  # noqa: F401  (imports numba: the settings go in)

    assert linking.installed()
    assert linking.install_lazy_linking()  # again: nothing to do, still installed
