"""The sampling configuration: a TOML file over built-in defaults, validated and hashed.

The defaults live in ``default_config.toml`` beside this module (``surfgen config show``):
``[run]``, ``[sampler]`` with one sub-table per sampler family (``[sampler.sculpture]``, ...)
and ``[filters]``. Unknown tables or keys are errors. Configs written before the family tables
(``sculpture_exponent = ...`` in ``[sampler]``) still read: the sampler maps their keys
(:func:`~surfgen.generator.model.sampler.nest_legacy_keys`, the one place). The canonical JSON
of the resolved config (:meth:`Config.to_dict`: the family tables flattened, as before them)
is hashed and the hash is recorded with every shape, so a catalogue says exactly how each shape
was drawn, and the same values give the same hash in either layout.
"""

from __future__ import annotations

import functools
import hashlib
import json
import tomllib
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

from surfgen.generator.errors import SpecError
from surfgen.generator.eval.grid import MAX_POINTS, MIN_POINTS
from surfgen.generator.formula.limits import (
    MAX_CONFIG_FILE_BYTES,
    MAX_JSON_DEPTH,
    json_depth_ok,
    read_text_file,
)
from surfgen.generator.model.families import families
from surfgen.generator.model.sampler import SAMPLER_VERSION, SamplerConfig, nest_legacy_keys
from surfgen.generator.model.settings import settings_from_mapping, settings_to_dict

if TYPE_CHECKING:  # numba modules, loaded when a config is built (`config show` needs neither)
    from surfgen.filters.verdict import FilterConfig

MAX_TIMEOUT = 86_400.0  # a day per shape: more is a typo


@dataclass(frozen=True)
class RunSettings:
    """The ``[run]`` table."""

    grid: int = 64
    cap: bool = True
    timeout: float = 60.0
    thumbnails: bool = True
    dedupe: bool = True
    dedupe_threshold: float = 1.0
    walls: str = "keep"

    def __post_init__(self) -> None:
        # deferred on purpose: the mesher's module loads numba (`config show` needs none)
        from surfgen.generator.mesh.walls import WALL_MODES

        if self.walls not in WALL_MODES:
            raise SpecError(
                f"config [run]: walls must be one of {', '.join(WALL_MODES)}, got {self.walls!r}"
            )
        if not self.dedupe_threshold >= 0:
            raise SpecError(
                f"config [run]: dedupe_threshold must be >= 0, got {self.dedupe_threshold}"
            )
        if isinstance(self.grid, bool) or not isinstance(self.grid, int):
            raise SpecError(f"config [run]: grid must be a whole number, got {self.grid!r}")
        if not MIN_POINTS <= self.grid <= MAX_POINTS:
            raise SpecError(f"grid must be from {MIN_POINTS} to {MAX_POINTS}, got {self.grid}")
        if not 0 < self.timeout <= MAX_TIMEOUT:
            raise SpecError(
                f"config [run]: timeout must be more than 0 and at most {MAX_TIMEOUT:g} seconds, "
                f"got {self.timeout}"
            )


@dataclass(frozen=True)
class Config:
    """A run's settings: ``[run]``, ``[sampler]`` (with its family tables), ``[filters]``.

    The sampler draws for the run's grid (its priors are bounded by the cell size): building a
    config copies ``[run] grid`` into the sampler's, so ``--grid`` changes both at once."""

    run: RunSettings
    sampler: SamplerConfig
    filters: FilterConfig

    def __post_init__(self) -> None:
        object.__setattr__(self, "sampler", self.sampler.with_grid(self.run.grid))

    def to_dict(self) -> dict[str, Any]:
        """The canonical form: what a catalogue stores (``runs.config``) and the hash covers,
        the sampler's family tables flattened (:meth:`SamplerConfig.canonical_dict`)."""
        return {
            "run": self._run_dict(),
            "sampler": self.sampler.canonical_dict(),
            "filters": self.filters.to_dict(),
        }

    def _run_dict(self) -> dict[str, Any]:
        return {
            "grid": self.run.grid,
            "cap": self.run.cap,
            "timeout": self.run.timeout,
            "thumbnails": self.run.thumbnails,
            "dedupe": self.run.dedupe,
            "dedupe_threshold": self.run.dedupe_threshold,
            "walls": self.run.walls,
        }

    def shape_dict(self) -> dict[str, Any]:
        """What decides the shapes and their verdicts (not timeouts or pictures)."""
        d = self.to_dict()
        d["run"] = {"grid": self.run.grid, "cap": self.run.cap}
        if self.run.walls != "keep":  # removing walls changes meshes and verdicts
            d["run"]["walls"] = self.run.walls
        if self.run.dedupe:  # near-duplicate rejection changes which shapes are accepted
            d["run"]["dedupe_threshold"] = self.run.dedupe_threshold
        d["sampler_version"] = SAMPLER_VERSION
        return d

    @functools.cached_property
    def hash(self) -> str:
        """The first 12 hex digits of the SHA-256 of :meth:`shape_dict` (canonical JSON). Kept
        once computed (a config is frozen): every shape drawn stamps its spec with it."""
        text = json.dumps(self.shape_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:12]

    def to_toml(self) -> str:
        """The whole config as a TOML file that :func:`load_config` reads back to an equal one
        (in the layout of ``config show``: one sub-table per sampler family)."""
        lines: list[str] = []
        tables = {"run": self._run_dict(), "sampler": self.sampler.to_dict()}
        for table, values in (tables | {"filters": self.filters.to_dict()}).items():
            _toml_table(lines, table, values)
        return "\n".join(lines)

    def with_grid(self, grid: int | None) -> Config:
        return self if grid is None else self.with_run(grid=grid)

    def with_family(self, family: str) -> Config:
        """The config with ``[sampler] family`` replaced (validated: one-line error)."""
        data = self.sampler.to_dict()
        data["family"] = family
        try:
            sampler = SamplerConfig.from_mapping(data)
        except SpecError as exc:
            raise SpecError(str(exc).replace("config [sampler]: family", "--family")) from None
        return Config(self.run, sampler, self.filters)

    def with_run(self, **changes: Any) -> Config:
        return Config(replace(self.run, **changes), self.sampler, self.filters)


