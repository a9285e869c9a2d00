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
from surfgen.generator.expr import Expr, params_of, to_string
from surfgen.generator.grid import Box, Grid
from surfgen.generator.parser import parse

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
        object.__setattr__(self, "params", _frozen({k: float(v) for k, v in self.params.items()}))
        object.__setattr__(self, "provenance", _frozen(self.provenance))
        object.__setattr__(self, "box", tuple(float(v) for v in self.box))
        object.__setattr__(self, "grid", tuple(int(v) for v in self.grid))
        if not math.isfinite(self.level):
            raise SpecError(f"level must be a finite number, got {self.level}")
        tree = parse(self.formula, self.params.keys())  # raises FormulaSyntaxError
        missing = sorted(params_of(tree) - self.params.keys())
        if missing:
            raise SpecError(f"parameter '{missing[0]}' has no value")
        object.__setattr__(self, "formula", to_string(tree))
        self.to_grid()  # validates box and grid

    @classmethod
    def from_tree(cls, tree: Expr, box, grid, **kw) -> SurfaceSpec:
        return cls(formula=to_string(tree), box=tuple(box), grid=tuple(grid), **kw)

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
        allowed = {"formula", "params", "box", "grid", "level", "provenance"}
        unknown = sorted(set(data) - allowed)
        if unknown:
            raise SpecError(
                f"spec: unknown key '{unknown[0]}' (allowed: {', '.join(sorted(allowed))})"
            )
        for k in ("formula", "box", "grid"):
            if k not in data:
                raise SpecError(f"spec: missing key '{k}'")
        try:
            box = [float(v) for v in data["box"]]
            grid = data["grid"]
            grid = [int(grid)] * 3 if isinstance(grid, int) else [int(v) for v in grid]
        except (TypeError, ValueError) as exc:
            raise SpecError(f"spec: box and grid must be lists of numbers ({exc})") from None
        if len(box) == 2:
            box = [box[0], box[1]] * 3
        if len(box) != 6 or len(grid) != 3:
            raise SpecError("spec: box needs 2 or 6 numbers and grid 1 or 3 whole numbers")
        return cls(
            formula=str(data["formula"]),
            box=tuple(box),
            grid=tuple(grid),
            params=data.get("params") or {},
            level=float(data.get("level", 0.0)),
            provenance=data.get("provenance") or {},
        )

    @classmethod
    def from_json(cls, text: str) -> SurfaceSpec:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise SpecError(f"spec: not valid JSON ({exc.msg} at line {exc.lineno})") from None
        if not isinstance(data, dict):
            raise SpecError("spec: expected a JSON object")
        return cls.from_dict(data)
