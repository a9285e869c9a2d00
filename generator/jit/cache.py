"""numba's on-disk cache, made to go stale with any of surfgen's numba sources.

numba's cache checks only the source file of the cached function itself, but a cached function
carries the machine code of every jitted function it calls from other files: the row table's C
functions (``eval/row_functions.py``) compile the elementary functions *into* their own code, the walls'
classification (``mesh/walls.py``) the points kernels (``eval/point_driver.py``), and so on; the kernels call the
interpreter through a pointer whose calling convention (its arguments) they compile in, and the
interpreter its rows through the row table's (``eval/row_calls.py``). A change of ``trig.py`` or
``interpreter.py`` would leave those callers stale, with the old bits or the old convention.
The locator installed here adds a digest of every
surfgen source that holds numba code to the freshness stamp of every cached function of surfgen
(and, in a source checkout, of its tests and benchmarks).

numba picks a function's locator when the function is decorated, so this must run before any of
surfgen's jitted functions is defined: it runs when numba is first imported (``jit/setup.py``,
put in place by ``surfgen.generator``'s ``__init__``, which ``surfgen.filters`` and
``surfgen.pipelines`` import first). (It was once installed by the
elementary functions' package: a process that imported the mesh or the filters before them gave
their kernels the plain stamp, one that imported them after the surfgen stamp, and each found the
other's cache index stale: every ``surfgen sample`` after a test run, or the other way round,
compiled the mesh and filter kernels again, about 20 s.)
"""

from __future__ import annotations

import hashlib
import logging
import os
from collections.abc import Callable
from typing import Any

from surfgen.generator.jit import interleave as vector_loops

log = logging.getLogger(__name__)

_GENERATOR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_ROOT = os.path.dirname(_GENERATOR)  # surfgen's package (installed) or the checkout (editable)
_NUMBA_MARKS = (b"njit", b"overload", b"_dual", b"intrinsic", b"cfunc")
# Sources without numba code whose constants numba freezes into surfgen's kernels (opcode
# numbers, coefficient tables): a change there must make the cached kernels stale too.
FROZEN_SOURCES = (
    "generator/eval/opcodes.py",
    "generator/elementary/explog_tables.py",
    "generator/elementary/trig_tables.py",
)


def package_digest() -> str:
    """sha256 of every surfgen source file (generator, its elementary functions, filters,
    pipelines) that holds numba code, and the interleave count the evaluator is compiled with."""
    h = hashlib.sha256()
    # how the evaluator is compiled: LLVM's interleave count, and which functions get it
    h.update(b"interleave %d\0" % vector_loops.INTERLEAVE)
    with open(vector_loops.__file__, "rb") as f:
        h.update(f.read())
    for top in ("generator", "filters", "pipelines"):
        for folder, _, names in sorted(os.walk(os.path.join(_ROOT, top))):
            for name in sorted(n for n in names if n.endswith(".py")):
                with open(os.path.join(folder, name), "rb") as f:
                    source = f.read()
                rel = os.path.relpath(os.path.join(folder, name), _ROOT)
                if rel.replace(os.sep, "/") in FROZEN_SOURCES or any(
                    mark in source for mark in _NUMBA_MARKS
                ):
                    h.update(rel.replace(os.sep, "/").encode() + b"\0")
                    h.update(source)
    return h.hexdigest()


def install_cache_stamp() -> None:
    """Put the stamped locator first in numba's list (once per process)."""
    try:  # deferred: this runs as numba is imported, and importing surfgen imports no numba
        from numba.core import caching
    except ImportError:  # pragma: no cover
        return
    inner_classes = list(caching.CacheImpl._locator_classes)
    if any(getattr(c, "_surfgen", False) for c in inner_classes):
        return
    digest = package_digest()

    class _StampedLocator(caching._CacheLocator):
        _surfgen = True

        def __init__(self, inner) -> None:
            self._inner = inner

        def ensure_cache_path(self) -> None:
            self._inner.ensure_cache_path()

        def get_cache_path(self) -> str:
            return self._inner.get_cache_path()

        def get_source_stamp(self):
            return (self._inner.get_source_stamp(), digest)

        def get_disambiguator(self) -> str:
            return self._inner.get_disambiguator()

        @classmethod
        def from_function(cls, py_func, py_file):
            path = os.path.abspath(py_file)
            inside = path[len(_ROOT) :]
            # surfgen's files only (in a checkout, not a virtual environment's packages under it)
            if not path.startswith(_ROOT + os.sep) or f"{os.sep}site-packages{os.sep}" in inside:
                return None
            for c in inner_classes:
                inner = c.from_function(py_func, py_file)
                if inner is not None:
                    return cls(inner)
            return None

    caching.CacheImpl._locator_classes = [_StampedLocator, *inner_classes]


def cached_on_disk(locate: Callable[[], tuple[Any, Any]], name: str) -> bool:
    """Whether numba's on-disk cache holds ``name`` compiled (any signature) for this machine and
    this code (then loading it takes a fraction of a second); ``locate()`` gives its numba cache
    and code generator. True when that cannot be told (numba's internals moved): the caller then
    does what it always did."""
    try:
        cache, codegen = locate()
        index = cache._cache_file._load_index()  # empty when missing or stale
        here = cache._index_key(None, codegen)[1:]
        return any(key[1:] == here for key in index)
    except Exception:
        log.debug("cannot read numba's cache index of %s", name, exc_info=True)
        return True


def c_function_cached(py_func: Callable, name: str) -> bool:
    """:func:`cached_on_disk` for the C function numba's ``cfunc`` makes of ``py_func``."""

    def locate():  # numba deferred: importing surfgen imports no numba
        from numba.core.caching import FunctionCache
        from numba.core.registry import cpu_target

        return FunctionCache(py_func), cpu_target.target_context.codegen()

    return cached_on_disk(locate, name)
