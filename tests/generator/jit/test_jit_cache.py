"""numba's cache stamp (generator/numba_cache.py): every cached function of surfgen goes stale
with any of surfgen's numba sources, whichever module a process imports first."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest


def test_every_cached_caller_is_stamped_with_the_numba_sources(tmp_path, monkeypatch):
    # A cached function carries the code of the jitted functions it calls from other files
    # (refine -> kernels -> trig): its cache must go stale when any of them changes, not only
    # when its own file does.
    from surfgen.generator.elementary import trig
    from surfgen.generator.eval import grid_driver as kernels
    from surfgen.generator.jit import cache as numba_cache
    from surfgen.generator.mesh import refine

    digest = numba_cache.package_digest()
    for fn in (refine._bisect_kernel, kernels.run_grid, trig.atan_row):
        locator = fn._cache._impl._locator
        assert getattr(locator, "_surfgen", False), fn
        assert locator.get_source_stamp()[1] == digest, fn
    # the digest follows the numba sources of the folders it reads (here a copy of them)
    for name in ("generator", "filters", "pipelines"):
        (tmp_path / name).mkdir()
    (tmp_path / "generator" / "eval").mkdir()  # sub-packages are read too
    (tmp_path / "generator" / "eval" / "kernels.py").write_text("from numba import njit\n")
    (tmp_path / "generator" / "plain.py").write_text("x = 1\n")
    monkeypatch.setattr(numba_cache, "_ROOT", str(tmp_path))
    monkeypatch.setattr(numba_cache, "_GENERATOR", str(tmp_path / "generator"))
    before = numba_cache.package_digest()
    (tmp_path / "generator" / "plain.py").write_text("x = 2\n")  # no numba code: no change
    assert numba_cache.package_digest() == before
    (tmp_path / "generator" / "eval" / "kernels.py").write_text("from numba import njit\n# edit\n")
    assert numba_cache.package_digest() != before
    # surfgen's files are stamped; other packages' are not, even in a virtual environment that
    # lives inside a checkout
    stamped = type(refine._bisect_kernel._cache._impl._locator)
    venv = tmp_path / ".venv" / "lib" / "site-packages"
    venv.mkdir(parents=True)
    (venv / "other.py").write_text("x = 1\n")
    py_func = refine._bisect_kernel.py_func
    kernels_py = str(tmp_path / "generator" / "eval" / "kernels.py")
    assert stamped.from_function(py_func, kernels_py) is not None
    assert stamped.from_function(py_func, str(venv / "other.py")) is None


# Fresh processes: the first surfgen module each imports is the one that used to decide.
FIRST_IMPORT = """
import json, sys
import {first}
from numba.core.registry import CPUDispatcher
stamped = {{}}
for name, module in list(sys.modules.items()):
    if name.startswith("surfgen."):
        for attr, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value._cache.__class__.__name__ != "NullCache":
                locator = value._cache._impl._locator
                stamped[name + "." + attr] = bool(getattr(locator, "_surfgen", False))
print(json.dumps(stamped))
"""


@pytest.mark.parametrize(
    "first",
    [
        "surfgen.filters.geometry",
        "surfgen.generator.mesh.mesh",
        "surfgen.pipelines.pictures.raster",
    ],
)
def test_every_kernel_is_stamped_whichever_module_comes_first(first):
    # Once only the elementary functions' package installed the stamp: a process that imported
    # the mesh or the filters first cached their kernels under numba's plain stamp, and the
    # next process, importing in the other order, found that index stale and compiled them all
    # again (about 20 s for every `surfgen sample` after a test run, and back).
    out = subprocess.run(
        [sys.executable, "-c", FIRST_IMPORT.format(first=first)],
        capture_output=True, text=True, timeout=120, check=True,
    )  # fmt: skip
    stamped = json.loads(out.stdout.strip().splitlines()[-1])
    assert len(stamped) >= 5, stamped
    assert all(stamped.values()), [k for k, v in stamped.items() if not v]
