"""The registry of surfgen's elementary functions: which module implements each, and each
function's entry (its numba rows and scalar, its numpy twin, numpy's own ufunc).

The implementing modules are numba modules: they are imported when the registry is first
asked for (:func:`registry`), so that importing the formula language costs no numba.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

_PACKAGE = "surfgen.generator.elementary"

UNARY = ("sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh", "asinh")
UNARY += ("acosh", "atanh", "exp", "log", "log10", "cbrt")
BINARY = ("atan2", "pow")

# Which module implements which function (API of LIBM.md). They are numba modules: imported
# when a function is first needed (REGISTRY, call, power, round_trip), so that importing the
# formula language (parser, spec, catalogue) costs no numba.
_PROVIDER: dict[str, str] = {
    **{name: "trig" for name in ("sin", "cos", "tan", "asin", "acos", "atan", "atan2")},
    **{name: "explog" for name in ("exp", "log", "log10", "pow", "sinh", "cosh", "tanh")},
    **{name: "explog" for name in ("asinh", "acosh", "atanh", "cbrt")},
}

UFUNCS: dict[str, Callable[..., np.ndarray]] = {
    "sin": np.sin,
    "cos": np.cos,
    "tan": np.tan,
    "asin": np.arcsin,
    "acos": np.arccos,
    "atan": np.arctan,
    "sinh": np.sinh,
    "cosh": np.cosh,
    "tanh": np.tanh,
    "asinh": np.arcsinh,
    "acosh": np.arccosh,
    "atanh": np.arctanh,
    "exp": np.exp,
    "log": np.log,
    "log10": np.log10,
    "cbrt": np.cbrt,
    "atan2": np.arctan2,
    "pow": np.power,
}


@dataclass(frozen=True)
class Elementary:
    """One function: its numba rows and scalar, its numpy twin, numpy's own ufunc."""

    name: str
    arity: int
    scalar: Callable
    array: Callable[..., np.ndarray]
    ufunc: Callable[..., np.ndarray]
    source: str  # the implementing module
    row: Callable | None = None  # unary
    row_vv: Callable | None = None  # binary
    row_vs: Callable | None = None
    row_sv: Callable | None = None


def _entry(name: str) -> Elementary:
    m = importlib.import_module(f"{_PACKAGE}.{_PROVIDER[name]}")
    common = {
        "name": name,
        "scalar": getattr(m, f"{name}_scalar"),
        "array": getattr(m, f"{name}_array"),
        "ufunc": UFUNCS[name],
        "source": m.__name__,
    }
    if name in BINARY:
        return Elementary(
            arity=2,
            row_vv=getattr(m, f"{name}_row_vv"),
            row_vs=getattr(m, f"{name}_row_vs"),
            row_sv=getattr(m, f"{name}_row_sv"),
            **common,
        )
    return Elementary(arity=1, row=getattr(m, f"{name}_row"), **common)


_REGISTRY: dict[str, Elementary] = {}


def registry() -> dict[str, Elementary]:
    """Every function's entry by name, built (and the numba modules imported) on first use."""
    if not _REGISTRY:
        _REGISTRY.update({name: _entry(name) for name in UNARY + BINARY})
    return _REGISTRY
