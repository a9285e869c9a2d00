"""A sampling run: draw shapes in index order, evaluate, mesh, filter, catalogue.

Shape ``i`` is a pure function of ``(seed, i, config)`` (:func:`make_shape`), computed in worker
processes in any order; the parent (the catalogue's only writer) commits results strictly in
index order and stops at the ``n``-th accepted shape. So the catalogue holds exactly the first
``n`` accepted shapes by index, whatever the number of workers, and a killed run resumed with
``resume=True`` ends identical to an uninterrupted one.

The workers are an executor (:class:`~surfgen.pipelines.run.executor.Executor`): local processes
(``executor="local"``), or a Dask cluster (``executor="dask"``, :mod:`surfgen.pipelines.run.cluster`),
whose workers hand the files back as bytes (:func:`make_shape_packed`). Ordering, commits and
files are handled by one code path (:func:`_drive`) for both.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import sqlite3
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from contextlib import ExitStack, nullcontext
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from surfgen.filters.descriptor import (
    DescriptorSet,
    descriptor,
    descriptor_from_text,
    descriptor_to_text,
)
from surfgen.filters.shape import quality_metrics
from surfgen.filters.verdict import (
    ACCEPT,
    REASONS,
    Verdict,
    judge,
    plain,
    quick_metrics,
    screen_field,
    shape_metrics,
)
from surfgen.generator import __version__
from surfgen.generator.errors import EmptySurface, SpecError, SurfgenError
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.files import renaming, write_atomic
from surfgen.generator.formula.expr import Expr
from surfgen.generator.formula.limits import (
    MAX_COUNT,
    check_count,
    check_memory,
    check_seed,
    estimate_memory,
)
from surfgen.generator.mesh.exchange import encode_mesh
from surfgen.generator.mesh.mesh import Mesh, extract_with_edges, face_areas
from surfgen.generator.mesh.walls import label_walls
from surfgen.generator.model.families import envelope_departure
from surfgen.generator.model.sampler import SAMPLER_VERSION, Draw, choose_d, draw_equation
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.curation import ensure_descriptors
from surfgen.pipelines.catalogue.store import DB_NAME, Catalogue, CatalogueError, open_catalogue
from surfgen.pipelines.run.config import Config
from surfgen.pipelines.run.executor import Executor, KillablePool
from surfgen.pipelines.run.warmup import warm_shape_kernels

log = logging.getLogger(__name__)

METRIC_DIGITS = 10  # significant digits kept in stored metrics
EXECUTORS = ("local", "dask")
ACCEPTED_FILE = "accepted-descriptors.tsv"  # in the staging folder: see AcceptedDescriptors
# Where each file of an accepted shape goes: (catalogue column, ShapeOutcome field).
FILE_FIELDS = (
    ("mesh_path", "mesh_file"),
    ("thumb_path", "thumb_file"),
    ("turntable_path", "turntable_file"),
)


@dataclass(frozen=True)
class ShapeOutcome:
    """What a worker hands back for one index: the row to store and its files, either staged
    on the driver's disk (``*_file``) or, from a remote worker, as bytes (``data``: pairs of
    a ``*_file`` field name and the file's bytes)."""

    index: int
    row: dict[str, Any]
    verdict: Verdict
    mesh_file: Path | None = None
    thumb_file: Path | None = None
    turntable_file: Path | None = None
    data: tuple[tuple[str, bytes], ...] = ()
    write_error: str | None = None  # the shape's files could not be written (disk full...)
    # The row at the near-duplicate check (the row a duplicate gets), and whether the worker
    # stopped there because it already knew of an accepted shape near this one.
    early_row: dict[str, Any] | None = None
    early_stop: bool = False


class SampleWriteError(SurfgenError):
    """A sampling run stopped because a file could not be written; ``--resume`` continues it."""


