"""The seeded stochastic sampler of equation (13): its configuration and its draw.

Shape ``index`` of a run with ``seed`` draws from
``np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index,)))`` only, so any shape
can be regenerated alone, in any order, on any worker: :func:`draw_equation` is a pure function
of ``(seed, index, config)``. It draws through the registry of families
(:mod:`surfgen.generator.model.families`).

Every distribution lives in :class:`SamplerConfig`: the ``[sampler]`` table of the TOML config
holds the shared keys (:class:`~surfgen.generator.model.draw.DrawSettings`), ``family`` and
``mix``; each family's own keys are its ``[sampler.<family>]`` table (``surfgen config show``
prints the defaults with their meaning).

Choosing d: a random ``d`` almost always leaves the box empty. We evaluate the sum of products on
a coarse grid and take ``d`` at a drawn quantile of its finite values, rounded to 6 significant
digits (so the printed formula is short and the key is stable to the last bit of a libm).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from surfgen.generator.errors import SpecError
from surfgen.generator.model.draw import (
    NOT_SAMPLER_KEYS,
    Draw,
    DrawSettings,
    choose,
    coarse_values,
)
from surfgen.generator.model.families import (
    MIX,
    default_mix,
    default_mix_weights,
    families,
    family_choices,
    family_names,
    get_family,
)
from surfgen.generator.model.settings import (
    require_names,
    require_numbers,
    require_weighted_pairs,
    settings_from_mapping,
    settings_to_dict,
)
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.generator.model.stretch import stretch_draw

SAMPLER_VERSION = 12  # 2: families (sculpture, lattice, free) and their mix; 3: ornaments redrawn when they crumble (sculpture_max_pieces); 4: ornament checks on the unit's transposed copies and a 24^3 grid, sculpture_min_departure 0.2, walls classified by bisection (wall_fraction); 5: half the ornaments pole-free (sculpture_pole_free_prob 0.5), group weights towards none and mirror; 6: priors bounded by the run's cell size ([sampler] period_cells), families infill, assembly and twist, a new default mix, the resolution check (unresolved, pole planes included) and plain by solidity and by curvature (issue 40); 7: spires and swelling lobes in twist, chains of 2-4 rings (every other one smaller) clear of each other and never ornamented, fewer blends, the near-duplicate check after the mesh checks, plain rings (genus 1 by curvature), fragmented bodies (min_body_fraction), min_inside_fraction 0.003; 8: bent twisted columns (horns: [sampler.twist] bend_prob, bend), perforated infill shells ([sampler.infill] hollow_prob, shell), infill periods and envelope weights, assembly body weights; 9: a hollow torus of infill left uncut (cut open it was a torn strip); 10: proportions: shapes of every family stretched along the axes, their axis swaps kept ([sampler] aspect_prob, aspect), the resolution check in cells of each axis, bodies in more than [filters] max_pieces pieces fragmented (flying debris); 11: ornaments and free draws with a pole on a plane through the centre redrawn (slit on grids of odd size: the resolution check rejected them after all the other work); 12: lumps told by their outline (plain: every view's silhouette fills [filters] plain_min_outline of its hull, twist excepted), debris under [filters] min_piece_fraction of the largest piece fragmented, assembly body weights towards rings


@dataclass(frozen=True)
class SamplerConfig(DrawSettings):
    """The distributions of a random eq. (13) instance (see ``surfgen config show``).

    The shared keys (:class:`DrawSettings`), the ``family`` drawn (a registered one or
    ``mix``), the families of the mix and their weights, and ``tables``: each registered
    family's settings, ``((name, settings), ...)`` in registry order (filled with the
    defaults of the families not given; :meth:`settings` reads one, :meth:`with_settings`
    changes one).
    """

    family: str = MIX  # a registered family (sculpture, lattice, free, ...) or mix
    mix: tuple[str, ...] = field(default_factory=default_mix)
    mix_weights: tuple[float, ...] = field(default_factory=default_mix_weights)
    tables: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.family, str) or self.family not in family_choices():
            raise SpecError(
                f"config [sampler]: family must be one of {', '.join(family_choices())}, "
                f"got {self.family!r}"
            )
        require_names(self, "mix", family_names(), "sampler")
        require_numbers(self, ("mix_weights",), "sampler")
        super().__post_init__()
        require_weighted_pairs(self, (("mix", "mix_weights"),), "sampler")
        object.__setattr__(self, "tables", _complete_tables(self.tables))

    def settings(self, family: str) -> Any:
        """The settings of ``family`` (its ``[sampler.<family>]`` table; None without one)."""
        return dict(self.tables).get(family)

    def with_grid(self, grid: int) -> SamplerConfig:
        """The config drawing for a run on ``grid`` points per axis (the cell size the
        priors resolve; :class:`~surfgen.pipelines.run.config.Config` keeps it equal to
        ``[run] grid``)."""
        return self if grid == self.grid else replace(self, grid=grid)

    def with_settings(self, family: str, **changes: Any) -> SamplerConfig:
        """The config with keys of ``family``'s table changed (validated)."""
        tables = dict(self.tables)
        if tables.get(family) is None:
            raise SpecError(f"config [sampler]: family {family!r} has no table")
        data = settings_to_dict(tables[family]) | changes
        tables[family] = settings_from_mapping(type(tables[family]), data, f"sampler.{family}")
        return replace(self, tables=tuple(tables.items()))

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any]) -> SamplerConfig:
        """The ``[sampler]`` table with its family tables, in the layout of the TOML (nested)
        or the canonical one (:meth:`canonical_dict`, flat). Raises :class:`SpecError`."""
        data = nest_legacy_keys(data)
        for key in ("tables", *NOT_SAMPLER_KEYS):
            if key in data:
                hint = " (the grid is [run] grid)" if key == "grid" else ""
                raise SpecError(f"config [sampler]: unknown key '{key}'{hint}")
        tables = []
        for family in families():
            if family.settings is None:
                continue
            table = data.pop(family.name, {})
            if not isinstance(table, Mapping):
                raise SpecError(f"config [sampler]: {family.name} must be a table")
            tables.append(
                (family.name, settings_from_mapping(family.settings, table, family.table))
            )
        return settings_from_mapping(cls, data | {"tables": tuple(tables)}, "sampler")

    def to_dict(self) -> dict[str, Any]:
        """The layout of the TOML: the shared keys, then one sub-table per family."""
        out = self._shared_dict()
        for name, settings in self.tables:
            out[name] = settings_to_dict(settings)
        return out

    def canonical_dict(self) -> dict[str, Any]:
        """The layout before the family tables, ``[sampler.sculpture] exponent`` written
        ``sculpture_exponent``: what a catalogue stores of a run's config and what the config
        hash covers, so both are the same as before the tables for the same values."""
        out = self._shared_dict()
        for name, settings in self.tables:
            out.update({f"{name}_{k}": v for k, v in settings_to_dict(settings).items()})
        return out

    def _shared_dict(self) -> dict[str, Any]:
        """The keys of ``[sampler]`` itself, lists for tuples (JSON- and TOML-ready)."""
        out = {}
        for f in fields(self):
            if f.name != "tables" and f.name not in NOT_SAMPLER_KEYS:
                value = getattr(self, f.name)
                out[f.name] = list(value) if isinstance(value, tuple) else value
        return out


