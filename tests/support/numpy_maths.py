"""numpy's transcendental ufuncs made inexact on purpose, to show that something does not use them.

numpy runs SIMD maths of its own for these where the CPU has it (on AVX-512 Xeons arccos, tan,
power, log2, ... are an ulp or two from the C library's), so whatever depends on them differs
from one machine to another. :func:`shift_numpy` replaces each in numpy's namespace by a copy
whose float results are scaled by ``1 + shift``: far more than any CPU's difference, so that any
use shows through rounded outputs. (numpy's operator ``**`` is not reached.)
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

TRANSCENDENTALS = (
    "sin", "cos", "tan", "arcsin", "arccos", "arctan", "arctan2", "sinh", "cosh", "tanh",
    "arcsinh", "arccosh", "arctanh", "exp", "exp2", "expm1", "log", "log2", "log10", "log1p",
    "cbrt", "power", "float_power",
)  # fmt: skip


def shifted(ufunc: np.ufunc, shift: float) -> Callable:
    """``ufunc`` with its float results scaled by ``1 + shift`` (in place where it wrote ``out``)."""
    factor = 1.0 + shift

    def call(*args, **kwargs):
        out = ufunc(*args, **kwargs)
        if np.asarray(out).dtype.kind != "f":
            return out
        if isinstance(out, np.ndarray):
            return np.multiply(out, factor, out=out)
        return out * factor

    return call


def shifted_ufuncs(shift: float) -> dict[str, Callable]:
    """Every one of :data:`TRANSCENDENTALS`, :func:`shifted`, by name."""
    return {name: shifted(getattr(np, name), shift) for name in TRANSCENDENTALS}


def shift_numpy(shift: float) -> None:
    """Put :func:`shifted_ufuncs` in numpy's namespace for the rest of this process (a child's).
    numba's tables of numpy's ufuncs are built first, from the plain ones."""
    import numba.core.typing.npydecl  # noqa: F401
    import numba.np.npyimpl  # noqa: F401

    for name, fn in shifted_ufuncs(shift).items():
        setattr(np, name, fn)
