"""surfgen.generator: formulas, constituent functions, equation (13), evaluation and meshing.

This package imports nothing from ``surfgen.filters`` or ``surfgen.pipelines``.

``SURFGEN_NO_VECTORIZE=1`` in the environment turns off numba's loop and SLP vectorisers for the
evaluator (``NUMBA_LOOP_VECTORIZE=0``, ``NUMBA_SLP_VECTORIZE=0``; it must be set before numba is
imported) and, unless ``NUMBA_CACHE_DIR`` is set, moves numba's on-disk cache to a directory of
its own, because numba's cache key does not include those flags. It changes speed only, never a
bit of a field: the evaluator's arithmetic has no FMA and no reassociation.
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
