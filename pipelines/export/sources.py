"""Export inputs: catalogue keys, spec files (or export sidecars) and mesh files, resolved.

:func:`resolve_sources` classifies each argument of ``surfgen export`` (and of the MathMod
script export) and reads what it names, in order and without duplicates, before any work is
done; :class:`ExportError` is the error of the whole export job.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from surfgen.generator.errors import SurfgenError
from surfgen.generator.formula.limits import (
    MAX_JSON_DEPTH,
    MAX_SPEC_FILE_BYTES,
    json_depth_ok,
    read_text_file,
)
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.store import open_catalogue


class ExportError(SurfgenError):
    """An export that cannot be done as asked (bad option, refused shape, clashing names...)."""


@dataclass(frozen=True)
class Source:
    """One resolved input: a catalogue entry, a spec file or a mesh file."""

    argument: str
    kind: str  # "catalogue" | "spec" | "mesh"
    name: str  # file stem of the outputs
    key: str | None = None
    spec: SurfaceSpec | None = None
    mesh_file: Path | None = None
    catalogue: Path | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "argument": self.argument,
            "catalogue": None if self.catalogue is None else str(self.catalogue),
            "mesh_file": None if self.mesh_file is None else str(self.mesh_file),
        }


def has_mesh(source: Source) -> bool:
    """Whether the input comes with a mesh file that is there."""
    return source.mesh_file is not None and source.mesh_file.is_file()


def resolve_sources(inputs: Sequence[str], catalogue: Path) -> list[Source]:
    """Classify and resolve the inputs, in order, without duplicates.

    ``*.json`` is a spec file (or an export sidecar); a name with a mesh suffix, a path or an
    existing file is a mesh file; anything else is a catalogue key or unique key prefix.
    """
    sources: list[Source] = []
    keys = [a for a in inputs if _kind(a) == "catalogue"]
    rows: dict[str, Source] = {}
    if keys:
        with open_catalogue(catalogue, readonly=True) as cat:
            for arg in keys:
                key = cat.resolve(arg)
                row = cat.shape(key)
                mesh_path = row.get("mesh_path")
                rows[arg] = Source(
                    argument=arg,
                    kind="catalogue",
                    name=key,
                    key=key,
                    spec=SurfaceSpec.from_json(row["spec"]),
                    mesh_file=cat.root / mesh_path if mesh_path else None,
                    catalogue=cat.root,
                )
    for arg in inputs:
        kind = _kind(arg)
        if kind == "catalogue":
            source = rows[arg]
        elif kind == "spec":
            spec = read_spec_or_sidecar(Path(arg))
            source = Source(arg, "spec", Path(arg).stem, key=spec.key, spec=spec)
        else:
            source = Source(arg, "mesh", Path(arg).stem, mesh_file=Path(arg))
        if all((s.kind, s.name) != (source.kind, source.name) for s in sources):
            sources.append(source)
    return sources


def read_spec_or_sidecar(path: Path) -> SurfaceSpec:
    """A spec from a spec file (``SurfaceSpec.to_json``) or from an export sidecar's ``spec``."""

    text = read_text_file(Path(path), MAX_SPEC_FILE_BYTES, "spec file")
    if not json_depth_ok(text):
        raise ExportError(f"{path}: JSON nested more than {MAX_JSON_DEPTH} levels deep")
    try:
        data = json.loads(text, parse_constant=_no_json_constant)
    except json.JSONDecodeError as exc:
        raise ExportError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    if isinstance(data, dict) and "spec" in data and "box" not in data:  # a sidecar
        if data["spec"] is None:
            raise ExportError(f"{path}: this export came from a mesh file and has no spec")
        data = data["spec"]
    if not isinstance(data, dict):
        raise ExportError(f"{path}: expected a JSON object")
    return SurfaceSpec.from_dict(data)


def _no_json_constant(name: str) -> float:
    raise json.JSONDecodeError(f"{name} is not a JSON number", name, 0)


def _kind(arg: str) -> str:
    path = Path(arg)
    if path.suffix.lower() == ".json":
        return "spec"
    # Keys are bare hex digits: anything with a suffix, a folder or on disk is a mesh file
    # (load_mesh names the allowed suffixes, MESH_SUFFIXES, when it is not one).
    if path.suffix or os.sep in arg or path.exists():
        return "mesh"
    return "catalogue"
