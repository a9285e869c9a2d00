"""A sampling run: draw shapes in index order, evaluate, mesh, filter, catalogue.

Shape ``i`` is a pure function of ``(seed, i, config)`` (:func:`make_shape`), computed in worker
processes in any order; the parent (the catalogue's only writer) commits results strictly in
index order and stops at the ``n``-th accepted shape. So the catalogue holds exactly the first
``n`` accepted shapes by index, whatever the number of workers, and a killed run resumed with
``resume=True`` ends identical to an uninterrupted one.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from surfgen.filters.descriptor import (
    descriptor,
    descriptor_distances,
    descriptor_from_text,
    descriptor_to_text,
)
from surfgen.filters.verdict import (
    REASONS,
    Verdict,
    judge,
    quick_metrics,
    screen_field,
    shape_metrics,
)
from surfgen.generator import __version__
from surfgen.generator.errors import EmptySurface, SpecError
from surfgen.generator.evaluate import evaluate
from surfgen.generator.expr import Expr
from surfgen.generator.grid import Box, Grid
from surfgen.generator.mesh import Mesh, extract_with_edges, save_mesh
from surfgen.generator.sampler import SAMPLER_VERSION, choose_d, draw_equation
from surfgen.generator.spec import SurfaceSpec
from surfgen.generator.walls import label_walls
from surfgen.pipelines.catalogue import Catalogue, CatalogueError, open_catalogue
from surfgen.pipelines.config import Config
from surfgen.pipelines.curation import ensure_descriptors
from surfgen.pipelines.executor import KillablePool

log = logging.getLogger(__name__)

METRIC_DIGITS = 10  # significant digits kept in stored metrics


@dataclass(frozen=True)
class ShapeOutcome:
    """What a worker hands back for one index: the row to store and the files' bytes."""

    index: int
    row: dict[str, Any]
    verdict: Verdict
    mesh_file: Path | None = None
    thumb_file: Path | None = None
    turntable_file: Path | None = None


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

    @property
    def shapes_per_minute(self) -> float:
        return 60.0 * self.accepted / self.seconds if self.seconds > 0 else 0.0


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
    index: int, *, seed: int, config: Config, staging: Path | None = None, pictures: bool = False
) -> ShapeOutcome:
    """Draw, evaluate, mesh, measure and judge shape ``index``: a pure function of its inputs
    (timings aside). Known failures become a rejected verdict with its reason."""
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
    verdict, metrics, mesh = _judge(tree, spec, d, config, watch)
    row: dict[str, Any] = {
        "key": spec.key,
        "spec": spec.to_json(),
        "formula": spec.formula,
        "identity": spec.identity,
        "d": d,
        "model": json.dumps(equation.to_dict(), sort_keys=True, separators=(",", ":")),
        **_metric_columns(_round_metrics(metrics)),
        "verdict": "accepted" if verdict.accepted else "rejected",
        "reasons": json.dumps(list(verdict.reasons)),
    }
    out = ShapeOutcome(index, row, verdict)
    if verdict.accepted and mesh is not None:
        row["descriptor"] = descriptor_to_text(descriptor(mesh))
        watch.lap("describe")
        if staging is not None:
            out = _with_files(out, mesh, staging, pictures, watch)
    row["timings"] = json.dumps({k: round(v, 4) for k, v in watch.seconds.items()}, sort_keys=True)
    return out