def _toml_table(lines: list[str], name: str, values: dict[str, Any]) -> None:
    """``[name]`` with its keys, then its sub-tables (``[name.key]``)."""
    lines.append(f"[{name}]")
    # JSON scalars/lists are TOML
    lines += [f"{k} = {json.dumps(v)}" for k, v in values.items() if not isinstance(v, dict)]
    lines.append("")
    for k, v in values.items():
        if isinstance(v, dict):
            _toml_table(lines, f"{name}.{k}", v)


def default_config_text() -> str:
    return resources.files("surfgen.pipelines.run").joinpath("default_config.toml").read_text()


def load_config(path: Path | None = None) -> Config:
    """The defaults, overridden by the TOML file at ``path``. Raises :class:`SpecError`."""
    data = tomllib.loads(default_config_text())
    for family in families():  # a registered family's table defaults to its dataclass's
        if family.settings is not None:
            data["sampler"].setdefault(family.name, settings_to_dict(family.settings()))
    if path is not None:
        text = read_text_file(Path(path), MAX_CONFIG_FILE_BYTES, "config")
        if not json_depth_ok(text):  # tomllib recurses into nested arrays and tables
            raise SpecError(f"config {path}: nested more than {MAX_JSON_DEPTH} levels deep")
        try:
            user = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise SpecError(f"config {path} is not valid TOML: {exc}") from None
        unknown = sorted(set(user) - set(data))
        if unknown:
            raise SpecError(
                f"config {path}: unknown table [{unknown[0]}] (allowed: run, sampler, filters)"
            )
        for table, values in user.items():
            if not isinstance(values, dict):
                raise SpecError(f"config {path}: '{table}' must be a table")
            if table == "sampler":  # keys of the layout before the family tables
                values = nest_legacy_keys(values)
            _merge(data[table], values, table, path)
    return config_from_dict(data)


def _merge(into: dict[str, Any], values: dict[str, Any], table: str, path: Path) -> None:
    """``values`` (a table of the user's file) over ``into`` (the defaults), sub-tables key by
    key; :class:`SpecError` for a key the defaults do not have."""
    bad = sorted(set(values) - set(into))
    if bad:
        hint = " (the grid is [run] grid)" if (table, bad[0]) == ("sampler", "grid") else ""
        raise SpecError(f"config {path}: unknown key '{bad[0]}' in [{table}]{hint}")
    for key, value in values.items():
        if isinstance(into[key], dict):
            if not isinstance(value, dict):
                raise SpecError(f"config {path}: '{table}.{key}' must be a table")
            _merge(into[key], value, f"{table}.{key}", path)
        else:
            into[key] = value


def config_from_dict(data: dict[str, Any]) -> Config:
    """A config from its :meth:`Config.to_dict` (a catalogue's ``runs.config``) or the nested
    layout of the TOML. Raises :class:`SpecError`."""
    from surfgen.filters.verdict import FilterConfig  # deferred on purpose: loads numba

    run = settings_from_mapping(RunSettings, data["run"], "run")
    return Config(
        run, SamplerConfig.from_mapping(data["sampler"]), FilterConfig.from_mapping(data["filters"])
    )