@dataclass
class RunSummary:
    run_id: int
    seed: int
    n: int
    accepted: int
    drawn: int
    counts: dict[str, int]
    seconds: float
    catalogue: Path
    status: str
    stage_seconds: dict[str, float] = field(default_factory=dict)
    setup_seconds: float = 0.0  # of ``seconds``, before the first draw (the first run compiles)

    @property
    def shapes_per_minute(self) -> float:
        """Accepted shapes per minute of sampling (the setup left out)."""
        sampling = self.seconds - self.setup_seconds
        return 60.0 * self.accepted / sampling if sampling > 0 else 0.0


def versions() -> dict[str, str]:
    import numba
    import skimage
    import trimesh

    from surfgen.filters.meshlab import installed_version

    return {
        "surfgen": __version__,
        "numpy": np.__version__,
        "numba": numba.__version__,
        "scikit-image": skimage.__version__,
        "trimesh": trimesh.__version__,
        "pymeshlab": installed_version(),
    }


def _round_metrics(m: dict[str, Any]) -> dict[str, Any]:
    out = {}
    for k, v in sorted(m.items()):
        if isinstance(v, float):
            v = float(f"{v:.{METRIC_DIGITS - 1}e}") if np.isfinite(v) else None
        elif isinstance(v, list | tuple):
            v = [float(f"{x:.{METRIC_DIGITS - 1}e}") if isinstance(x, float) else x for x in v]
        out[k] = v
    return out


