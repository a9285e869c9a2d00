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
``NUMBA_CPU_FEATURES`` (or ``NUMBA_ENABLE_AVX=0``) to keep numba's own choice. That and
surfgen's other numba settings apply when numba is first imported (:mod:`.jit.setup`):
importing surfgen does not import numba.
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


# numba's settings (512-bit vectors on AVX-512 CPUs, the cache stamp, four vectors per
# iteration in the evaluator's loops) are applied when numba is first imported, before any of
# surfgen's jitted functions is defined: importing surfgen imports no numba (jit/setup.py).
from surfgen.generator.jit.setup import install as _install_numba_setup  # noqa: E402
from surfgen.generator.jit.setup import wide_vector_features  # noqa: E402, F401

_install_numba_setup()
