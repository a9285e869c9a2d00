"""What an explore step can change: the formula's numeric literals, change sets and sliders.

A change set (``changes``) is a flat JSON object applied to a base :class:`SurfaceSpec` by
:func:`apply_changes` (the keys are listed in :mod:`surfgen.pipelines.studies.explore`);
:func:`check_changes` validates one, :func:`knobs_of` lists the sliders a page shows for a spec.
Grids are refused over :data:`MAX_POINTS` samples (one request cannot take the machine).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from surfgen.generator.errors import SurfgenError
from surfgen.generator.eval.grid import MIN_POINTS, Box, Grid
from surfgen.generator.formula.expr import Expr, to_string, walk
from surfgen.generator.model.spec import SurfaceSpec

MAX_GRID = 160  # points per axis an explore request may ask for
MAX_POINTS = 128**3  # samples per request: 2.1 M float64 = 17 MB of field, < 1 s to evaluate
MAX_CHANGES = 64  # entries in one change set
MAX_CONSTANT_KNOBS = 24  # literal sliders listed for one formula
CONSTANT_RE = re.compile(r"^#(\d{1,4})$")
NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,31}$")


class ExploreError(SurfgenError):
    """An explore request or change set that is malformed or out of range."""


# ----------------------------------------------------------------------------- literals


@dataclass(frozen=True)
class Literal:
    """A numeric literal of a formula: its position (parents first), value and where it sits."""

    index: int
    value: float
    context: str


def literals_of(tree: Expr) -> list[Literal]:
    """The numeric literals of ``tree`` in parents-first order. A literal under a unary minus
    counts as negative; ``context`` is the smallest enclosing call or power, printed."""
    out: list[Literal] = []

    def visit(node: Expr, parent: Expr | None, context: Expr) -> None:
        if node.op == "num":
            sign = -1.0 if parent is not None and parent.op == "neg" else 1.0
            out.append(Literal(len(out), sign * float(node.value), _short(context)))  # type: ignore[arg-type]
            return
        here = node if node.op not in ("+", "-", "*", "/", "neg") else context
        for a in node.args:
            visit(a, node, here)

    visit(tree, None, tree)
    return out


def _short(node: Expr, width: int = 48) -> str:
    text = to_string(node)
    return text if len(text) <= width else text[: width - 1] + "…"


def replace_literals(tree: Expr, values: Mapping[int, float]) -> Expr:
    """``tree`` with the literals at the given positions (as :func:`literals_of` counts them)
    set to new values; a negative value becomes a unary minus (or drops one)."""
    counter = [0]

    def rebuild(node: Expr) -> Expr:
        if node.op == "neg" and node.args[0].op == "num":
            i = counter[0]
            counter[0] += 1
            if i in values:
                return _signed(values[i])
            return node
        if node.op == "num":
            i = counter[0]
            counter[0] += 1
            return _signed(values[i]) if i in values else node
        if not node.args:
            return node
        return Expr(node.op, tuple(rebuild(a) for a in node.args), node.value)

    return rebuild(tree)


def _signed(value: float) -> Expr:
    v = float(value)
    leaf = Expr("num", (), abs(v))
    return Expr("neg", (leaf,)) if v < 0 else leaf


def d_literal(tree: Expr) -> int | None:
    """Position of eq. (13)'s d: the literal subtracted (or added) at the top of ``F = S - d``."""
    if tree.op in ("+", "-") and len(tree.args) == 2:
        right = tree.args[1]
        if right.op == "num" or (right.op == "neg" and right.args[0].op == "num"):
            return sum(1 for n in walk(tree.args[0]) if n.op == "num")
    return None


# ----------------------------------------------------------------------------- change sets