class _Stopwatch:
    """Seconds spent per stage (``eval``, ``mesh``, ``walls``, ``filters``, ``describe``,
    ``io``, ``pictures``)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._last = time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        self.seconds[stage] = self.seconds.get(stage, 0.0) + now - self._last
        self._last = now


def make_shape(
    index: int,
    *,
    seed: int,
    config: Config,
    staging: Path | None = None,
    pictures: bool = False,
    duplicates: AcceptedDescriptors | None = None,
) -> ShapeOutcome:
    """Draw, evaluate, mesh, measure and judge shape ``index``: a pure function of its inputs
    (timings aside). Known failures become a rejected verdict with its reason.

    With near-duplicate rejection on, a mesh that passes the cheap checks is described there
    and the outcome carries that point's row (``early_row``): the parent rejects the shape as a
    duplicate with that row if an accepted shape is near it (:func:`_drive`), so that verdict
    does not depend on the later checks. ``duplicates`` (a worker's view of the shapes already
    accepted) lets the worker stop there when it already knows; the row is the same."""
    watch = _Stopwatch()
    draw = draw_equation(seed, index, config.sampler)
    d = choose_d(draw, config.sampler, threads=1)  # one process per core: numba serial inside
    equation = draw.equation.with_d(d or 0.0)
    tree = equation.to_tree()
    provenance = {"seed": seed, "index": index, "sampler": SAMPLER_VERSION, "config": config.hash}
    spec = SurfaceSpec.from_tree(
        tree, draw.box.bounds(), (config.run.grid,) * 3, provenance=provenance
    )
    watch.lap("eval")
    verdict, metrics, mesh, rest = _judge(tree, spec, d, config, watch, draw)

    def row_for(verdict: Verdict) -> dict[str, Any]:
        return {
            "key": spec.key,
            "spec": spec.to_json(),
            "formula": spec.formula,
            "identity": spec.identity,
            "d": d,
            "model": _model_json(draw, equation),
            **_metric_columns(_round_metrics(metrics)),
            "verdict": "accepted" if verdict.accepted else "rejected",
            "reasons": json.dumps(list(verdict.reasons)),
        }

    early = described = None
    if verdict.accepted and config.run.dedupe:  # where near duplicates are judged
        described = descriptor_to_text(descriptor(mesh))
        watch.lap("describe")
        early = dict(row_for(DUPLICATE), descriptor=described)
        # compared as stored (rounded), as the parent compares it
        if duplicates is not None and duplicates.near(descriptor_from_text(described)):
            early["timings"] = _timings(watch)
            return ShapeOutcome(index, dict(early), DUPLICATE, early_row=early, early_stop=True)
    if verdict.accepted:
        verdict = rest()
    row = row_for(verdict)
    out = ShapeOutcome(index, row, verdict, early_row=early)
    if verdict.accepted and mesh is not None:
        row["descriptor"] = described or descriptor_to_text(descriptor(mesh))
        watch.lap("describe")
        if staging is not None:
            try:
                out = _with_files(out, mesh, staging, pictures, watch)
            except OSError as exc:  # not a verdict on the shape: the run must stop
                return ShapeOutcome(index, row, verdict, write_error=_write_error(exc, staging))
    row["timings"] = _timings(watch)
    if early is not None:
        early["timings"] = row["timings"]
    return out


DUPLICATE = Verdict.reject("duplicate")


def _timings(watch: _Stopwatch) -> str:
    return json.dumps({k: round(v, 4) for k, v in watch.seconds.items()}, sort_keys=True)


def _model_json(draw: Draw, equation) -> str:
    return json.dumps(draw.model_dict(equation), sort_keys=True, separators=(",", ":"))


def _judge(
    tree: Expr,
    spec: SurfaceSpec,
    d: float | None,
    config: Config,
    watch: _Stopwatch,
    draw: Draw | None = None,
) -> tuple[Verdict, dict[str, Any], Mesh | None, Callable[[], Verdict]]:
    """The cascade: coarse field, full field (and how far it departs from the draw's envelope,
    if any), mesh, cheap mesh checks; then, when called, ``rest()``: the walls, the full mesh
    checks and the shape-quality metrics of an accepted mesh. Returns the cheap checks'
    verdict, the metrics (``rest()`` adds to them), the mesh (if made) and ``rest``."""
    fcfg, run = config.filters, config.run
    metrics: dict[str, Any] = {}

    def stop(verdict: Verdict, mesh: Mesh | None = None):
        return verdict, metrics, mesh, lambda: verdict

    if d is None:
        return stop(Verdict.reject("no_crossing"))
    box = Box.from_bounds(spec.box)
    coarse = evaluate(tree, Grid(box, (fcfg.coarse_grid,) * 3), threads=1)
    verdict = screen_field(coarse.values, spec.level, fcfg, coarse=True, capped=run.cap)
    watch.lap("eval")
    if not verdict.accepted:
        return stop(verdict)
    field_ = evaluate(tree, spec.to_grid(), threads=1)
    metrics["nonfinite"] = field_.nonfinite
    verdict = screen_field(field_.values, spec.level, fcfg, coarse=False)
    if verdict.accepted and draw is not None and draw.envelope is not None:
        envelope = evaluate(draw.envelope, spec.to_grid(), threads=1).values
        metrics["departure"] = envelope_departure(field_.values, envelope, spec.level)
        if plain(metrics, fcfg):  # no need to mesh it
            verdict = Verdict.reject("plain")
    watch.lap("eval")
    if not verdict.accepted:
        return stop(verdict)
    # Without its walls a capped solid is open on purpose: do not ask it to be watertight.
    capped = run.cap and run.walls != "remove"
    try:
        mesh, edges = extract_with_edges(field_, spec.level, cap=capped)
        areas = face_areas(mesh)  # the walls' and the filters' (computed once)
        if run.walls != "keep":  # the mesh itself depends on the classification
            mesh, crossings = label_walls(
                mesh, edges, field_, tree, {}, spec.level, run.cap, run.walls, areas
            )
            metrics["wall_fraction"] = crossings.wall_fraction
            if run.walls == "remove":  # fewer faces
                areas = face_areas(mesh)
    except EmptySurface:
        return stop(Verdict.reject("empty"))
    finally:
        watch.lap("mesh")
    # Cheap checks first (most draws fail them)...
    quick = quick_metrics(mesh, spec.box, areas)
    metrics.update(quick)
    verdict = judge(metrics, fcfg, capped=capped)
    watch.lap("filters")

    def rest() -> Verdict:
        verdict = ACCEPT
        if "wall_fraction" not in metrics:
            # ...then the walls (root, pole or jump for every crossing: refines with the formula)
            _, crossings = label_walls(
                mesh, edges, field_, tree, {}, spec.level, run.cap, "keep", areas
            )
            metrics["wall_fraction"] = crossings.wall_fraction
            watch.lap("walls")
            verdict = judge(metrics, fcfg, capped=capped)
        if verdict.accepted:  # ...then pymeshlab's topology and the curvature (quick reused)
            metrics.update(shape_metrics(mesh, spec.box, quick=quick))
            verdict = judge(metrics, fcfg, capped=capped)
        if verdict.accepted:
            metrics.update(quality_metrics(mesh, metrics))
        watch.lap("filters")
        return verdict

    return verdict, metrics, mesh, rest


def _metric_columns(m: dict[str, Any]) -> dict[str, Any]:
    cols = {
        k: m.get(k) for k in ("faces", "vertices", "components", "genus", "euler", "area", "volume")
    }
    cols["metrics"] = json.dumps(m, sort_keys=True, separators=(",", ":"))
    return cols


def _with_files(
    out: ShapeOutcome, mesh: Mesh, staging: Path, pictures: bool, watch: _Stopwatch
) -> ShapeOutcome:
    """Write the accepted shape's files into the run's staging folder; the parent moves them
    into the catalogue when it commits the row (so a discarded index leaves nothing behind).

    Only the thumbnail is rendered here (contact sheets and the gallery grid show every one);
    the 12-view turntable, which most shapes never get hovered for, is rendered the first
    time it is asked for (:func:`surfgen.pipelines.pictures.gallery.ensure_turntable`)."""
    key = out.row["key"]
    mesh_file = write_atomic(staging / f"{key}.ply", encode_mesh(mesh, "ply"))
    watch.lap("io")
    thumb = None
    if pictures:
        from surfgen.pipelines.pictures.raster import THUMBNAIL_SIZE, render_thumbnail

        thumb = render_thumbnail(mesh, staging / f"{key}.thumb.png", size=THUMBNAIL_SIZE)
        watch.lap("pictures")
    return replace(out, mesh_file=mesh_file, thumb_file=thumb)


def make_shape_packed(
    index: int, *, seed: int, config: Config, pictures: bool = False
) -> ShapeOutcome:
    """:func:`make_shape` for a worker that shares no disk with the driver: the accepted
    shape's files are made in a temporary folder and handed back as bytes in ``data``."""
    with tempfile.TemporaryDirectory(prefix="surfgen-shape-") as tmp:
        out = make_shape(index, seed=seed, config=config, staging=Path(tmp), pictures=pictures)
        data = tuple(
            (name, getattr(out, name).read_bytes())
            for _, name in FILE_FIELDS
            if getattr(out, name) is not None
        )
    return replace(out, mesh_file=None, thumb_file=None, data=data)


