"""surfgen's numba settings are applied when numba is first imported, whoever imports it, and
importing the formula language imports no numba (numba_setup.py)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from surfgen.generator.jit import setup as numba_setup

# What a process reports: is numba loaded, are surfgen's settings in (the stamped cache locator
# first, the interleave listener registered with numba's compile events)?
_REPORT = """
import json, sys
def report():
    if "numba" not in sys.modules:
        return {"numba": False}
    from numba.core import caching, event
    from surfgen.generator.jit import setup as numba_setup, interleave as vector_loops
    first = caching.CacheImpl._locator_classes[0]
    listeners = event._registered.get("numba:compile", [])
    return {
        "numba": True,
        "installed": numba_setup.installed(),
        "stamp_first": bool(getattr(first, "_surfgen", False)),
        "listener": vector_loops._INSTALLED is not None and vector_loops._INSTALLED in listeners,
    }
"""


def _run(body: str) -> list[dict]:
    code = _REPORT + body + "\nprint(json.dumps(out))"
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=False, timeout=120
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


SET_UP = {"numba": True, "installed": True, "stamp_first": True, "listener": True}


def test_the_formula_language_imports_no_numba_and_numba_gets_the_settings_when_it_comes():
    out = _run(
        "import surfgen.generator.model.spec, surfgen.generator.formula.parser, surfgen.generator.elementary\n"
        "import surfgen.pipelines.catalogue.store\n"
        "box = (-2, 2, -2, 2, -2, 2)\n"
        "spec = surfgen.generator.model.spec.SurfaceSpec('x^2+y^2+z^2-1', box=box, grid=(8, 8, 8))\n"
        "out = [report()]\n"
        "import numba\n"
        "out.append(report())\n"
    )
    assert out == [{"numba": False}, SET_UP]


def test_a_kernel_module_imported_first_gets_the_settings_before_its_functions():
    # the import chain runs through vector_loops and numba_cache themselves (no cycle), and the
    # row table's jitted functions are defined with the stamped locator
    out = _run(
        "from surfgen.generator.jit import interleave as vector_loops\n"
        "from surfgen.generator.elementary import trig\n"
        "loc = trig.sin_scalar._cache._impl.locator\n"
        "out = [report(), type(loc).__name__]\n"
    )
    assert out == [SET_UP, "_StampedLocator"]


def test_numba_imported_before_surfgen_gets_the_settings_at_once():
    out = _run("import numba\nimport surfgen.generator\nout = [report()]\n")
    assert out == [SET_UP]


def test_the_finder_leaves_once_numba_and_its_array_math_are_in():
    import numba.np.arraymath  # noqa: F401  (loaded with the first kernel; the finder is gone)

    assert numba_setup.installed()
    assert not any(isinstance(f, numba_setup._Finder) for f in sys.meta_path)


# A process's first kernel: numba's array math imported, its BLAS check answered without
# scipy.linalg, numba's own check back in place; then a kernel that does call BLAS.
_BLAS = """
import numpy as np, numba
@numba.njit
def total(a):
    return a.sum()
total(np.ones(3))
import numba.np.arraymath as arraymath, numba.np.linalg as linalg
from surfgen.generator.jit import setup as numba_setup
out = [report(), "scipy.linalg" in sys.modules, arraymath._HAVE_BLAS,
       arraymath.ensure_blas is linalg.ensure_blas,
       linalg.ensure_blas is not numba_setup._scipy_installed,
       any(isinstance(f, numba_setup._Finder) for f in sys.meta_path)]
@numba.njit
def dot(a, b):
    return np.dot(a, b)
out += [dot(np.ones(4), np.arange(4.0)), "scipy.linalg" in sys.modules]
"""


def test_a_first_kernel_loads_without_scipy_linalg_and_blas_is_there_when_asked():
    assert _run("import surfgen.generator\n" + _BLAS) == [
        SET_UP,
        False,
        True,
        True,
        True,
        False,
        6.0,
        True,
    ]


def test_numba_imported_before_surfgen_still_loads_its_first_kernel_without_scipy_linalg():
    out = _run("import numba\nimport surfgen.generator\n" + _BLAS)
    assert out == [SET_UP, False, True, True, True, False, 6.0, True]


def test_the_stand_in_blas_check_answers_as_numba_where_scipy_is_missing(monkeypatch):
    numba_setup._scipy_installed()  # scipy is installed: no error
    monkeypatch.setattr(numba_setup.importlib.util, "find_spec", lambda name: None)
    with pytest.raises(ImportError, match="scipy"):
        numba_setup._scipy_installed()
