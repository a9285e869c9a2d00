"""Random shapes: :func:`draw` one, :func:`sample` a catalogue (the run of ``surfgen sample``),
or stream the accepted ones with :func:`shapes` (in this process, no files: for data loaders).

The sampler, its filters and the run's executors (numba, trimesh, pymeshlab) are imported when
these functions run, so that ``import surfgen`` loads none of them.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from surfgen.catalogue import Catalogue
from surfgen.display import facts_html, png_of, shorten
from surfgen.generator.errors import SurfgenError
from surfgen.generator.formula.limits import MAX_COUNT, check_count, check_seed
from surfgen.generator.model.sampler import draw_equation, draw_spec
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.run.config import Config
from surfgen.settings import ConfigLike, mesh_walls, run_config
from surfgen.surface import GridLike, Surface

if TYPE_CHECKING:
    import trimesh

    from surfgen.pipelines.run.shapes import ShapeOutcome


def draw(
    seed: int,
    index: int,
    *,
    family: str | None = None,
    config: ConfigLike = None,
    grid: int | None = None,
) -> Surface:
    """Shape ``index`` of the run ``seed``: the sampler's draw, whatever the filters say.

    A pure function of its arguments: shape ``(seed, index)`` of ``surfgen sample --seed
    SEED`` with the same config, grid and family has the same spec and key.

    Parameters
    ----------
    seed : int
        The run's seed, 0 to 2^63 - 1.
    index : int
        The draw's index in the run, from 0.
    family : str, optional
        ``sculpture``, ``lattice``, ``free`` or ``mix`` (default: the config's).
    config : Config, path or None
        The run's config (default: the defaults).
    grid : int, optional
        Points per axis (default: the config's ``[run] grid``).

    Returns
    -------
    Surface
        With the run's cap and walls, its config (for :meth:`Surface.check`) and family.

    Raises
    ------
    LimitError
        A seed, index or grid out of range.
    SpecError
        An unknown family or a bad config.
    """
    check_seed(seed)
    check_count(index, "index", 0)
    cfg = run_config(config, grid=grid, family=family)
    made, d, spec = draw_spec(seed, index, cfg.sampler, cfg.run.grid, cfg.hash, threads=1)
    return Surface(spec, cap=cfg.run.cap, walls=mesh_walls(cfg), config=cfg, _draw=made, _d=d)


def sample(
    n: int,
    seed: int = 0,
    *,
    out: str | os.PathLike[str] = "out/catalogue",
    grid: int | None = None,
    family: str | None = None,
    config: ConfigLike = None,
    workers: int | None = None,
    max_draws: int | None = None,
    resume: bool = False,
    dedupe: bool | None = None,
    thumbnails: bool = True,
    executor: str = "local",
    scheduler: str | None = None,
    max_memory: int | None = None,
    progress: Callable[[int, int, int], None] | None = None,
    notice: Callable[[str], None] | None = None,
) -> Catalogue:
    """Draw random shapes until ``n`` pass the filters, into the catalogue ``out``: the run of
    ``surfgen sample`` (the same catalogue, byte for byte, whatever ``workers``).

    Parameters
    ----------
    n : int
        Accepted shapes wanted.
    seed : int
        The run's seed: same seed, config and grid, same shapes.
    out : path
        The catalogue folder (created if needed).
    grid, family, config, dedupe, thumbnails
        As ``surfgen sample --grid --family --config --dedupe/--no-dedupe --no-thumbnails``.
    workers : int, optional
        Worker processes (default: all cores).
    max_draws : int, optional
        Stop after this many draws (default ``max(1000, 50 n)``).
    resume : bool
        Continue the run with the same seed, grid and config in ``out``.
    executor, scheduler : str
        ``local`` worker processes, or ``dask`` and a scheduler's address.
    max_memory : int, optional
        Bytes: refuse a run estimated to need more (default: the available memory).
    progress : callable, optional
        ``progress(accepted, drawn, n)`` after each committed draw.
    notice : callable, optional
        ``notice(text)`` before a long wait that is not sampling (compiling the kernels).

    Returns
    -------
    Catalogue
        The catalogue, with the run's :attr:`Catalogue.summary`: its ``status`` is
        ``complete``, or ``exhausted`` when fewer than ``n`` shapes were accepted within
        ``max_draws`` (the catalogue keeps them; the CLI then exits with an error).

    Raises
    ------
    CatalogueError
        ``out`` already has this run and ``resume`` is false.
    SpecError, LimitError
        A bad option (the CLI's messages).
    """
    # deferred: the run loads the sampler, its filters and the executors
    from surfgen.pipelines.run.sampling import run_sample

    cfg = run_config(config, grid=grid, family=family, dedupe=dedupe, thumbnails=thumbnails)
    summary = run_sample(
        n=n,
        seed=seed,
        config=cfg,
        catalogue=Path(out),
        workers=workers,
        max_draws=max_draws,
        resume=resume,
        progress=progress,
        executor=executor,
        scheduler=scheduler,
        max_memory=max_memory,
        notice=notice,
    )
    return Catalogue(out, summary=summary)


@dataclass(frozen=True, eq=False)
class Shape:
    """An accepted shape of :func:`shapes`: what the catalogue would hold, in memory.

    Attributes
    ----------
    index : int
        Its draw's index in the run.
    key : str
        Its key (the catalogue's file stem).
    surface : Surface
        Its spec, with the run's cap, walls and config.
    metrics : dict
        The catalogue's metrics (as stored: 10 significant digits).
    family : str
        The sampler family it was drawn from.
    """

    index: int
    key: str
    surface: Surface
    metrics: dict[str, Any]
    family: str
    _row: dict[str, Any] = field(repr=False)

    @property
    def formula(self) -> str:
        """The canonical formula (K3DSurf/MathMod syntax)."""
        return self.surface.formula

    @property
    def descriptor(self) -> str | None:
        """The shape descriptor the near-duplicate check compared (text, as stored)."""
        value = self._row.get("descriptor")
        return None if value is None else str(value)

    def mesh(self, grid: GridLike | None = None) -> trimesh.Trimesh:
        """The mesh the catalogue would store (its run's cap and walls): see
        :meth:`Surface.mesh`."""
        return self.surface.mesh(grid)

    def __repr__(self) -> str:
        return (
            f"Shape(index={self.index}, key={self.key!r}, family={self.family!r}, "
            f"formula={shorten(self.formula)!r})"
        )

    def _repr_png_(self) -> bytes | None:
        return self.surface._repr_png_()

    def _repr_html_(self) -> str:
        try:
            png: bytes | None = png_of(self.surface.thumbnail())
        except SurfgenError:
            png = None
        facts = [("index", self.index), ("family", self.family), ("formula", self.formula)]
        facts += [(k, self.metrics.get(k)) for k in ("genus", "components", "faces", "area")]
        return facts_html(f"Shape {self.key}", facts, png)


def shapes(
    seed: int = 0,
    *,
    grid: int | None = None,
    family: str | None = None,
    config: ConfigLike = None,
    dedupe: bool | None = None,
    max_draws: int | None = None,
) -> Iterator[Shape]:
    """The shapes :func:`sample` would accept, in its order, computed one at a time here.

    Lazy: each ``next`` draws, evaluates, meshes and judges until a shape is accepted; nothing
    is written. With the same ``seed``, ``grid``, ``family``, ``config`` and ``dedupe``, the
    first ``n`` shapes are those ``sample(n, seed, ...)`` catalogues into a new catalogue, with
    the same keys and metrics (near duplicates of earlier accepted shapes rejected as the run
    rejects them).

    Parameters
    ----------
    seed, grid, family, config, dedupe
        As :func:`sample`.
    max_draws : int, optional
        Stop after this many draws (default: no limit).

    Yields
    ------
    Shape
        Index, key, surface, metrics and family of each accepted shape.
    """
    check_seed(seed)
    if max_draws is not None:
        check_count(max_draws, "--max-draws")
    cfg = run_config(config, grid=grid, family=family, dedupe=dedupe, thumbnails=False)
    return _stream(seed, cfg, MAX_COUNT if max_draws is None else max_draws)


def _stream(seed: int, cfg: Config, max_draws: int) -> Iterator[Shape]:
    """The accepted outcomes of :func:`~surfgen.pipelines.run.shapes.make_shape`, judged for
    duplicates as the run's driver (``pipelines/run/sampling.py: _drive``) judges them in
    index order: an accepted shape is a duplicate when an accepted one has its identity (the
    same formula, box and grid), or, with ``dedupe``, its descriptor is within the threshold
    of one's."""
    # deferred: the sampler's shapes load numba, trimesh and pymeshlab
    from surfgen.filters.descriptor import DescriptorSet, descriptor_from_text
    from surfgen.pipelines.run.duplicates import near_duplicate
    from surfgen.pipelines.run.shapes import make_shape

    identities: set[str] = set()
    known = DescriptorSet()
    for index in range(max_draws):
        outcome = make_shape(index, seed=seed, config=cfg)
        row = outcome.row
        if not outcome.verdict.accepted:
            continue
        if row["identity"] in identities:
            continue
        if outcome.early_row is not None:  # dedupe on: judged at the early row, as the run does
            if near_duplicate(outcome.early_row, known, cfg.run.dedupe_threshold) is not None:
                continue
            values = descriptor_from_text(row["descriptor"])
            assert values is not None  # the worker wrote it from a descriptor
            known.add(row["key"], values)
        identities.add(row["identity"])
        yield _shape(seed, outcome, cfg)


def _shape(seed: int, outcome: ShapeOutcome, cfg: Config) -> Shape:
    """The :class:`Shape` of an accepted outcome; its surface has the draw again (a
    sculpture's envelope, for :meth:`Surface.check`: a fraction of the shape's cost)."""
    row = outcome.row
    spec = SurfaceSpec.from_json(row["spec"])
    made = draw_equation(seed, outcome.index, cfg.sampler)
    surface = Surface(
        spec, cap=cfg.run.cap, walls=mesh_walls(cfg), config=cfg, _draw=made, _d=row["d"]
    )
    family = json.loads(row["model"]).get("family", "free")
    return Shape(outcome.index, row["key"], surface, json.loads(row["metrics"]), family, row)