def _complete_tables(tables: Any) -> tuple[tuple[str, Any], ...]:
    """``tables`` as ``((name, settings), ...)`` for every registered family with settings,
    in registry order, the defaults where one is not given; :class:`SpecError` for a table of
    no family or of the wrong type."""
    given = dict(tables)
    known = {f.name: f for f in families() if f.settings is not None}
    unknown = sorted(set(given) - set(known))
    if unknown:
        raise SpecError(f"config [sampler]: unknown table [sampler.{unknown[0]}]")
    out = []
    for name, family in known.items():
        settings = given.get(name)
        if settings is None:
            settings = family.settings()
        elif not isinstance(settings, family.settings):
            raise SpecError(f"config [sampler.{name}] must be a {family.settings.__name__}")
        out.append((name, settings))
    return tuple(out)


def nest_legacy_keys(data: Mapping[str, Any]) -> dict[str, Any]:
    """``data`` (a ``[sampler]`` table) with the keys of the layout before the family tables
    moved into their tables: ``sculpture_exponent`` becomes ``[sampler.sculpture] exponent``.

    The one place configs written for that layout, and the configs catalogues store
    (:meth:`SamplerConfig.canonical_dict`), are read: a key ``{family}_{key}`` whose ``key`` is
    one of that family's settings moves. Raises :class:`SpecError` if both spellings are given.
    """
    out = dict(data)
    shared = {f.name for f in fields(SamplerConfig)}
    for family in families():
        if family.settings is None:
            continue
        keys = {f.name for f in fields(family.settings)}
        prefix = f"{family.name}_"
        for old in [k for k in out if k.startswith(prefix) and k not in shared]:
            key = old[len(prefix) :]
            if key not in keys:
                continue
            table = out.get(family.name, {})
            if not isinstance(table, Mapping):
                raise SpecError(f"config [sampler]: {family.name} must be a table")
            if key in table:
                raise SpecError(f"config [sampler]: {old} and [{family.table}] {key} both given")
            out[family.name] = {**table, key: out.pop(old)}
    return out


