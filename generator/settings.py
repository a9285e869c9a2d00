"""Settings tables: frozen dataclasses read from a mapping (one table of the TOML config).

Shared by :class:`~surfgen.generator.sampler.SamplerConfig` and
:class:`~surfgen.filters.verdict.FilterConfig`: unknown keys are errors, lists become tuples
(so settings stay hashable and comparable), and every message names the table.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import asdict, fields
from typing import Any, TypeVar

from surfgen.generator.errors import SpecError

T = TypeVar("T")


def settings_from_mapping(cls: type[T], data: Mapping[str, Any], table: str) -> T:
    """``cls(**data)`` for a settings dataclass; :class:`SpecError` for unknown or bad keys."""
    unknown = sorted(set(data) - {f.name for f in fields(cls)})  # type: ignore[arg-type]
    if unknown:
        raise SpecError(f"config [{table}]: unknown key '{unknown[0]}'")
    kw = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
    try:
        return cls(**kw)
    except TypeError as exc:
        raise SpecError(f"config [{table}]: {exc}") from None


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
