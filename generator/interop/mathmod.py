"""MathMod scripts: read their implicit ("Iso3D") models as surfgen specs, write specs as scripts.

A MathMod script is JSON: one model ``{"Iso3D": {...}}`` (beside optional ``"Texture"``,
``"Pigment"`` and ``"Sliders"``), or a collection ``{"MathModels": [model, ...]}``. The keys of
an Iso3D model hold lists of strings, one entry per component where it matters:

=============== ====================================================================================
``Name``        the model's name (first entry)
``Component``   the components' names
``Fxyz``        one formula per component (MathMod's fparser syntax: ``if``, comparisons, ``& | !``)
``Xmin``…``Zmax`` one box bound per component: expressions of constants, sliders and ``t``
``Grid``        points per axis, one value or one per component (default 64, MathMod's)
``Const``       ``name = expression`` of earlier constants; they become the spec's parameters
``Funct``       ``name = expression`` in x, y, z, t, called as ``name(x, y, z, t)`` and inlined;
                a later definition of a name may call the earlier one; recursion is an error
``Cnd``         a condition per component: samples where it is false are outside (``if(c, F, 0/0)``)
``Description`` kept as the shape's note
``Varu``        helpers of parametric models: ignored with a notice
``Vect``, ``Import`` not supported: a one-line error
=============== ====================================================================================

``Sliders`` (``Name``, ``Position`` with one value per slider and set, ``Min``, ``Max``, ``Step``,
``SetNames``) bind named constants; the first set is used unless another is chosen. ``t`` is
MathMod's time: 0 unless given. MathMod's internal C++ functions (``NoiseW``, ``NoiseP``,
``CmpId`` …) cannot be written as formulas: they are a one-line "not supported" error.
Parametric models (``Param3D``, ``Param4D``) are not implicit surfaces: also refused.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from surfgen.generator.errors import FormulaSyntaxError, SpecError
from surfgen.generator.eval.reference import evaluate_points
from surfgen.generator.formula.expr import Expr, params_of, to_string
from surfgen.generator.formula.parser import parse
from surfgen.generator.interop.builtins import expand_builtins
from surfgen.generator.model.spec import SurfaceSpec

MAX_SCRIPT_BYTES = 8 * 1024 * 1024
DEFAULT_GRID = 64  # MathMod's
ISO3D_KEYS = (
    "Name",
    "Component",
    "Fxyz",
    "Xmin",
    "Xmax",
    "Ymin",
    "Ymax",
    "Zmin",
    "Zmax",
    "Grid",
    "Const",
    "Funct",
    "Cnd",
    "Description",
    "Varu",
    "Vect",
    "Import",
)
MODEL_KEYS = ("Iso3D", "Texture", "Pigment", "Sliders", "Param3D", "Param4D", "Param3D_C")
SLIDER_KEYS = ("Name", "Position", "Min", "Max", "Step", "SetNames")
INTERNAL_FUNCTIONS = (
    "NoiseW",
    "NoiseP",
    "Noise",
    "NoiseT",
    "CmpId",
    "fhelp",
    "fhelp1",
    "fhelp2",
    "ihelp",
    "psh",
    "csd",
)
DOT_TOKEN = "DOTSYMBOL"  # MathMod's files write the decimal point so (any locale reads them)
OLD_DOT_TOKEN = "$DOT$"  # the same, in older collections
_BOUNDS = ("Xmin", "Xmax", "Ymin", "Ymax", "Zmin", "Zmax")
_DEFINITION = re.compile(r"^\s*([A-Za-z_][A-Za-z_0-9]*)\s*=(?!=)(.*)$", re.S)


@dataclass(frozen=True)
class Component:
    name: str
    spec: SurfaceSpec


@dataclass(frozen=True)
class Model:
    """One Iso3D model: its components as specs, its note, and what was ignored."""

    name: str
    components: tuple[Component, ...]
    description: str
    notices: tuple[str, ...]

    def component(self, name: str | None) -> Component:
        """The component called ``name`` (its index is accepted too)."""
        names = [c.name for c in self.components]
        for i, c in enumerate(self.components):
            if name in (c.name, str(i)):
                return c
        raise SpecError(
            f"model {self.name} has no component '{name}' (components: {', '.join(names)})"
        )


# ----------------------------------------------------------------------------- reading


def read_script(path: Path) -> list[dict[str, Any]]:
    """The models (raw dicts) of a MathMod script file; :class:`SpecError` if it is not one."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if not path.is_file():
            raise SpecError(f"MathMod script {path} is not a file")
        if size > MAX_SCRIPT_BYTES:
            raise SpecError(
                f"MathMod script {path} is {size} bytes (at most {MAX_SCRIPT_BYTES} allowed)"
            )
        with path.open("rb") as fh:
            raw = fh.read(MAX_SCRIPT_BYTES + 1)
    except OSError as exc:
        raise SpecError(f"cannot read MathMod script {path}: {exc.strerror}") from None
    return parse_script(raw, str(path))


