"""surfgen.generator: formulas, constituent functions, equation (13), evaluation and meshing.

This package imports nothing from ``surfgen.filters`` or ``surfgen.pipelines``.

``SURFGEN_NO_VECTORIZE=1`` in the environment turns off numba's loop and SLP vectorisers for the
evaluator (``NUMBA_LOOP_VECTORIZE=0``, ``NUMBA_SLP_VECTORIZE=0``; it must be set before numba is
imported) and, unless ``NUMBA_CACHE_DIR`` is set, moves numba's on-disk cache to a directory of
its own, because numba's cache key does not include those flags. It changes speed only, never a
bit of a field: the evaluator's arithmetic has no FMA and no reassociation.

On a CPU with AVX-512, numba compiles with 512-bit vectors (:func:`wide_vector_features`):
LLVM's tuning for Intel's AVX-512 Xeons prefers 256-bit ones, which would halve the width of
every loop of the evaluator there while numpy's own SIMD maths runs on 512 bits. Set
``NUMBA_CPU_FEATURES`` (or ``NUMBA_ENABLE_AVX=0``) to keep numba's own choice.
"""

import os as _os
import tempfile as _tempfile

__version__ = "0.1.0"

NO_VECTORIZE = _os.environ.get("SURFGEN_NO_VECTORIZE", "") not in ("", "0")
if NO_VECTORIZE:
    _os.environ["NUMBA_LOOP_VECTORIZE"] = "0"
    _os.environ["NUMBA_SLP_VECTORIZE"] = "0"
    _os.environ.setdefault(
        "NUMBA_CACHE_DIR", _os.path.join(_tempfile.gettempdir(), "surfgen-numba-novectorize")
    )

# numba caches compiled kernels next to their sources, or in the user's cache folder when the
# package is read-only (a system-wide install). When neither is writable (a service account
# without a home), give it a private temporary folder rather than failing at import.
if "NUMBA_CACHE_DIR" not in _os.environ and not _os.access(
    _os.path.dirname(_os.path.abspath(__file__)), _os.W_OK
):
    _home_cache = _os.path.join(_os.path.expanduser("~"), ".cache")
    if not (_os.path.isdir(_home_cache) and _os.access(_home_cache, _os.W_OK)):
        _os.environ["NUMBA_CACHE_DIR"] = _os.path.join(
            _tempfile.gettempdir(), f"surfgen-numba-{_os.getuid()}"
        )


def wide_vector_features(environ, host_features: str) -> str | None:
    """The ``NUMBA_CPU_FEATURES`` that let LLVM use 512-bit vectors on an AVX-512 CPU: the host's
    features with LLVM's tuning flag ``prefer-256-bit`` turned off; ``None`` where there is
    nothing to do (no AVX-512, or the user chose the features or turned AVX off).

    LLVM tunes ``skylake-avx512``, ``icelake-server``, ``sapphirerapids`` ... to prefer 256-bit
    vectors (512-bit instructions once lowered those Xeons' clocks), AMD's Zen 4 and 5 not. On
    the Zen 5, with Intel's code generation (``NUMBA_CPU_NAME=skylake-avx512``) and numpy's
    dispatch cut to that Xeon's, the median fast / numpy ratio of ``benchmarks/bench_eval.py``
    was 2.3-2.4x with 256-bit vectors and 3.0-3.6x with 512-bit ones. Vector width changes no
    bit: every operation is elementwise, without FMA.
    """
    if "NUMBA_CPU_FEATURES" in environ or environ.get("NUMBA_ENABLE_AVX", "") == "0":
        return None
    if "+avx512f" not in host_features.split(","):
        return None
    return host_features + ",-prefer-256-bit"


def _use_wide_vectors() -> None:
    try:
        from llvmlite import binding
    except ImportError:  # pragma: no cover (numba requires llvmlite)
        return
    features = wide_vector_features(_os.environ, binding.get_host_cpu_features().flatten())
    if features is None:
        return
    _os.environ["NUMBA_CPU_FEATURES"] = features  # read by numba at import, and by workers
    import sys

    config = sys.modules.get("numba.core.config")
    if config is not None:  # numba came first: its config has read the environment already
        config.CPU_FEATURES = features


_use_wide_vectors()

# Last: numba reads the settings above when it is imported. Before any jitted function of
# surfgen is defined (numba picks a function's cache locator then): see numba_cache.py.
from surfgen.generator.numba_cache import install_cache_stamp as _install_cache_stamp  # noqa: E402

_install_cache_stamp()

# Before any of surfgen's functions is compiled too: four vectors per iteration in the
# evaluator's loops (vector_loops.py).
from surfgen.generator.vector_loops import install as _install_interleave  # noqa: E402

_install_interleave()
