"""Hard cases for the row division (``generator/elementary/division.py``), shared by
``tests/generator/elementary/test_division.py`` and ``benchmarks/row_division.py``."""

from __future__ import annotations

import numpy as np


def midpoint_row(rng: np.random.Generator) -> tuple[np.ndarray, float] | None:
    """One row of quotients next to a rounding midpoint with their own divisor: for a random
    odd 53-bit S and each odd t in [-63, 63], the 53-bit X with X * 2**54 = S*M + t, M an odd
    54-bit midpoint of 53-bit quotients, so X/S is within |t|/S of an ulp (below 2**-46) of
    M / 2**54; dividends and divisor scaled by random powers of two, a random sign. None when
    no t gives a 53-bit X (rare)."""
    S = int(rng.integers(1 << 52, 1 << 53)) | 1
    inv = pow(S, -1, 1 << 54)
    xs = []
    for t in range(-63, 64, 2):
        M = (-t * inv) % (1 << 54)
        X = (S * M + t) >> 54
        if M >= (1 << 53) and (1 << 52) <= X < (1 << 53):
            xs.append(float(X))
    if not xs:
        return None
    x = np.ldexp(np.array(xs), int(rng.integers(-840, 840))) * float(rng.choice([-1.0, 1.0]))
    return x, float(np.ldexp(float(S), int(rng.integers(-150, 40))))