def _judge(
    tree: Expr, spec: SurfaceSpec, d: float | None, config: Config, watch: _Stopwatch
) -> tuple[Verdict, dict[str, Any], Mesh | None]:
    """The cascade: coarse field, full field, mesh, cheap mesh checks, full mesh checks.
    Returns the verdict, the metrics measured so far and the mesh (if one was made)."""
    fcfg, run = config.filters, config.run
    metrics: dict[str, Any] = {}
    if d is None:
        return Verdict.reject("no_crossing"), metrics, None
    box = Box.from_bounds(spec.box)
    coarse = evaluate(tree, Grid(box, (fcfg.coarse_grid,) * 3), threads=1)
    verdict = screen_field(coarse.values, spec.level, fcfg, coarse=True, capped=run.cap)
    watch.lap("eval")
    if not verdict.accepted:
        return verdict, metrics, None
    field_ = evaluate(tree, spec.to_grid(), threads=1)
    metrics["nonfinite"] = field_.nonfinite
    verdict = screen_field(field_.values, spec.level, fcfg, coarse=False)
    watch.lap("eval")
    if not verdict.accepted:
        return verdict, metrics, None
    # Without its walls a capped solid is open on purpose: do not ask it to be watertight.
    capped = run.cap and run.walls != "remove"
    try:
        mesh, edges = extract_with_edges(field_, spec.level, cap=capped)
        if run.walls != "keep":  # the mesh itself depends on the classification
            mesh, crossings = label_walls(
                mesh, edges, field_, tree, {}, spec.level, run.cap, run.walls
            )
            metrics["wall_fraction"] = crossings.wall_fraction
    except EmptySurface:
        return Verdict.reject("empty"), metrics, None
    finally:
        watch.lap("mesh")
    # Cheap checks first (most draws fail them)...
    quick = quick_metrics(mesh, spec.box)
    metrics.update(quick)
    verdict = judge(metrics, fcfg, capped=capped)
    if verdict.accepted and "wall_fraction" not in metrics:
        # ...then the walls (root, pole or jump for every crossing: refines with the formula)
        _, crossings = label_walls(mesh, edges, field_, tree, {}, spec.level, run.cap, "keep")
        metrics["wall_fraction"] = crossings.wall_fraction
        watch.lap("walls")
        verdict = judge(metrics, fcfg, capped=capped)
    if verdict.accepted:  # ...then pymeshlab's topology and the curvature (quick ones reused)
        metrics.update(shape_metrics(mesh, spec.box, quick=quick))
        verdict = judge(metrics, fcfg, capped=capped)
    watch.lap("filters")
    return verdict, metrics, mesh


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
    time it is asked for (:func:`surfgen.pipelines.gallery.ensure_turntable`)."""
    key = out.row["key"]
    mesh_file = save_mesh(mesh, staging / f"{key}.ply")
    watch.lap("io")
    thumb = None
    if pictures:
        from surfgen.pipelines.pictures import THUMBNAIL_SIZE, render_thumbnail

        thumb = render_thumbnail(mesh, staging / f"{key}.thumb.png", size=THUMBNAIL_SIZE)
        watch.lap("pictures")
    return ShapeOutcome(out.index, out.row, out.verdict, mesh_file, thumb)


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
) -> RunSummary:
    """Sample until ``n`` shapes are accepted or ``max_draws`` indices are drawn.

    ``progress(accepted, drawn, n)`` is called after each committed index.
    Raises :class:`SpecError` for bad options and :class:`CatalogueError` when a run with the
    same seed, grid and config exists and ``resume`` is false.
    """
    if n <= 0:
        raise SpecError(f"--n must be at least 1, got {n}")
    workers = os.cpu_count() or 1 if workers is None else workers
    if workers < 1:
        raise SpecError(f"--workers must be at least 1, got {workers}")
    max_draws = max_draws if max_draws is not None else max(1000, 50 * n)
    if max_draws < 1:
        raise SpecError(f"--max-draws must be at least 1, got {max_draws}")
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
        if run is None:
            run = cat.create_run(
                seed, n, config.run.grid, config.to_dict(), config.hash, SAMPLER_VERSION, versions()
            )
        cat.set_run_status(run.id, "running", n=max(n, run.n) if resume else n)
        status = "interrupted"
        try:
            status, stage = _drive(cat, run.id, n, seed, config, workers, max_draws, progress)
        finally:
            cat.set_run_status(run.id, status)
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
    )


def _drive(
    cat: Catalogue,
    run_id: int,
    n: int,
    seed: int,
    config: Config,
    workers: int,
    max_draws: int,
    progress,
) -> tuple[str, dict[str, float]]:
    run = cat.get_run(run_id)
    accepted, next_index = run.accepted, run.next_index
    counts: Counter[str] = Counter(run.counts)
    stage: Counter[str] = Counter()
    if accepted >= n:
        return "complete", {}
    staging = cat.root / ".staging"
    staging.mkdir(exist_ok=True)
    fn = partial(
        make_shape, seed=seed, config=config, staging=staging, pictures=config.run.thumbnails
    )
    buffer: dict[int, Any] = {}
    known = ensure_descriptors(cat)[0] if config.run.dedupe else {}

    def tasks():
        i = next_index
        while i < max_draws and accepted < n:
            yield i
            i += 1

    with KillablePool(fn, workers, config.run.timeout) as pool:
        for result in pool.run(tasks()):
            buffer[result.task] = result
            while next_index in buffer and accepted < n:
                res = buffer.pop(next_index)
                outcome = _outcome(res, seed, config)
                if outcome.verdict.accepted:
                    dup = cat.has_accepted_identity(outcome.row["identity"])
                    if dup is None and config.run.dedupe:
                        dup = _near_duplicate(outcome, known, config.run.dedupe_threshold)
                    if dup is not None:
                        outcome = _rejected(outcome, ("duplicate",))
                        outcome.row["duplicate_of"] = dup
                    elif config.run.dedupe:
                        known[outcome.row["key"]] = descriptor_from_text(outcome.row["descriptor"])
                _commit(cat, run_id, outcome, counts)
                accepted += int(outcome.verdict.accepted)
                for k, v in json.loads(outcome.row.get("timings", "{}")).items():
                    stage[k] += v
                next_index += 1
                if progress is not None:
                    progress(accepted, next_index, n)
            if accepted >= n:
                break
    shutil.rmtree(staging, ignore_errors=True)
    status = "complete" if accepted >= n else "exhausted"
    return status, dict(stage)


def _near_duplicate(
    outcome: ShapeOutcome, known: dict[str, np.ndarray], threshold: float
) -> str | None:
    """The key of the first accepted shape whose descriptor is within ``threshold``, if any."""
    if not known:
        return None
    keys = list(known)
    dist = descriptor_distances(
        descriptor_from_text(outcome.row["descriptor"]), np.stack(list(known.values()))
    )
    j = int(np.argmin(dist))
    return keys[j] if dist[j] < threshold else None


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
        "model": json.dumps(draw.equation.to_dict(), sort_keys=True, separators=(",", ":")),
        "verdict": "rejected",
        "reasons": json.dumps([reason]),
        "metrics": "{}",
        "timings": "{}",
        "error": res.message,
    }
    return ShapeOutcome(res.task, row, Verdict.reject(reason))


def _commit(cat: Catalogue, run_id: int, outcome: ShapeOutcome, counts: Counter) -> None:
    row = dict(outcome.row)
    key = row["key"]
    if outcome.verdict.accepted:
        files = (
            ("mesh_path", cat.meshes / f"{key}.ply", outcome.mesh_file),
            ("thumb_path", cat.thumbs / f"{key}.png", outcome.thumb_file),
            ("turntable_path", cat.turntables / f"{key}.png", outcome.turntable_file),
        )
        for column, path, staged in files:
            if staged is not None:
                os.replace(staged, path)
                row[column] = str(path.relative_to(cat.root))
    else:
        for r in outcome.verdict.reasons:
            counts[r] += 1
    assert all(r in REASONS for r in outcome.verdict.reasons), outcome.verdict.reasons
    cat.record_shape(run_id, outcome.index, row, outcome.verdict.accepted, counts)