def family_rng(seed: int, index: int) -> np.random.Generator:
    """The stream ``mix`` picks shape ``index``'s family from (separate from the draw's own)."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index, 1)))


def pick_family(seed: int, index: int, cfg: SamplerConfig) -> str:
    """The family of shape ``index``: ``cfg.family``, or a weighted pick from ``cfg.mix``."""
    if cfg.family != MIX:
        return cfg.family
    return str(choose(family_rng(seed, index), cfg.mix, cfg.mix_weights))


def draw_equation(seed: int, index: int, cfg: SamplerConfig) -> Draw:
    """Shape ``index`` of the run ``seed``: a pure function of its arguments.

    ``cfg.family`` picks the distribution; ``mix`` picks one family per index from a stream of
    its own, so a ``free`` shape of the mix is the very shape ``family = "free"`` draws there.
    The family's shape is then stretched along the axes (:mod:`.stretch`, a stream of its own).
    """
    name = pick_family(seed, index, cfg)
    family = get_family(name)
    draw = family.draw(seed, index, cfg, cfg.settings(name))
    return stretch_draw(seed, index, cfg, draw, family.aspect_limit)


def draw_spec(
    seed: int,
    index: int,
    cfg: SamplerConfig,
    grid: int,
    config_hash: str,
    threads: int | None = None,
) -> tuple[Draw, float | None, SurfaceSpec]:
    """Shape ``index`` of the run ``seed`` as a spec with ``grid`` points per axis: the draw, its d
    (None: no d makes a surface; the spec then has d = 0) and the spec, whose provenance is
    ``seed``, ``index``, :data:`SAMPLER_VERSION` and the run's ``config_hash``.

    The one place a sampling run's shapes become specs (the sampler's workers and
    ``surfgen.draw``); ``threads`` as :func:`choose_d`.
    """
    draw = draw_equation(seed, index, cfg)
    d = choose_d(draw, cfg, threads=threads)
    provenance = {"seed": seed, "index": index, "sampler": SAMPLER_VERSION, "config": config_hash}
    spec = SurfaceSpec.from_tree(
        draw.equation.with_d(d or 0.0).to_tree(),
        draw.box.bounds(),
        (grid,) * 3,
        provenance=provenance,
    )
    return draw, d, spec


def choose_d(
    draw: Draw, cfg: DrawSettings, evaluator: str = "fast", threads: int | None = None
) -> float | None:
    """``d`` at the draw's quantile of the body's finite values on a coarse grid.

    Returns ``None`` when the body has fewer than two distinct finite values there
    (no ``d`` can make a surface). A family that chose d itself (``d_quantile`` None) gives it.
    """
    if draw.d_quantile is None:
        return draw.d
    return coarse_values(draw, cfg, evaluator, threads)[1]