def _stage(outcome: ShapeOutcome, staging: Path) -> ShapeOutcome:
    """Write the bytes a remote worker handed back into the driver's staging folder, so the
    outcome looks like a local one (its files are moved in when the row commits)."""
    if not outcome.data:
        return outcome
    key = outcome.row["key"]
    suffix = {"mesh_file": ".ply", "thumb_file": ".thumb.png", "turntable_file": ".turntable.png"}
    try:
        files = {
            name: write_atomic(staging / f"{key}{suffix[name]}", b) for name, b in outcome.data
        }
    except OSError as exc:
        return replace(outcome, data=(), write_error=_write_error(exc, staging))
    return replace(outcome, data=(), **files)


def open_executor(
    executor: str,
    *,
    seed: int,
    config: Config,
    staging: Path,
    workers: int | None,
    scheduler: str | None = None,
    notice: Callable[[str], None] | None = None,
) -> Executor:
    """The workers that compute shapes: ``local`` processes, or a Dask cluster (``scheduler``
    address, or a local one of ``workers`` processes). ``notice`` hears when the local workers'
    kernels must be compiled first (a minute or two, once per machine). Raises :class:`SpecError` for an unknown
    executor and ``ExecutorError`` when Dask is missing or unreachable."""
    pictures = config.run.thumbnails
    if executor == "local":
        duplicates = (
            AcceptedDescriptors(staging / ACCEPTED_FILE, config.run.dedupe_threshold)
            if config.run.dedupe
            else None
        )
        fn = partial(
            make_shape,
            seed=seed,
            config=config,
            staging=staging,
            pictures=pictures,
            duplicates=duplicates,
        )
        # Compile (fresh checkout) or load numba's kernels once, here: the forked workers
        # inherit them, and no shape's timeout is spent compiling.
        warm_shape_kernels(notice=notice)
        return KillablePool(fn, workers or os.cpu_count() or 1, config.run.timeout)
    if executor == "dask":
        from surfgen.pipelines.run.cluster import DaskPool

        fn = partial(make_shape_packed, seed=seed, config=config, pictures=pictures)
        return DaskPool(
            fn, config.run.timeout, scheduler=scheduler, workers=workers, environment=versions
        )
    raise SpecError(f"unknown executor '{executor}' (allowed: {', '.join(EXECUTORS)})")


