"""surfgen's numba options: every ``njit``, ``cfunc`` and ``overload`` of surfgen takes one of
these sets, by name, so that one place says how surfgen's kernels are compiled and why.

- ``cache``: numba keeps the machine code on disk (stamped with every numba source of surfgen,
  :mod:`surfgen.generator.jit.cache`), so a process loads a kernel instead of compiling it.
- ``error_model="numpy"``: a division by zero gives inf or NaN, as numpy's does, instead of
  raising (no zero test before each division): the paper's formulas have poles and 0/0, which
  are values, not errors.
- ``nogil``: the kernels release the GIL, so the evaluator can run them on a pool of threads.

No set asks for ``fastmath``: the evaluator's results are the reference's bit for bit (no
contraction into FMAs, no reassociation, NaN and inf kept).

This module imports no numba: it is read by modules that do, when they define their kernels
(and by their callers, for :func:`read_only`).
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

#: A kernel: cached, NaN/inf as values, the GIL released.
KERNEL: Mapping[str, Any] = MappingProxyType({"cache": True, "error_model": "numpy", "nogil": True})

#: A small helper of a kernel, inlined into its callers by numba (its IR is copied into theirs,
#: so each caller's LLVM sees the whole loop and vectorises it).
INLINE: Mapping[str, Any] = MappingProxyType({**KERNEL, "inline": "always"})

#: An elementary function's scalar core: a separate numba function that LLVM must inline into
#: every loop that calls it (``alwaysinline``): numba's own inlining of these deep call trees
#: costs much longer compiles, and a call left in a loop would stop its vectorisation.
FORCE_INLINE: Mapping[str, Any] = MappingProxyType({**KERNEL, "forceinline": True})

#: A C function (``numba.cfunc``) called through a pointer: cached, NaN/inf as values (a C
#: function holds no GIL to release).
C_FUNCTION: Mapping[str, Any] = MappingProxyType({"cache": True, "error_model": "numpy"})

#: A helper of a C function only (it unpacks raw pointers into arrays), inlined there.
C_HELPER: Mapping[str, Any] = MappingProxyType({"error_model": "numpy", "inline": "always"})

#: ``jit_options`` of an ``@overload``: the implementation is compiled inside its caller, which
#: is cached itself (``overload`` takes no ``cache`` option).
OVERLOAD: Mapping[str, Any] = MappingProxyType({"error_model": "numpy", "nogil": True})

#: A kernel of the filters (mesh measures): numba's default error model ("python": a division
#: by zero raises ``ZeroDivisionError`` rather than giving inf), cached, the GIL released, as
#: the filters have always been compiled.
CHECKED: Mapping[str, Any] = MappingProxyType({"cache": True, "nogil": True})

__all__ = ["C_FUNCTION", "C_HELPER", "CHECKED", "FORCE_INLINE", "INLINE", "KERNEL", "OVERLOAD"]


def read_only(a: np.ndarray) -> np.ndarray:
    """``a`` read-only: itself when it is, else a read-only view (no copy). Numba compiles a
    kernel once per signature and types read-only arrays apart from writable ones, so a kernel
    whose callers pass both is compiled twice; its callers pass it ``read_only(...)``."""
    if not a.flags.writeable:
        return a
    view = a.view()
    view.flags.writeable = False
    return view
