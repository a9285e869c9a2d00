"""Comparisons, logic, ``if`` and ``%`` as MathMod's expression language (fparser) has them.

Decided once, here, for both evaluators (the numba kernels repeat these lines exactly):

- a value is *true* when ``|v| >= 0.5`` (fparser's ``fp_truth``); NaN is false;
- comparisons give 1 or 0 and allow fparser's tolerance ``EPS = 1e-12``:
  ``a < b`` is ``a < b - EPS``, ``a <= b`` is ``a <= b + EPS``, ``a = b`` is ``|a - b| <= EPS``,
  ``a != b`` is ``|a - b| > EPS``; ``>`` and ``>=`` swap their operands. Any NaN operand: 0;
- ``&``, ``|``, ``!`` give 1 or 0 from the truth of their operands;
- ``if(c, a, b)`` is ``a`` where ``c`` is true, else ``b``: the other branch never leaks into
  the result (a pole of ``b`` where ``c`` holds does not make the value NaN). It is lowered to
  ``pick(c, a) + pickn(c, b)``, where the branch not taken contributes an exact 0, so the value
  is exact (only a ``-0`` result becomes ``+0``);
- ``a % b`` is C's ``fmod`` (exact; the sign of ``a``); ``int(x) = floor(x + 0.5)`` (fparser's
  rounding), ``trunc(x)`` rounds towards 0.
"""

from __future__ import annotations

import numpy as np

EPS = 1e-12

COMPARISONS = ("<", "<=", ">", ">=", "=", "!=")
LOGIC = ("&", "|")
OPERATORS = (*COMPARISONS, *LOGIC, "%")


def truth(v: np.ndarray) -> np.ndarray:
    """Boolean array: ``|v| >= 0.5`` (NaN is false)."""
    return np.abs(v) >= 0.5


def _f(mask: np.ndarray) -> np.ndarray:
    return np.where(mask, 1.0, 0.0)


def lt(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return _f(a < b - EPS)


def le(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return _f(a <= b + EPS)


def eq(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return _f(np.abs(a - b) <= EPS)


def ne(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return _f(np.abs(a - b) > EPS)


def and_(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return _f(truth(a) & truth(b))


def or_(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return _f(truth(a) | truth(b))


def not_(a: np.ndarray) -> np.ndarray:
    return _f(~truth(a))


def pick(c: np.ndarray, a: np.ndarray) -> np.ndarray:
    """``a`` where ``c`` is true, else exactly 0."""
    return np.where(truth(c), a, 0.0)


def pickn(c: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exactly 0 where ``c`` is true, else ``b``."""
    return np.where(truth(c), 0.0, b)


def if_(c: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.add(pick(c, a), pickn(c, b))


def fmod(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.fmod(a, b)


def round_half_up(x: np.ndarray) -> np.ndarray:
    """fparser's ``int``: ``floor(x + 0.5)``."""
    return np.floor(np.add(x, 0.5))


def trunc(x: np.ndarray) -> np.ndarray:
    return np.trunc(x)


# Operator node -> numpy function, for the reference evaluator and constant folding.
BINARY = {
    "<": lt,
    "<=": le,
    ">": lambda a, b: lt(b, a),
    ">=": lambda a, b: le(b, a),
    "=": eq,
    "!=": ne,
    "&": and_,
    "|": or_,
    "%": fmod,
}
