"""A sampling run: draw shapes in index order, evaluate, mesh, filter, catalogue.

Shape ``i`` is a pure function of ``(seed, i, config)``
(:func:`~surfgen.pipelines.run.shapes.make_shape`), computed in worker processes in any order;
the parent (the catalogue's only writer) commits results strictly in index order and stops at
the ``n``-th accepted shape. So the catalogue holds exactly the first ``n`` accepted shapes by
index, whatever the number of workers, and a killed run resumed with ``resume=True`` ends
identical to an uninterrupted one.

The workers are an executor (:class:`~surfgen.pipelines.run.executor.Executor`): local processes
(``executor="local"``), or a Dask cluster (``executor="dask"``, :mod:`surfgen.pipelines.run.cluster`),
whose workers hand the files back as bytes
(:func:`~surfgen.pipelines.run.shapes.make_shape_packed`). Ordering, commits and files are
handled by one code path (:func:`_drive`) for both.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import sqlite3
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
    descriptor_from_text,
)
from surfgen.filters.meshlab import installed_version
from surfgen.filters.verdict import (
    REASONS,
    Verdict,
)
from surfgen.generator import __version__
from surfgen.generator.errors import SpecError, SurfgenError
from surfgen.generator.files import renaming, write_atomic
from surfgen.generator.formula.limits import (
    MAX_COUNT,
    check_count,
    check_memory,
    check_seed,
    estimate_memory,
)
from surfgen.generator.model.sampler import SAMPLER_VERSION, draw_equation
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.curation import ensure_descriptors
from surfgen.pipelines.catalogue.store import DB_NAME, Catalogue, CatalogueError, open_catalogue
from surfgen.pipelines.run.cluster import DaskPool
from surfgen.pipelines.run.config import Config
from surfgen.pipelines.run.duplicates import (
    ACCEPTED_FILE,
    AcceptedDescriptors,
    near_duplicate,
    publish,
)
from surfgen.pipelines.run.executor import Executor, KillablePool
from surfgen.pipelines.run.shapes import (
    DUPLICATE,
    ShapeOutcome,
    make_shape,
    make_shape_packed,
    model_json,
    write_error,
)
from surfgen.pipelines.run.warmup import warm_shape_kernels

log = logging.getLogger(__name__)


EXECUTORS = ("local", "dask")


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

    return {
        "surfgen": __version__,
        "numpy": np.__version__,
        "numba": numba.__version__,
        "scikit-image": skimage.__version__,
        "trimesh": trimesh.__version__,
        "pymeshlab": installed_version(),
    }


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
        return replace(outcome, data=(), write_error=write_error(exc, staging))
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
        publish(staging / ACCEPTED_FILE, [(r[0], r[1]) for r in texts if r[0] in keys])

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
                    dup = near_duplicate(outcome.early_row, known, config.run.dedupe_threshold)
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
                publish(staging / ACCEPTED_FILE, published)
                published.clear()
            accepted += int(outcome.verdict.accepted)
            next_index += 1
            if progress is not None:
                progress(accepted, next_index, n)
        if accepted >= n:
            break
    status = "complete" if accepted >= n else "exhausted"
    return status, dict(stage)


def _stop_writing(error: str, index: int, accepted: int) -> None:
    raise SampleWriteError(
        f"cannot write {error}; sampling stopped before shape {index} ({accepted} accepted "
        "shapes are catalogued): free some space and run the same command with --resume"
    )


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
        "model": model_json(draw, draw.equation),
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