def number_of(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ExploreError(f"'{name}' must be a number, got {json.dumps(value)[:40]}")
    v = float(value)
    if not math.isfinite(v) or abs(v) > 1e12:
        raise ExploreError(f"'{name}' must be a finite number of magnitude up to 1e12, got {v}")
    return v


def _whole(name: str, value: Any) -> int:
    v = number_of(name, value)
    if v != int(v):
        raise ExploreError(f"'{name}' must be a whole number, got {v}")
    return int(v)


def grid_of(value: Any, capped: bool = True) -> tuple[int, int, int]:
    """A grid from ``N`` or ``[nx, ny, nz]``: within the CLI's limits, and with ``capped`` within
    :data:`MAX_GRID` per axis and :data:`MAX_POINTS` in all. Raises :class:`ExploreError` (or the
    CLI's ``GridError``) naming the limits."""
    sizes = value if isinstance(value, list | tuple) else [value]
    if len(sizes) not in (1, 3):
        raise ExploreError(f"'grid' takes 1 or 3 whole numbers, got {len(sizes)}")
    shape = [_whole("grid", s) for s in sizes] * (3 if len(sizes) == 1 else 1)
    Grid.from_sizes(Box.cube(1.0), shape)  # the CLI's own limits and message first
    if not capped:
        return tuple(shape)  # type: ignore[return-value]
    for n in shape:
        if not MIN_POINTS <= n <= MAX_GRID:
            raise ExploreError(
                f"grid: {n} points per axis is out of range (allowed: {MIN_POINTS} to {MAX_GRID})"
            )
    if math.prod(shape) > MAX_POINTS:
        raise ExploreError(
            f"grid: {'x'.join(map(str, shape))} is {math.prod(shape)} samples, more than the "
            f"{MAX_POINTS} (128³) one explore step may evaluate"
        )
    return tuple(shape)  # type: ignore[return-value]


def box_of(value: Any) -> tuple[float, ...]:
    """A box from a half-width ``h`` (``[-h, h]^3``) or 6 bounds. Raises :class:`ExploreError`."""
    if isinstance(value, list | tuple):
        if len(value) != 6:
            raise ExploreError(f"'box' takes a half-width or 6 numbers, got {len(value)} numbers")
        bounds = [number_of("box", v) for v in value]
    else:
        h = number_of("box", value)
        if h <= 0:
            raise ExploreError(f"'box' half-width must be positive, got {h}")
        bounds = [-h, h] * 3
    try:
        return Box.from_bounds(bounds).bounds()
    except SurfgenError as exc:
        raise ExploreError(str(exc)) from None


def check_changes(changes: Any) -> dict[str, Any]:
    """Validate the shape of a change set (an object of at most :data:`MAX_CHANGES` entries
    with known kinds of names) without a spec. Raises :class:`ExploreError`."""
    if not isinstance(changes, dict):
        raise ExploreError('\'changes\' must be a JSON object such as {"m": 0.5, "grid": 64}')
    if len(changes) > MAX_CHANGES:
        raise ExploreError(f"'changes' has {len(changes)} entries, at most {MAX_CHANGES} allowed")
    for name in changes:
        if not (NAME_RE.match(name) or CONSTANT_RE.match(name)):
            raise ExploreError(
                f"unknown change '{name[:40]}' (allowed: a parameter name, box, grid, level, d, #K)"
            )
    return dict(changes)


def apply_changes(
    spec: SurfaceSpec, changes: Mapping[str, Any], capped: bool = True
) -> SurfaceSpec:
    """``spec`` with a change set applied (see the module docstring); the provenance is kept.
    ``capped``: a ``grid`` change must stay within the explore limits (:func:`grid_of`).

    Raises :class:`ExploreError` for an unknown name or a bad value, and the spec's own errors
    (:class:`SpecError`, ``FormulaSyntaxError``) when the result is not a valid spec.
    """
    changes = check_changes(dict(changes))
    tree = spec.tree()
    literals = literals_of(tree)
    new_params = dict(spec.params)
    new_literals: dict[int, float] = {}
    new_d: float | None = None
    update: dict[str, Any] = {}
    for name, value in changes.items():
        m = CONSTANT_RE.match(name)
        if name == "box":
            update["box"] = box_of(value)
        elif name == "grid":
            update["grid"] = grid_of(value, capped)
        elif name == "level":
            update["level"] = number_of(name, value)
        elif name == "d" and "d" not in spec.params:
            k = d_literal(tree)
            if k is None:
                raise ExploreError("this formula has no d: it does not end in '- number'")
            new_d = number_of(name, value)
        elif m:
            k = int(m.group(1))
            if k >= len(literals):
                raise ExploreError(
                    f"'{name}': the formula has {len(literals)} numeric literals (#0 to "
                    f"#{len(literals) - 1})"
                )
            new_literals[k] = number_of(name, value)
        elif name in spec.params:
            new_params[name] = number_of(name, value)
        else:
            allowed = ", ".join([*sorted(spec.params), "box", "grid", "level", "d", "#K"])
            raise ExploreError(f"unknown change '{name}' (allowed: {allowed})")
    if new_literals or new_d is not None:
        changed = replace_literals(tree, new_literals)
        if new_d is not None:  # S - d, written S + |d| when d < 0
            top = "-" if new_d >= 0 else "+"
            changed = Expr(top, (changed.args[0], Expr("num", (), abs(new_d))))
        update["formula"] = to_string(changed)
    if new_params != dict(spec.params):
        update["params"] = new_params
    return spec.replace(**update) if update else spec


def d_of(spec: SurfaceSpec) -> float | None:
    """The d of ``F = S - d`` if the formula has that form (parameter ``d`` first)."""
    if "d" in spec.params:
        return float(spec.params["d"])
    tree = spec.tree()
    k = d_literal(tree)
    if k is None:
        return None
    value = literals_of(tree)[k].value
    return value if tree.op == "-" else -value


# ----------------------------------------------------------------------------- knobs


@dataclass(frozen=True)
class Knob:
    """One slider: the change-set ``name``, a label, the current value, range and step."""

    name: str
    label: str
    value: float
    lo: float
    hi: float
    step: float
    kind: str  # param, d, box, grid, level, literal
    hint: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "label": self.label,
            "value": self.value,
            "lo": self.lo,
            "hi": self.hi,
            "step": self.step,
            "kind": self.kind,
            "hint": self.hint,
        }


