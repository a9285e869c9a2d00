"""surfgen's settings for numba, applied when numba is first imported, and not before.

Three things must happen around numba's import, whoever imports it first (surfgen's kernels, a
test, the user's own code):

- before: on a CPU with AVX-512, ``NUMBA_CPU_FEATURES`` without LLVM's ``prefer-256-bit``
  (:func:`wide_vector_features`), which numba reads when it is imported;
- after, before any of surfgen's jitted functions is defined: the cache locator that stamps
  surfgen's numba sources (:mod:`surfgen.generator.jit.cache`), the listener that compiles
  the evaluator's loops with four vectors per iteration (:mod:`surfgen.generator.jit.interleave`),
  and cached kernels loaded without a parsed copy for linking (:mod:`surfgen.generator.jit.linking`).

They used to run when ``surfgen.generator`` was imported, which imported numba (and llvmlite,
and through them scipy) into every process: about a second before ``surfgen --help`` or
``surfgen catalogue list`` could print anything, for commands that never compile. :func:`install`
instead puts a finder first on ``sys.meta_path`` that wraps numba's loader once: the import of
numba itself runs the settings, at the same moment as before relative to numba, and a command
that needs no kernel never pays for them. If numba is already imported, they run at once.

The same finder then waits for one of numba's own modules, ``numba.np.arraymath``, which numba
imports when a process first compiles or loads a kernel, and which checks on import whether
``np.dot`` may call BLAS by importing scipy's (``scipy.linalg``, 15 MiB and 0.15-0.2 s of a
process's first kernel: :func:`_defer_blas_check`).
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import importlib.util
import os
import sys
import threading
from collections.abc import Callable, Mapping
from types import ModuleType
from typing import Any

from surfgen.generator.jit.cache import install_cache_stamp
from surfgen.generator.jit.interleave import install as install_interleave
from surfgen.generator.jit.linking import install_lazy_linking

_LOCK = threading.Lock()
_DONE = False


def wide_vector_features(environ: Mapping[str, str], host_features: str) -> str | None:
    """The ``NUMBA_CPU_FEATURES`` that let LLVM use 512-bit vectors on an AVX-512 CPU: the host's
    features with LLVM's tuning flag ``prefer-256-bit`` turned off; ``None`` where there is
    nothing to do (no AVX-512, or the user chose the features or turned AVX off).

    LLVM tunes ``skylake-avx512``, ``icelake-server``, ``sapphirerapids`` ... to prefer 256-bit
    vectors (512-bit instructions once lowered those Xeons' clocks), AMD's Zen 4 and 5 not. On
    the Zen 5, with Intel's code generation (``NUMBA_CPU_NAME=skylake-avx512``) and numpy's
    dispatch cut to that Xeon's, the median fast / numpy ratio of ``benchmarks/eval_speed.py``
    was 2.3-2.4x with 256-bit vectors and 3.0-3.6x with 512-bit ones. Vector width changes no
    bit: every operation is elementwise, without FMA.
    """
    if "NUMBA_CPU_FEATURES" in environ or environ.get("NUMBA_ENABLE_AVX", "") == "0":
        return None
    if "+avx512f" not in host_features.split(","):
        return None
    return host_features + ",-prefer-256-bit"


def _use_wide_vectors() -> None:
    try:  # deferred: llvmlite is loaded with numba, never by importing surfgen
        from llvmlite import binding
    except ImportError:  # pragma: no cover (numba requires llvmlite)
        return
    features = wide_vector_features(os.environ, binding.get_host_cpu_features().flatten())
    if features is None:
        return
    os.environ["NUMBA_CPU_FEATURES"] = features  # read by numba at import, and by workers
    config = sys.modules.get("numba.core.config")
    if config is not None:  # numba came first: its config has read the environment already
        config.CPU_FEATURES = features


def _after_numba() -> None:
    """What must follow numba's import and precede surfgen's first jitted function."""
    global _DONE
    with _LOCK:
        if _DONE:
            return
        install_cache_stamp()
        install_interleave()
        install_lazy_linking()
        _DONE = True


def installed() -> bool:
    """Whether numba has been imported and given surfgen's settings in this process."""
    return _DONE


def _scipy_installed() -> None:
    """numba's BLAS check (``ensure_blas``) as ``numba.np.arraymath`` makes it on import: the
    same answer where scipy is installed or not, without importing it."""
    if importlib.util.find_spec("scipy") is None:
        raise ImportError("scipy 0.16+ is required for linear algebra")  # numba's own message


def _defer_blas_check() -> Callable[[ModuleType, bool], None]:
    """Before ``numba.np.arraymath`` runs: its check for a BLAS told whether scipy is installed
    rather than importing ``scipy.linalg``; returns what puts numba's own check back after.

    arraymath uses the answer only to choose between BLAS and a loop for ``np.dot`` of vectors,
    and numba's linear algebra calls its own check (import, and the Fortran integers' width)
    whenever a kernel that uses it is compiled, so nothing that needs scipy.linalg goes without
    it. A process that loads surfgen's kernels (none uses BLAS) no longer imports it: 15 MiB
    less and 0.15-0.2 s sooner (a cached kernel's first load 0.33 -> 0.14 s, measured on a
    2-core AMD EPYC Zen 2)."""
    try:
        from numba.np import linalg
    except ImportError:  # pragma: no cover (a numba without the module: nothing to defer)
        return lambda module, ran: None
    real = getattr(linalg, "ensure_blas", None)
    if real is None:  # pragma: no cover (a numba that checks otherwise)
        return lambda module, ran: None
    linalg.ensure_blas = _scipy_installed

    def restore(module: ModuleType, ran: bool) -> None:  # whether or not the module ran
        linalg.ensure_blas = real
        if getattr(module, "ensure_blas", None) is _scipy_installed:  # arraymath's own name
            module.ensure_blas = real

    return restore


def _before_numba() -> Callable[[ModuleType, bool], None]:
    _use_wide_vectors()
    return lambda module, ran: _after_numba() if ran else None


#: The modules whose import the finder wraps: what runs before each, returning what runs after
#: (given the module and whether it ran to its end).
_WRAPPED: dict[str, Callable[[], Callable[[ModuleType, bool], None]]] = {
    "numba": _before_numba,
    "numba.np.arraymath": _defer_blas_check,
}


class _Loader(importlib.abc.Loader):
    """A module's own loader, with surfgen's steps before and after it runs the module (for
    numba, its ``__init__``); everything else (resources, code, file names) is the wrapped
    loader's."""

    def __init__(
        self, inner: Any, before: Callable[[], Callable[[ModuleType, bool], None]]
    ) -> None:
        self._inner = inner
        self._before = before

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        return self._inner.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        after = self._before()
        ran = False
        try:
            self._inner.exec_module(module)
            ran = True
        finally:
            after(module, ran)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)


_FINDING = threading.local()


class _Finder(importlib.abc.MetaPathFinder):
    """Finds nothing but the modules of :data:`_WRAPPED`, once each: their spec as the other
    finders give it, the loader wrapped. It leaves ``sys.meta_path`` once they are all in."""

    def find_spec(
        self, fullname: str, path: Any = None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        if fullname not in _WRAPPED or getattr(_FINDING, "name", None) == fullname:
            return None
        _FINDING.name = fullname  # the other finders asked below: not this one again
        try:
            spec = importlib.util.find_spec(fullname)
        finally:
            _FINDING.name = None
        if spec is not None and spec.loader is not None:
            spec.loader = _Loader(spec.loader, _WRAPPED[fullname])
        if all(name in sys.modules or name == fullname for name in _WRAPPED):
            _remove_finder()
        return spec


def _remove_finder() -> None:
    sys.meta_path[:] = [f for f in sys.meta_path if not isinstance(f, _Finder)]


def install() -> None:
    """Apply surfgen's numba settings when numba is imported (at once if it already is)."""
    if "numba" in sys.modules:
        _use_wide_vectors()
        _after_numba()
    if all(name in sys.modules for name in _WRAPPED):
        return
    if not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.insert(0, _Finder())
