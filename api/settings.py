"""A sampling run's config as the API takes it: a :class:`~surfgen.pipelines.run.config.Config`,
a TOML file, or None (the defaults), with the options ``surfgen sample`` applies on top.

Reading a config loads the filters' module (numba, pymeshlab): that happens when a function
that needs a config runs, never at ``import surfgen``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal, TypeAlias

from surfgen.generator.eval.grid import MAX_POINTS, MIN_POINTS
from surfgen.generator.formula.limits import check_count
from surfgen.pipelines.run.config import Config, load_config

ConfigLike: TypeAlias = Config | str | os.PathLike[str] | None
"""A config: a :class:`Config`, the path of a TOML file, or None for the defaults."""

Walls: TypeAlias = Literal["keep", "remove", "mark"]
"""What a mesh keeps of the walls (poles and jumps): ``keep`` the solid's whole boundary,
``remove`` only the zero set (open sheets), ``mark`` all of it with each face labelled."""


def run_config(
    config: ConfigLike = None,
    *,
    grid: int | None = None,
    family: str | None = None,
    dedupe: bool | None = None,
    thumbnails: bool | None = None,
) -> Config:
    """The config of a run, as ``surfgen sample --config --grid --family --dedupe
    --no-thumbnails`` makes it: ``config`` (a :class:`Config`, a TOML path, or None: the
    defaults) with the options that are not None applied.

    Raises
    ------
    SpecError
        A config file, family or grid that is not allowed (the CLI's messages).
    LimitError
        A grid outside [MIN_POINTS, MAX_POINTS].
    """
    if grid is not None:
        check_count(grid, "--grid", MIN_POINTS, MAX_POINTS)
    cfg = config if isinstance(config, Config) else load_config(_path(config))
    cfg = cfg.with_grid(grid)
    if family is not None:
        cfg = cfg.with_family(family)
    if dedupe is not None:
        cfg = cfg.with_run(dedupe=dedupe)
    if thumbnails is not None and not thumbnails:
        cfg = cfg.with_run(thumbnails=False)
    return cfg


def _path(config: str | os.PathLike[str] | None) -> Path | None:
    return None if config is None else Path(config)


def mesh_walls(config: Config) -> Walls | None:
    """How a run's shapes are meshed: None (no classification) for ``keep``, whose mesh is
    the same, else the run's walls mode."""
    walls = config.run.walls
    if walls == "keep":
        return None
    return "remove" if walls == "remove" else "mark"
