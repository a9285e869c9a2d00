"""surfgen's elementary functions: one registry for every transcendental of the formula language.

Each function exists three times with the **same IEEE operation sequence** (contract:
``LIBM.md`` of issue 9), so the fast evaluator and the numpy reference agree bit for bit on every
CPU, whatever numpy's SIMD dispatch and the C library do:

- ``row`` (numba, unary) ``row(W, d, a, n)``: ``W[d, k] = f(W[a, k])`` for ``k < n`` on the
  interpreter's register file; binary functions have ``row_vv(W, d, a, b, n)``,
  ``row_vs(W, d, a, s, n)`` and ``row_sv(W, d, s, b, n)`` (``s`` a float64 scalar);
- ``scalar`` (numba): one value, same bits;
- ``array`` (plain numpy): any shape (broadcasting), same bits.

``ufunc`` is numpy's own function of the same name; it is *not* used to evaluate formulas, only
as an accuracy cross-check and as the benchmark's baseline (:func:`numpy_ufuncs`).

The numpy-level API used by the reference evaluator, the constituent functions and the
compiler's constant folding is :func:`call`, :func:`power` (with the ``x^c`` convention) and
:func:`round_trip`; inside ``with numpy_ufuncs():`` they compute with numpy's ufuncs instead.
"""

from __future__ import annotations

import contextlib
import contextvars
import importlib
from collections.abc import Iterator

import numpy as np

from surfgen.generator.elementary.registry import BINARY, UFUNCS, UNARY, Elementary, registry

# ----------------------------------------------------------------------------- the registry


def __getattr__(name: str):
    # REGISTRY (every function's entry) and ROUND_TRIPS (the names of the closed-form round
    # trips) live in the numba modules: they are loaded on first use (PEP 562).
    if name == "REGISTRY":
        return registry()
    if name == "ROUND_TRIPS":
        return _roundtrip().ROUND_TRIPS
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _roundtrip():
    """The round trips' module, imported on first use: a numba module (importing the formula
    language imports no numba). It imports the registry, not this package's ``__init__``."""
    return importlib.import_module("surfgen.generator.elementary.roundtrip")


# ----------------------------------------------------------------------------- numpy-level API

_BACKEND: contextvars.ContextVar[str] = contextvars.ContextVar("surfgen_maths", default="surfgen")


@contextlib.contextmanager
def numpy_ufuncs() -> Iterator[None]:
    """Inside this block :func:`call`, :func:`power` and :func:`round_trip` compute with numpy's
    own ufuncs (SIMD maths where the CPU has it, the direct forms of the round trips): the
    accuracy cross-check and the benchmark's baseline. Results then depend on the CPU."""
    token = _BACKEND.set("numpy")
    try:
        yield
    finally:
        _BACKEND.reset(token)


def using_numpy_ufuncs() -> bool:
    """Whether the caller is inside :func:`numpy_ufuncs`."""
    return _BACKEND.get() == "numpy"


def call(name: str, *args) -> np.ndarray:
    """``name(*args)`` on arrays (float64, broadcasting) with surfgen's function."""
    if _BACKEND.get() == "numpy":
        return UFUNCS[name](*args)
    return registry()[name].array(*(np.asarray(a, np.float64) for a in args))


# ``x^c`` convention (numpy's fast path of np.power, kept as a rule applied per element by both
# evaluators): an exponent equal to 2, 0.5, -1, 1 or 0 gives u*u, sqrt(u), 1/u, u and 1.
# It differs from C pow only for sqrt: sqrt(-0) = -0 and sqrt(-inf) = NaN where pow gives +0, +inf.
POW_SHORTCUTS = (2.0, 0.5, -1.0, 1.0, 0.0)


def _pow_shortcut(u: np.ndarray, e: float) -> np.ndarray | None:
    if e == 2.0:
        return u * u
    if e == 0.5:
        return np.sqrt(u)
    if e == -1.0:
        return 1.0 / u
    if e == 1.0:
        return u.copy()
    if e == 0.0:
        return np.ones_like(u)
    return None


def power(u, e) -> np.ndarray:
    """``u^e`` of the formula language: C ``pow`` (surfgen's) with the ``x^c`` convention."""
    u = np.asarray(u, np.float64)
    e = np.asarray(e, np.float64)
    if _BACKEND.get() == "numpy":
        return np.power(u, e)
    with np.errstate(all="ignore"):
        if e.ndim == 0:
            short = _pow_shortcut(u, float(e))
            return short if short is not None else registry()["pow"].array(u, e)
        out = registry()["pow"].array(u, e)
        out = np.where(e == 2.0, u * u, out)
        out = np.where(e == 0.5, np.sqrt(u), out)
        out = np.where(e == -1.0, 1.0 / u, out)
        out = np.where(e == 1.0, u, out)
        return np.where(e == 0.0, 1.0, out)


def round_trip(name: str, u) -> np.ndarray:
    """A closed-form round trip (``"atantan"`` = ``atan(tan(u))``, ...; see :mod:`.roundtrip`)."""
    roundtrip = _roundtrip()
    if _BACKEND.get() == "numpy":
        return roundtrip.direct_array(name, np.asarray(u, np.float64), UFUNCS)
    return roundtrip.ARRAYS[name](np.asarray(u, np.float64))


__all__ = [
    "BINARY",
    "Elementary",
    "POW_SHORTCUTS",
    "REGISTRY",
    "ROUND_TRIPS",
    "UFUNCS",
    "UNARY",
    "call",
    "numpy_ufuncs",
    "power",
    "round_trip",
    "using_numpy_ufuncs",
]
