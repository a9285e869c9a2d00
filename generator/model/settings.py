"""Settings tables: frozen dataclasses read from a mapping (one table of the TOML config).

Shared by :class:`~surfgen.generator.model.sampler.SamplerConfig` and
:class:`~surfgen.filters.verdict.FilterConfig`: unknown keys are errors, lists become tuples
(so settings stay hashable and comparable), and every message names the table.
"""

from __future__ import annotations

import math
import types
from collections.abc import Iterable, Mapping
from dataclasses import asdict, fields
from typing import Any, Literal, TypeVar, Union, get_args, get_origin, get_type_hints

from surfgen.generator.errors import SpecError

T = TypeVar("T")


def settings_from_mapping(cls: type[T], data: Mapping[str, Any], table: str) -> T:
    """``cls(**data)`` for a settings dataclass; :class:`SpecError` for unknown or bad keys.

    Every value is checked against the field's type hint first (so a new field is validated
    without code of its own): ``bool`` takes only true/false, ``int`` whole numbers, ``float``
    finite numbers, ``tuple[X, ...]`` lists of X, ``tuple[X, Y]`` lists of exactly two.
    """
    unknown = sorted(set(data) - {f.name for f in fields(cls)})  # type: ignore[arg-type]
    if unknown:
        raise SpecError(f"config [{table}]: unknown key '{_shown(unknown[0])}'")
    hints = get_type_hints(cls)
    kw = {k: check_setting(v, hints.get(k, Any), table, k) for k, v in data.items()}
    try:
        return cls(**kw)
    except TypeError as exc:
        raise SpecError(f"config [{table}]: {exc}") from None


def check_setting(value: Any, hint: Any, table: str, name: str) -> Any:
    """``value`` converted to the type ``hint`` names (lists become tuples, whole numbers
    floats where a float is wanted); :class:`SpecError` naming table, key, value and type."""
    ok, out = _convert(value, hint)
    if not ok:
        raise SpecError(
            f"config [{table}]: {name} must be {describe_type(hint)}, got {_shown(_toml(value))}"
        )
    return out


def _convert(value: Any, hint: Any) -> tuple[bool, Any]:
    origin, args = get_origin(hint), get_args(hint)
    if hint is Any:
        return True, value
    if hint is bool:
        return isinstance(value, bool), value
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool), value
    if hint is float:
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        return ok and math.isfinite(value), float(value) if ok else value
    if hint is str:
        return isinstance(value, str), value
    if origin is tuple:
        if not isinstance(value, list | tuple):
            return False, value
        if len(args) == 2 and args[1] is Ellipsis:
            kinds = [args[0]] * len(value)
        elif len(value) != len(args):
            return False, value
        else:
            kinds = list(args)
        out = []
        for v, k in zip(value, kinds, strict=True):
            ok, c = _convert(v, k)
            if not ok:
                return False, value
            out.append(c)
        return True, tuple(out)
    if origin is Literal:
        return value in args, value
    if origin in (Union, types.UnionType):
        if value is None:
            return type(None) in args, value
        for a in args:
            if a is not type(None):
                ok, c = _convert(value, a)
                if ok:
                    return True, c
        return False, value
    return True, value


def describe_type(hint: Any) -> str:
    """Words for a type hint: ``tuple[float, float]`` → ``'a list of 2 finite numbers'``."""
    origin, args = get_origin(hint), get_args(hint)
    words = {bool: "true or false", int: "a whole number", float: "a finite number", str: "text"}
    if hint in words:
        return words[hint]
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_plural(args[0])}"
        if len(set(args)) == 1:
            return f"a list of {len(args)} {_plural(args[0])}"
        return "a list of " + ", ".join(describe_type(a) for a in args)
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin in (Union, types.UnionType):
        return " or ".join("nothing" if a is type(None) else describe_type(a) for a in args)
    return getattr(hint, "__name__", str(hint))


def _plural(hint: Any) -> str:
    return {bool: "true/false", int: "whole numbers", float: "finite numbers", str: "texts"}.get(
        hint, describe_type(hint)
    )


def _toml(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value + '"'
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return repr(value)


def _shown(text: str, limit: int = 60) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def require_range(obj: Any, name: str, low: float, high: float, table: str) -> None:
    """Each number of field ``name`` (a number or a list) lies in [low, high]."""
    v = getattr(obj, name)
    for x in v if isinstance(v, tuple) else (v,):
        if not low <= x <= high:
            raise SpecError(f"config [{table}]: {name} must be from {low:g} to {high:g}, got {x}")


def settings_to_dict(obj: Any) -> dict[str, Any]:
    """The dataclass as TOML/JSON-ready values (tuples become lists)."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(obj).items()}


def require_fractions(obj: Any, names: Iterable[str], table: str, noun: str = "") -> None:
    """Each named field lies in [0, 1]; ``noun`` (e.g. "a probability") words the message."""
    for name in names:
        v = getattr(obj, name)
        if not 0 <= v <= 1:
            what = f"{noun} in [0, 1]" if noun else "in [0, 1]"
            raise SpecError(f"config [{table}]: {name} must be {what}, got {v}")


def require_weighted_pairs(obj: Any, pairs: Iterable[tuple[str, str]], table: str) -> None:
    """Each ``(choices, weights)`` pair: non-empty lists of one length, weights non-negative
    and not all zero."""
    for a, b in pairs:
        if len(getattr(obj, a)) != len(getattr(obj, b)) or not getattr(obj, a):
            raise SpecError(
                f"config [{table}]: {a} and {b} must be non-empty lists of the same length"
            )
        weights = getattr(obj, b)
        total = float(sum(weights))  # a float sum overflows to inf, silently
        if any(w < 0 for w in weights) or total <= 0:
            raise SpecError(f"config [{table}]: {b} must be non-negative and not all zero")
        # a draw divides each weight by their sum: check what it uses, not only each number
        if not math.isfinite(total):
            raise SpecError(
                f"config [{table}]: {b} add up to {total} (each is divided by their sum, which "
                f"must be finite): use smaller weights, only their ratios matter"
            )


def require_low_high(obj: Any, names: Iterable[str], table: str) -> None:
    """Each named field is ``[low, high]`` with low <= high."""
    for name in names:
        if len(getattr(obj, name)) != 2:
            raise SpecError(f"config [{table}]: {name} must be [low, high]")
        lo, hi = getattr(obj, name)
        if not lo <= hi:
            raise SpecError(f"config [{table}]: {name} must be [low, high] with low <= high")


def require_names(obj: Any, name: str, allowed: Iterable[str], table: str) -> None:
    """Field ``name`` lists names from ``allowed``, none twice (one-line errors saying what is
    allowed)."""
    allowed = tuple(allowed)
    values = getattr(obj, name)
    bad = [v for v in values if v not in allowed]
    if bad:
        raise SpecError(
            f"config [{table}]: {name} has unknown {bad[0]!r} (allowed: {', '.join(allowed)})"
        )
    if len(set(values)) != len(values):
        raise SpecError(f"config [{table}]: {name} lists a name twice")


def require_numbers(obj: Any, names: Iterable[str], table: str) -> None:
    """Each named field is a list of finite numbers (not booleans)."""
    for name in names:
        for w in getattr(obj, name):
            if isinstance(w, bool) or not isinstance(w, int | float) or not math.isfinite(w):
                raise SpecError(f"config [{table}]: {name} must be numbers, got {w!r}")