def _around(value: float, spread: float = 1.0) -> tuple[float, float, float]:
    """A slider range around ``value``: ±spread·|value| (±1 at 0), 200 steps."""
    width = spread * (abs(value) or 1.0)
    lo, hi = value - width, value + width
    return lo, hi, _nice_step((hi - lo) / 200)


def _nice_step(raw: float) -> float:
    exp = math.floor(math.log10(raw))
    return float(f"{10.0**exp:.0e}")


def knobs_of(spec: SurfaceSpec) -> list[Knob]:
    """The sliders for ``spec``: its parameters, d (eq. (13) shapes), the box half-width, the
    grid, the level, then up to :data:`MAX_CONSTANT_KNOBS` numeric literals."""
    knobs: list[Knob] = []
    for name, value in sorted(spec.params.items()):
        knobs.append(Knob(name, name, value, *_around(value), "param", "named parameter"))
    tree = spec.tree()
    k_d = d_literal(tree) if "d" not in spec.params else None
    d = d_of(spec)
    if k_d is not None and d is not None:
        knobs.append(Knob("d", "d", d, *_around(d), "d", "F = S − d: the level set of the sum"))
    lo, hi = spec.box[0::2], spec.box[1::2]
    half = max(max(abs(a), abs(b)) for a, b in zip(lo, hi, strict=True))
    knobs.append(
        Knob("box", "box half-width", half, half / 4, half * 2, _nice_step(half / 100), "box")
    )
    n = max(spec.grid)
    knobs.append(Knob("grid", "grid", float(n), 16, 128, 1, "grid", "points per axis"))
    knobs.append(
        Knob(
            "level", "level", spec.level, *_around(spec.level, 1.0), "level", "inside is F < level"
        )
    )
    for lit in literals_of(tree)[:MAX_CONSTANT_KNOBS]:
        if lit.index == k_d:
            continue
        knobs.append(
            Knob(f"#{lit.index}", f"#{lit.index}", lit.value, *_around(lit.value, 0.75), "literal",
                 lit.context)
        )  # fmt: skip
    return knobs


__all__ = ["ExploreError", "Knob", "apply_changes", "check_changes", "knobs_of"]