def run_sample(
    *,
    n: int,
    seed: int,
    config: Config,
    catalogue: Path,
    workers: int | None = None,
    max_draws: int | None = None,
    resume: bool = False,
    progress: Callable[[int, int, int], None] | None = None,
    executor: str = "local",
    scheduler: str | None = None,
    max_memory: int | None = None,
    notice: Callable[[str], None] | None = None,
) -> RunSummary:
    """Sample until ``n`` shapes are accepted or ``max_draws`` indices are drawn.

    ``progress(accepted, drawn, n)`` is called after each committed index; ``notice(text)``
    before a long wait that is not sampling (compiling the kernels on a new machine). ``executor`` is
    ``local`` (``workers`` processes) or ``dask`` (the cluster at ``scheduler``, or a local one
    of ``workers`` processes). Raises :class:`SpecError` for bad options,
    :class:`CatalogueError` when a run with the same seed, grid and config exists and ``resume``
    is false, and ``ExecutorError`` when the Dask cluster cannot be used.
    """
    check_count(n, "--n")
    check_seed(seed)
    if executor not in EXECUTORS:
        raise SpecError(f"unknown executor '{executor}' (allowed: {', '.join(EXECUTORS)})")
    if scheduler and executor != "dask":
        raise SpecError("--scheduler needs --executor dask")
    if workers is not None:
        check_count(workers, "--workers", 1, 256)
    max_draws = max_draws if max_draws is not None else min(max(1000, 50 * n), MAX_COUNT)
    check_count(max_draws, "--max-draws")
    grid = config.run.grid
    check_memory(
        estimate_memory(grid**3, mesh=True),
        max_memory,
        f"sampling on a {grid}^3 grid",
        times=workers or os.cpu_count() or 1,
    )
    start = time.perf_counter()
    with open_catalogue(catalogue) as cat:
        cat.make_dirs()
        run = cat.find_run(seed, config.hash, config.run.grid)
        if run is not None and not resume:
            hint = (
                "use --resume with a larger --n to extend it"
                if run.accepted >= run.n
                else "use --resume to continue it"
            )
            raise CatalogueError(
                f"{catalogue} already has run {run.id} with seed {seed}, grid {run.grid} and this "
                f"config ({run.accepted}/{run.n} accepted, {run.status}): {hint}"
            )
        done = run is not None and run.accepted >= n
        staging = cat.root / ".staging"
        # The workers start before the run is recorded: a cluster that cannot be reached
        # leaves the catalogue as it was.
        pool = (
            nullcontext(None)
            if done
            else open_executor(
                executor,
                seed=seed,
                config=config,
                staging=staging,
                workers=workers,
                scheduler=scheduler,
                notice=notice,
            )
        )
        ready = time.perf_counter()
        with ExitStack() as cleanup:
            # after the workers are gone (they write there): what was staged and not
            # committed is redone by --resume
            cleanup.callback(shutil.rmtree, staging, ignore_errors=True)
            cleanup.enter_context(pool)
            if run is None:
                run = cat.create_run(
                    seed,
                    n,
                    config.run.grid,
                    config.to_dict(),
                    config.hash,
                    SAMPLER_VERSION,
                    versions(),
                )
            cat.set_run_status(run.id, "running", n=max(n, run.n) if resume else n)
            status, stage = "interrupted", {}
            try:
                if done:
                    status = "complete"
                else:
                    shutil.rmtree(staging, ignore_errors=True)  # an interrupted run's leftovers
                    staging.mkdir(exist_ok=True)
                    status, stage = _drive(cat, run.id, n, seed, config, pool, max_draws, progress)
            finally:
                try:
                    cat.set_run_status(run.id, status)
                except sqlite3.Error as exc:  # e.g. the disk is still full: keep the first error
                    log.error("could not record the run's status (%s)", exc)
        final = cat.get_run(run.id)
    return RunSummary(
        run_id=final.id,
        seed=seed,
        n=n,
        accepted=final.accepted,
        drawn=final.next_index,
        counts=final.counts,
        seconds=time.perf_counter() - start,
        catalogue=Path(catalogue),
        status=status,
        stage_seconds=stage,
        setup_seconds=ready - start,
    )