def parse_script(raw: bytes | str, where: str = "script") -> list[dict[str, Any]]:
    """The models of a MathMod script given as text.

    Read as MathMod reads it (``ParisoMathObject::ReadJsonFile``): the token ``DOTSYMBOL`` (and
    the older ``$DOT$``) is the decimal point, and line breaks and tabs are removed from the text
    before the JSON is parsed, so a formula may span lines inside its string.
    """
    try:
        text = raw.decode("utf-8") if isinstance(raw, bytes) else raw
    except UnicodeDecodeError:
        raise SpecError(f"{where}: not UTF-8 text") from None
    text = text.strip().replace(DOT_TOKEN, ".").replace(OLD_DOT_TOKEN, ".")
    try:
        data = _loads(text)
    except json.JSONDecodeError as exc:
        raise SpecError(f"{where}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    except RecursionError:
        raise SpecError(f"{where}: JSON nested too deeply") from None
    if not isinstance(data, dict):
        raise SpecError(f"{where}: a MathMod script is a JSON object, got {type(data).__name__}")
    if "MathModels" in data:
        models = data["MathModels"]
        if not isinstance(models, list) or not all(isinstance(m, dict) for m in models):
            raise SpecError(f"{where}: MathModels must be a list of models (JSON objects)")
    else:
        models = [data]
    if not models:
        raise SpecError(f"{where}: the script has no model")
    return [_normalised(m, MODEL_KEYS) for m in models]


def _loads(text: str) -> Any:
    """JSON as MathMod reads it: when the text is not valid as it stands, again without its line
    breaks and tabs (MathMod drops them first, so its strings may hold raw ones). The error
    raised is the first one, whose line number points into the file as written."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        first = exc
    try:
        return json.loads(text.replace("\r\n", "").replace("\n", "").replace("\t", ""))
    except json.JSONDecodeError:
        raise first from None


def _normalised(raw: Mapping[str, Any], allowed: Sequence[str]) -> dict[str, Any]:
    """``raw`` with a key that differs from a known one only by blanks around it
    (``"Description "``, as some of MathMod's own files have) renamed to that key, unless the
    exact key is there too. Other keys stay as they are."""
    out: dict[str, Any] = {}
    for key, value in raw.items():
        name = key.strip()
        out[name if name in allowed and name not in raw else key] = value
    return out


def _known_keys(
    raw: Mapping[str, Any], allowed: Sequence[str], where: str, notices: list[str]
) -> dict[str, Any]:
    """The keys MathMod uses (after :func:`_normalised`); the others are ignored, as MathMod
    ignores them, each with a notice."""
    out = {}
    for key, value in _normalised(raw, allowed).items():
        if key in allowed:
            out[key] = value
        else:
            notices.append(f"ignored: unknown key '{key}' in {where}")
    return out


def model_names(models: Sequence[Mapping[str, Any]]) -> list[str]:
    names = []
    for m in models:
        body = m.get("Iso3D") or m.get("Param3D") or m.get("Param4D") or {}
        name = _normalised(body, ("Name",)).get("Name") if isinstance(body, dict) else None
        names.append(_first(name) if name else "?")
    return names


def load_model(
    models: Sequence[Mapping[str, Any]],
    name: str | None = None,
    *,
    slider_set: int | None = None,
    params: Mapping[str, float] | None = None,
    grid: int | None = None,
) -> Model:
    """The model called ``name`` (or the only / first implicit one) as specs."""
    names = model_names(models)
    if name is None:
        iso = [i for i, m in enumerate(models) if "Iso3D" in m]
        if not iso:
            _refuse_parametric(models[0], names[0])
        index = iso[0]
    elif name in names:
        index = names.index(name)
    else:
        raise SpecError(f"no model '{name}' in the script (models: {', '.join(names)})")
    return build_model(models[index], slider_set=slider_set, params=params, grid=grid)


def _refuse_parametric(model: Mapping[str, Any], name: str) -> None:
    kind = next((k for k in ("Param3D", "Param4D", "Param3D_C") if k in model), None)
    raise SpecError(
        f"not supported: model {name} is a parametric {kind} model (only Iso3D implicit surfaces)"
        if kind
        else f"model {name} has no Iso3D part"
    )


def build_model(
    model: Mapping[str, Any],
    *,
    slider_set: int | None = None,
    params: Mapping[str, float] | None = None,
    grid: int | None = None,
) -> Model:
    """Turn one raw model into specs (one per component)."""
    notices: list[str] = []
    model = _known_keys(model, MODEL_KEYS, "a model", notices)
    if "Iso3D" not in model:
        _refuse_parametric(model, model_names([model])[0])
    iso = model["Iso3D"]
    if not isinstance(iso, dict):
        raise SpecError("Iso3D must be a JSON object")
    iso = _known_keys(iso, ISO3D_KEYS, "Iso3D", notices)
    fields = {k: _strings(iso, k) for k in iso}
    name = _first(fields.get("Name")) or "mathmod"
    for key in ("Texture", "Pigment"):
        if key in model:
            notices.append(f"ignored: {key} (colour formulas)")
    if fields.get("Varu"):
        notices.append("ignored: Varu (helpers of parametric models)")
    for key, what in (("Vect", "vector constants"), ("Import", "imported C++ functions")):
        if any(s.strip() for s in fields.get(key, [])):
            raise SpecError(f"not supported: {key} ({what}) in model {name}")
    values = _slider_values(model.get("Sliders"), slider_set, name, notices)
    values.setdefault("t", 0.0)
    overrides = dict(params or {})
    unknown_params = sorted(set(overrides) - set(values) - {"t"})
    values.update({k: v for k, v in overrides.items() if k in values or k == "t"})
    consts = _constants(fields.get("Const", []), values, name)
    # a --param may also set a constant (then later constants see it)
    if unknown_params:
        missing = [p for p in unknown_params if p not in consts]
        if missing:
            allowed = ", ".join(sorted({*values, *consts})) or "none"
            raise SpecError(f"model {name} has no parameter '{missing[0]}' (parameters: {allowed})")
        consts = _constants(fields.get("Const", []), values, name, overrides)
    env = {**values, **consts}
    functions = _functions(fields.get("Funct", []), env, name)
    formulas = fields.get("Fxyz", [])
    if not formulas:
        raise SpecError(f"model {name} has no Fxyz formula")
    names = fields.get("Component") or [f"{name}-{i}" for i in range(len(formulas))]
    if len(names) < len(formulas):
        names = names + [f"{name}-{i}" for i in range(len(names), len(formulas))]
    conditions = fields.get("Cnd", [])
    description = " ".join(s.strip() for s in fields.get("Description", []) if s.strip())
    provenance = {"mathmod": name, **({"description": description} if description else {})}
    grids = fields.get("Grid", [])
    components = []
    for i, text in enumerate(formulas):
        where = f"model {name}, component {names[i].strip()}"
        tree = _parse(text, env, functions, where)
        cnd = (
            conditions[i]
            if i < len(conditions)
            else (conditions[0] if len(conditions) == 1 else "")
        )
        if cnd.strip():
            c = _parse(cnd, env, functions, f"{where}, Cnd")
            tree = Expr("if", (c, tree, Expr("/", (_num(0.0), _num(0.0)))))
        box = tuple(_bound(fields, key, i, env, functions, where) for key in _BOUNDS)
        n = grid or _grid(grids, i, where)
        used = {p: env[p] for p in sorted(params_of(tree))}
        spec = SurfaceSpec(
            formula=to_string(tree),
            box=box,
            grid=(n, n, n),
            params=used,
            provenance={**provenance, "component": names[i].strip()},
        )
        components.append(Component(names[i].strip(), spec))
    return Model(name, tuple(components), description, tuple(notices))


# ----------------------------------------------------------------------------- pieces


def _strings(iso: Mapping[str, Any], key: str) -> list[str]:
    value = iso[key]
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, (str, int, float)) for v in value):
        raise SpecError(f"Iso3D {key} must be a list of strings")
    return [str(v) for v in value]


def _first(value: Any) -> str:
    if isinstance(value, list):
        return str(value[0]).strip() if value else ""
    return str(value or "").strip()


def _num(v: float) -> Expr:
    return Expr("num", (), float(v))


def _slider_values(
    sliders: Any, chosen: int | None, model: str, notices: list[str]
) -> dict[str, float]:
    if sliders is None:
        if chosen not in (None, 0):
            raise SpecError(f"model {model} has no Sliders (so no --slider {chosen})")
        return {}
    if not isinstance(sliders, dict):
        raise SpecError(f"model {model}: Sliders must be a JSON object")
    sliders = _known_keys(sliders, SLIDER_KEYS, "Sliders", notices)
    names = [str(n).strip() for n in sliders.get("Name", [])]
    positions = sliders.get("Position", [])
    if not names or not isinstance(positions, list) or not positions:
        raise SpecError(f"model {model}: Sliders need Name and Position lists")
    if len(positions) % len(names):
        raise SpecError(
            f"model {model}: Sliders have {len(names)} names but {len(positions)} positions "
            "(one per slider and set)"
        )
    sets = len(positions) // len(names)
    k = 0 if chosen is None else chosen
    if not 0 <= k < sets:
        raise SpecError(f"--slider {k}: model {model} has slider sets 0 to {sets - 1}")
    out = {}
    for j, n in enumerate(names):
        try:
            out[n] = float(str(positions[k * len(names) + j]))
        except ValueError:
            raise SpecError(f"model {model}: slider {n} position is not a number") from None
        if not math.isfinite(out[n]):
            raise SpecError(f"model {model}: slider {n} position must be finite")
    return out


def _definition(entry: str, key: str, model: str) -> tuple[str, str]:
    m = _DEFINITION.match(entry)
    if m is None:
        raise SpecError(
            f"model {model}: {key} entry '{entry.strip()[:40]}' is not 'name = expression'"
        )
    return m.group(1), m.group(2)


def _constants(
    entries: Sequence[str],
    values: Mapping[str, float],
    model: str,
    overrides: Mapping[str, float] | None = None,
) -> dict[str, float]:
    known = dict(values)
    out: dict[str, float] = {}
    for entry in entries:
        if not entry.strip():
            continue
        name, text = _definition(entry, "Const", model)
        if overrides and name in overrides:
            value = float(overrides[name])
        else:
            value = _constant_value(text, known, f"model {model}, Const {name}")
        known[name] = out[name] = value
    return out


def _constant_value(
    text: str, env: Mapping[str, float], where: str, functions: Mapping[str, Expr] | None = None
) -> float:
    tree = _parse(text, env, functions or {}, where)
    if any(n.op == "var" for n in _nodes(tree)):
        raise SpecError(f"{where}: must not depend on x, y or z")
    with np.errstate(all="ignore"):
        value = float(evaluate_points(tree, 0.0, 0.0, 0.0, {p: env[p] for p in params_of(tree)}))
    if not math.isfinite(value):
        raise SpecError(f"{where}: evaluates to {value}")
    return value


def _functions(entries: Sequence[str], env: Mapping[str, float], model: str) -> dict[str, Expr]:
    functions: dict[str, Expr] = {}
    for entry in entries:
        if not entry.strip():
            continue
        name, text = _definition(entry, "Funct", model)
        where = f"model {model}, Funct {name}"
        if name not in functions and re.search(rf"\b{re.escape(name)}\s*\(", text):
            raise SpecError(f"{where}: calls itself (recursive functions are not supported)")
        functions[name] = _parse(text, env, functions, where)
    return functions


def _parse(text: str, env: Mapping[str, float], functions: Mapping[str, Expr], where: str) -> Expr:
    names = [*env, "t"]
    try:
        return parse(text, sorted(set(names)), functions)
    except FormulaSyntaxError as exc:
        message = str(exc)
        for internal in INTERNAL_FUNCTIONS:
            if f"unknown function '{internal}'" in message:
                raise SpecError(
                    f"not supported: {internal} ({where}) is one of MathMod's internal C++ functions"
                ) from None
        raise SpecError(f"{where}: {message}") from None


def _bound(
    fields: Mapping[str, list[str]],
    key: str,
    i: int,
    env: Mapping[str, float],
    functions: Mapping[str, Expr],
    where: str,
) -> float:
    entries = fields.get(key)
    if not entries:
        raise SpecError(f"{where}: missing {key}")
    text = entries[i] if i < len(entries) else entries[-1]
    return _constant_value(text, env, f"{where}, {key}", functions)


def _grid(entries: Sequence[str], i: int, where: str) -> int:
    if not entries:
        return DEFAULT_GRID
    text = entries[i] if i < len(entries) else entries[0]
    try:
        n = int(float(text))
    except ValueError:
        raise SpecError(f"{where}: Grid '{text}' is not a whole number") from None
    return n


def _nodes(tree: Expr):
    stack = [tree]
    while stack:
        node = stack.pop()
        yield node
        stack.extend(node.args)


# ----------------------------------------------------------------------------- writing


def to_script(specs: Sequence[tuple[str, SurfaceSpec]], name: str, description: str = "") -> dict:
    """A one-model MathMod script (JSON-ready) with one component per ``(name, spec)``.

    Constituent built-ins are expanded into standard functions (:mod:`.expand`);
    named parameters become ``Const`` entries.
    """
    consts: dict[str, float] = {}
    fields: dict[str, list[str]] = {k: [] for k in ("Component", "Fxyz", *_BOUNDS, "Grid")}
    for comp, spec in specs:
        consts.update(spec.params)
        fields["Component"].append(comp)
        fields["Fxyz"].append(to_string(expand_builtins(spec.tree(), spec.params)))
        for key, value in zip(_BOUNDS, spec.box, strict=True):
            fields[key].append(repr(float(value)))
        fields["Grid"].append(str(max(spec.grid)))
    iso: dict[str, list[str]] = {"Name": [name], **fields}
    if consts:
        iso["Const"] = [f"{k}={v!r}" for k, v in sorted(consts.items())]
    if description:
        iso["Description"] = [description]
    return {"Iso3D": iso}
