"""A shape as data: :class:`SurfaceSpec` (formula, params, box, grid, level, provenance).

Its canonical JSON (sorted keys, no spaces, floats as shortest repr) is what gets hashed:
the first 16 hex digits of its sha256 are the shape's ``key`` and file stem.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from surfgen.generator.errors import SpecError
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.expr import Expr, params_of, to_string
from surfgen.generator.formula.limits import MAX_JSON_DEPTH, MAX_SPEC_FILE_BYTES, json_depth_ok
from surfgen.generator.formula.parser import parse

KEY_LENGTH = 16


def _frozen(mapping: Mapping | None) -> Mapping:
    return MappingProxyType(dict(mapping or {}))


@dataclass(frozen=True)
class SurfaceSpec:
    """Everything needed to regenerate one shape.

    ``formula`` is the canonical formula text; ``params`` binds its named parameters;
    ``box`` is ``(xmin, xmax, ymin, ymax, zmin, zmax)``; ``grid`` is ``(Nx, Ny, Nz)``;
    ``provenance`` says where it came from (preset name, or seed/index/sampler version).
    """

    formula: str
    box: tuple[float, float, float, float, float, float]
    grid: tuple[int, int, int]
    params: Mapping[str, float] = field(default_factory=dict)
    level: float = 0.0
    provenance: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._settle(None)

    def _settle(self, tree: Expr | None) -> None:
        """Normalise and check the fields; the formula becomes ``tree`` printed (``None``: the
        formula parsed)."""
        object.__setattr__(self, "params", _frozen({k: float(v) for k, v in self.params.items()}))
        object.__setattr__(self, "provenance", _frozen(self.provenance))
        object.__setattr__(self, "box", tuple(float(v) for v in self.box))
        object.__setattr__(self, "grid", tuple(int(v) for v in self.grid))
        if not math.isfinite(self.level):
            raise SpecError(f"level must be a finite number, got {self.level}")
        if tree is None:
            tree = parse(self.formula, self.params.keys())  # raises FormulaSyntaxError
        used = params_of(tree)
        missing = sorted(used - self.params.keys())
        if missing:
            raise SpecError(f"parameter '{missing[0]}' has no value")
        unused = sorted(self.params.keys() - used)
        if unused:  # a typo in --param or a spec file would otherwise be silently ignored
            raise SpecError(
                f"parameter '{_shown(unused[0])}' is not used by the formula "
                f"(its parameters: {', '.join(sorted(used)) or 'none'})"
            )
        object.__setattr__(self, "formula", to_string(tree))
        self.to_grid()  # validates box and grid

    @classmethod
    def from_tree(
        cls,
        tree: Expr,
        box,
        grid,
        params: Mapping[str, float] | None = None,
        level: float = 0.0,
        provenance: Mapping[str, Any] | None = None,
    ) -> SurfaceSpec:
        """The spec of a tree built in code (the sampler's draws): the same spec as
        ``SurfaceSpec(to_string(tree), ...)``, without parsing the printed formula back (the
        printer is the parser's fixed point: tests/generator/test_parser.py)."""
        spec = cls.__new__(cls)
        fields = {"formula": "", "box": tuple(box), "grid": tuple(grid), "params": params or {}}
        fields.update(level=level, provenance=provenance or {})
        for name, value in fields.items():
            object.__setattr__(spec, name, value)
        spec._settle(tree)
        return spec

    def tree(self) -> Expr:
        return parse(self.formula, self.params.keys())

    def to_grid(self) -> Grid:
        return Grid(Box.from_bounds(self.box), self.grid)

    def to_dict(self) -> dict[str, Any]:
        return {
            "formula": self.formula,
            "params": dict(sorted(self.params.items())),
            "box": list(self.box),
            "grid": list(self.grid),
            "level": self.level,
            "provenance": dict(sorted(self.provenance.items())),
        }

    def to_json(self) -> str:
        """Canonical JSON: sorted keys, compact separators, exact floats."""
        return json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"), allow_nan=False)

    @property
    def identity(self) -> str:
        """What makes two shapes exact duplicates: the spec without its provenance."""
        d = self.to_dict()
        d.pop("provenance")
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:KEY_LENGTH]

    @property
    def key(self) -> str:
        return hashlib.sha256(self.to_json().encode()).hexdigest()[:KEY_LENGTH]

    def replace(self, **changes: Any) -> SurfaceSpec:
        d = {
            "formula": self.formula,
            "box": self.box,
            "grid": self.grid,
            "params": dict(self.params),
            "level": self.level,
            "provenance": dict(self.provenance),
        }
        d.update(changes)
        return SurfaceSpec(**d)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SurfaceSpec:
        """A spec from decoded JSON, every field's type and range checked first.

        Raises :class:`SpecError` naming the field, the value and what is allowed.
        """
        if not isinstance(data, Mapping):
            raise SpecError(f"spec: expected a JSON object, got {_kind(data)}")
        allowed = ("box", "formula", "grid", "level", "params", "provenance")
        unknown = sorted(str(k) for k in set(data) - set(allowed))
        if unknown:
            raise SpecError(
                f"spec: unknown key '{_shown(unknown[0])}' (allowed: {', '.join(allowed)})"
            )
        for k in ("formula", "box", "grid"):
            if k not in data:
                raise SpecError(f"spec: missing key '{k}'")
        formula = data["formula"]
        if not isinstance(formula, str):
            raise SpecError(f"spec: formula must be text, got {_kind(formula)}")
        box = _numbers(data["box"], "box", (2, 6), "2 or 6 finite numbers")
        raw_grid = data["grid"]
        grid = _numbers(
            [raw_grid] if _is_int(raw_grid) else raw_grid,
            "grid",
            (1, 3),
            "a whole number or a list of 1 or 3 whole numbers",
            whole=True,
        )
        params = data.get("params", {})
        if params is None:
            params = {}
        if not isinstance(params, Mapping):
            raise SpecError(f"spec: params must be an object {{name: number}}, got {_kind(params)}")
        for name, value in params.items():
            if not isinstance(value, int | float) or isinstance(value, bool):
                raise SpecError(
                    f"spec: params.{_shown(name)} must be a finite number, got {_kind(value)}"
                )
            if not math.isfinite(value):
                raise SpecError(f"spec: params.{_shown(name)} must be a finite number, got {value}")
        level = data.get("level", 0.0)
        if (
            not isinstance(level, int | float)
            or isinstance(level, bool)
            or not math.isfinite(level)
        ):
            raise SpecError(f"spec: level must be a finite number, got {_kind(level)}")
        provenance = data.get("provenance", {})
        if provenance is None:
            provenance = {}
        if not isinstance(provenance, Mapping):
            raise SpecError(
                f"spec: provenance must be an object {{name: value}}, got {_kind(provenance)}"
            )
        for name, value in provenance.items():
            try:  # any JSON value (a variant records its changes as an object), finite numbers
                json.dumps(value, allow_nan=False)
            except (TypeError, ValueError):
                raise SpecError(
                    f"spec: provenance.{_shown(name)} must be a JSON value with finite numbers, "
                    f"got {_kind(value)}"
                ) from None
        if len(box) == 2:
            box = [box[0], box[1]] * 3
        if len(grid) == 1:
            grid = grid * 3
        return cls(
            formula=formula,
            box=tuple(box),
            grid=tuple(grid),
            params=params,
            level=float(level),
            provenance=provenance,
        )

    @classmethod
    def from_json(cls, text: str) -> SurfaceSpec:
        """A spec from JSON text (at most :data:`MAX_SPEC_FILE_BYTES`, nesting at most
        :data:`MAX_JSON_DEPTH`; ``NaN`` and ``Infinity`` are not JSON). Raises :class:`SpecError`."""
        if len(text) > MAX_SPEC_FILE_BYTES:
            raise SpecError(
                f"spec: {len(text)} characters is too long (at most {MAX_SPEC_FILE_BYTES})"
            )
        if not json_depth_ok(text):
            raise SpecError(f"spec: JSON nested more than {MAX_JSON_DEPTH} levels deep")
        try:
            data = json.loads(text, parse_constant=_no_constant)
        except json.JSONDecodeError as exc:
            raise SpecError(f"spec: not valid JSON ({exc.msg} at line {exc.lineno})") from None
        if not isinstance(data, dict):
            raise SpecError(f"spec: expected a JSON object, got {_kind(data)}")
        return cls.from_dict(data)


def _no_constant(name: str) -> float:
    raise json.JSONDecodeError(f"{name} is not a JSON number", name, 0)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _kind(v: Any) -> str:
    """A value for an error message: short, with its JSON type when that is the problem."""
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f"text {_shown(json.dumps(v))}"
    if isinstance(v, Mapping):
        return f"an object {_shown(json.dumps(v, default=str))}"
    if isinstance(v, list | tuple):
        return f"a list {_shown(json.dumps(v, default=str))}"
    return _shown(repr(v))


def _shown(text: Any, limit: int = 40) -> str:
    text = str(text)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _numbers(
    value: Any, name: str, counts: tuple[int, ...], allowed: str, whole: bool = False
) -> list:
    """``value`` as a list of finite numbers (whole ones with ``whole``) of an allowed length."""
    if not isinstance(value, list | tuple) or len(value) not in counts:
        raise SpecError(f"spec: {name} must be {allowed}, got {_kind(value)}")
    for v in value:
        ok = _is_int(v) if whole else isinstance(v, int | float) and not isinstance(v, bool)
        if not ok or (isinstance(v, float) and not math.isfinite(v)):
            raise SpecError(f"spec: {name} must be {allowed}, got {_kind(value)}")
    return [int(v) if whole else float(v) for v in value]