def _drive(
    cat: Catalogue,
    run_id: int,
    n: int,
    seed: int,
    config: Config,
    pool: Executor,
    max_draws: int,
    progress,
) -> tuple[str, dict[str, float]]:
    """Feed indices to ``pool`` and commit its results strictly in index order."""
    run = cat.get_run(run_id)
    accepted, next_index = run.accepted, run.next_index
    counts: Counter[str] = Counter(run.counts)
    stage: Counter[str] = Counter()
    staging = cat.root / ".staging"
    buffer: dict[int, Any] = {}
    published: list[tuple[str, str]] = []
    known = DescriptorSet()
    if config.run.dedupe:
        for key, values in ensure_descriptors(cat)[0].items():
            known.add(key, values)
        texts = cat.conn.execute(
            "SELECT key, descriptor FROM shapes WHERE verdict = 'accepted' AND descriptor IS NOT NULL"
        ).fetchall()
        keys = set(known.keys)
        _publish(staging / ACCEPTED_FILE, [(r[0], r[1]) for r in texts if r[0] in keys])

    def tasks():
        i = next_index
        while i < max_draws and accepted < n:
            yield i
            i += 1

    for result in pool.run(tasks()):
        if result.task < next_index or result.task in buffer:
            continue  # already committed or buffered: never twice (an executor's retry)
        if result.status == "ok" and result.value.write_error is not None:
            # Stop at the first write error: what is committed is a prefix of the run, and
            # this shape (and any after it) is redone by --resume once there is space.
            _stop_writing(result.value.write_error, result.task, accepted)
        staged = _stage(_outcome(result, seed, config), staging)
        if staged.write_error is not None:
            _stop_writing(staged.write_error, result.task, accepted)
        buffer[result.task] = staged
        while next_index in buffer and accepted < n:
            outcome = buffer.pop(next_index)
            for k, v in json.loads(outcome.row.get("timings", "{}")).items():
                stage[k] += v  # the work done, whatever the row kept
            if outcome.early_row is not None:  # near duplicates are judged at that point
                dup = cat.has_accepted_identity(outcome.early_row["identity"])
                if dup is None:
                    dup = _near_duplicate(outcome.early_row, known, config.run.dedupe_threshold)
                if dup is not None:
                    row = dict(outcome.early_row, duplicate_of=dup)
                    outcome = ShapeOutcome(outcome.index, row, DUPLICATE)
                elif outcome.early_stop:  # cannot happen: the worker's shapes are ours
                    log.warning("shape %d: stopped as a duplicate by its worker alone", next_index)
                    outcome = make_shape(
                        next_index,
                        seed=seed,
                        config=config,
                        staging=staging,
                        pictures=config.run.thumbnails,
                    )
                if outcome.verdict.accepted:
                    key, text = outcome.row["key"], outcome.row["descriptor"]
                    known.add(key, descriptor_from_text(text))
                    published.append((key, text))
            elif outcome.verdict.accepted:
                dup = cat.has_accepted_identity(outcome.row["identity"])
                if dup is not None:
                    outcome = _rejected(outcome, ("duplicate",))
                    outcome.row["duplicate_of"] = dup
            _commit(cat, run_id, outcome, counts)
            if published:  # once its row is in
                _publish(staging / ACCEPTED_FILE, published)
                published.clear()
            accepted += int(outcome.verdict.accepted)
            next_index += 1
            if progress is not None:
                progress(accepted, next_index, n)
        if accepted >= n:
            break
    status = "complete" if accepted >= n else "exhausted"
    return status, dict(stage)


def _write_error(exc: OSError, staging: Path) -> str:
    return f"{exc.filename or staging}: {exc.strerror}"


def _stop_writing(error: str, index: int, accepted: int) -> None:
    raise SampleWriteError(
        f"cannot write {error}; sampling stopped before shape {index} ({accepted} accepted "
        "shapes are catalogued): free some space and run the same command with --resume"
    )


def _near_duplicate(row: dict[str, Any], known: DescriptorSet, threshold: float) -> str | None:
    """The key of the accepted shape nearest to ``row``'s if it is within ``threshold``."""
    key, dist = known.nearest(descriptor_from_text(row["descriptor"]))
    return key if dist < threshold else None


class AcceptedDescriptors:
    """A worker's view of the accepted shapes' descriptors: the parent appends each one's
    key and descriptor text to a file in the run's staging folder (:func:`_publish`), as it
    commits them; :meth:`near` reads what was added since it last looked and says whether a
    descriptor is within ``threshold`` of one of them, so the worker can stop at the
    near-duplicate check.

    Every shape it holds is in the parent's :class:`DescriptorSet` too, with the descriptor
    stored with the row, so the parent, which checks against all of them, reaches the same
    verdict: the worker only saves the later checks' time. (A file, not the catalogue: SQLite
    connections do not survive the fork that starts the workers.)"""

    def __init__(self, path: Path, threshold: float) -> None:
        self.path, self.threshold = Path(path), float(threshold)
        self._known = DescriptorSet()
        self._offset = 0

    def __getstate__(self) -> dict[str, Any]:
        return {"path": self.path, "threshold": self.threshold}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["path"], state["threshold"])

    def near(self, values: np.ndarray) -> bool:
        try:
            self._refresh()
        except OSError as exc:  # no file yet, or gone: the parent decides alone
            log.debug("accepted descriptors not read (%s)", exc)
        return len(self._known) > 0 and self._known.nearest(values)[1] < self.threshold

    def _refresh(self) -> None:
        with open(self.path, "rb") as f:
            f.seek(self._offset)
            data = f.read()
        end = data.rfind(b"\n") + 1  # whole lines only: the parent may be writing the next
        for line in data[:end].decode("utf-8", errors="replace").splitlines():
            key, _, text = line.partition("\t")
            values = descriptor_from_text(text)
            if values is not None:
                self._known.add(key, values)
        self._offset += end


def _publish(path: Path, rows: list[tuple[str, str]]) -> None:
    """Append accepted shapes' ``(key, descriptor text)`` for :class:`AcceptedDescriptors`.

    Only an optimisation: if it cannot be written (a full disk), the workers know less and
    the parent, which decides, goes on; a failed append leaves at most a partial last line,
    which the readers skip until a newline ends it."""
    try:
        with open(path, "a", encoding="utf-8") as f:
            f.write("".join(f"{key}\t{text}\n" for key, text in rows))
    except OSError as exc:
        log.debug("accepted descriptors not published (%s)", exc)


def _rejected(outcome: ShapeOutcome, reasons: tuple[str, ...]) -> ShapeOutcome:
    row = dict(outcome.row, verdict="rejected", reasons=json.dumps(list(reasons)))
    return ShapeOutcome(outcome.index, row, Verdict.reject(*reasons))


def _outcome(res, seed: int, config: Config) -> ShapeOutcome:
    """A worker's outcome, or a rejection recording why the worker gave none."""
    if res.status == "ok":
        return res.value
    reason = "timeout" if res.status == "timeout" else "crashed"
    log.warning("shape %d: %s (%s)", res.task, reason, res.message)
    # The spec of a shape is cheap and safe to rebuild here: draw and d need no meshing.
    draw = draw_equation(seed, res.task, config.sampler)
    provenance = {
        "seed": seed,
        "index": res.task,
        "sampler": SAMPLER_VERSION,
        "config": config.hash,
    }
    spec = SurfaceSpec.from_tree(
        draw.equation.to_tree(),
        draw.box.bounds(),
        (config.run.grid,) * 3,
        provenance={**provenance, "failed": reason},
    )
    row = {
        "key": spec.key,
        "spec": spec.to_json(),
        "formula": spec.formula,
        "identity": spec.identity,
        "d": None,
        "model": _model_json(draw, draw.equation),
        "verdict": "rejected",
        "reasons": json.dumps([reason]),
        "metrics": "{}",
        "timings": "{}",
        "error": res.message,
    }
    return ShapeOutcome(res.task, row, Verdict.reject(reason))


def _commit(cat: Catalogue, run_id: int, outcome: ShapeOutcome, counts: Counter) -> None:
    """Move the shape's staged files into the catalogue and insert its row, as one: if a
    rename or the row fails (a full disk, for SQLite too), the files already moved go back to
    the staging folder, so the catalogue never has a file without its row or a row without
    its files, and the run stops for ``--resume`` to redo this shape."""
    row = dict(outcome.row)
    key = row["key"]
    reasons = Counter(counts)
    if not outcome.verdict.accepted:
        for r in outcome.verdict.reasons:
            reasons[r] += 1
    assert all(r in REASONS for r in outcome.verdict.reasons), outcome.verdict.reasons
    stop = f"sampling stopped before shape {outcome.index}: fix it and run the same command with --resume"
    try:
        with renaming() as tx:
            if outcome.verdict.accepted:
                files = (
                    ("mesh_path", cat.meshes / f"{key}.ply", outcome.mesh_file),
                    ("thumb_path", cat.thumbs / f"{key}.png", outcome.thumb_file),
                    ("turntable_path", cat.turntables / f"{key}.png", outcome.turntable_file),
                )
                for column, path, staged in files:
                    if staged is not None:
                        tx.move(staged, path)
                        row[column] = str(path.relative_to(cat.root))
            cat.record_shape(run_id, outcome.index, row, outcome.verdict.accepted, reasons)
    except OSError as exc:
        raise SampleWriteError(f"cannot write {exc.filename}: {exc.strerror}; {stop}") from None
    except sqlite3.Error as exc:
        raise SampleWriteError(
            f"cannot write catalogue {cat.root / DB_NAME}: {exc}; {stop}"
        ) from None
    counts.clear()
    counts.update(reasons)  # only once the row is in
