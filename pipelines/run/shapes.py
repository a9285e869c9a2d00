"""One shape of a sampling run: draw, evaluate, mesh, judge, describe and stage its files.

Shape ``i`` is a pure function of ``(seed, i, config)`` (:func:`make_shape`), computed in a worker
process; :mod:`surfgen.pipelines.run.sampling` drives the workers and commits the outcomes.
The cascade (:func:`_judge`) turns every known failure into a rejected verdict with its reason.
"""

from __future__ import annotations

import json
import logging
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from surfgen.filters.descriptor import (
    descriptor,
    descriptor_from_text,
    descriptor_to_text,
)
from surfgen.filters.resolution import measure_resolution
from surfgen.filters.shape import quality_metrics, solidity
from surfgen.filters.verdict import (
    ACCEPT,
    Verdict,
    judge,
    judged_by_outline,
    plain,
    quick_metrics,
    screen_field,
    shape_metrics,
)
from surfgen.generator.errors import EmptySurface
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.files import write_atomic
from surfgen.generator.formula.expr import Expr, substitute_params
from surfgen.generator.mesh.exchange import encode_mesh
from surfgen.generator.mesh.mesh import Mesh, extract_with_edges, face_areas
from surfgen.generator.mesh.outline import outline_fill
from surfgen.generator.mesh.walls import label_walls
from surfgen.generator.model.draw import Draw
from surfgen.generator.model.families import get_family
from surfgen.generator.model.families.carving import envelope_departure
from surfgen.generator.model.sampler import draw_spec
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.pictures.raster import THUMBNAIL_SIZE, render_thumbnail
from surfgen.pipelines.run.config import Config
from surfgen.pipelines.run.duplicates import AcceptedDescriptors

log = logging.getLogger(__name__)

METRIC_DIGITS = 10  # significant digits kept in stored metrics

#: A later stage of the cascade (:func:`_judge`): runs its checks, returns the verdict.
Later = Callable[[], Verdict]


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


def _round_metrics(m: dict[str, Any]) -> dict[str, Any]:
    out = {}
    for k, v in sorted(m.items()):
        if isinstance(v, float):
            v = float(f"{v:.{METRIC_DIGITS - 1}e}") if np.isfinite(v) else None
        elif isinstance(v, list | tuple):
            v = [float(f"{x:.{METRIC_DIGITS - 1}e}") if isinstance(x, float) else x for x in v]
        out[k] = v
    return out


class Stopwatch:
    """Seconds spent per stage (``eval``, ``mesh``, ``walls``, ``resolution``, ``filters``,
    ``describe``, ``io``, ``pictures``)."""

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

    With near-duplicate rejection on, a mesh that passes every check of the mesh itself is
    described there, before the costly check on the finer grid, and the outcome carries that
    point's row (``early_row``): the parent rejects the shape as a duplicate with that row if
    an accepted shape is near it (:func:`~surfgen.pipelines.run.sampling._drive`), so that
    verdict does not depend on the later check. ``duplicates`` (a worker's view of the shapes
    already accepted) lets the worker stop there when it already knows; the row is the same."""
    watch = Stopwatch()
    # one process per core: numba serial inside
    draw, d, spec = draw_spec(seed, index, config.sampler, config.run.grid, config.hash, threads=1)
    equation = draw.equation.with_d(d or 0.0)
    tree = equation.to_tree()
    watch.lap("eval")
    verdict, metrics, mesh, (mesh_checks, fine_checks) = _judge(tree, spec, d, config, watch, draw)

    def row_for(verdict: Verdict) -> dict[str, Any]:
        return {
            "key": spec.key,
            "spec": spec.to_json(),
            "formula": spec.formula,
            "identity": spec.identity,
            "d": d,
            "model": model_json(draw, equation),
            **_metric_columns(_round_metrics(metrics)),
            "verdict": "accepted" if verdict.accepted else "rejected",
            "reasons": json.dumps(list(verdict.reasons)),
        }

    if verdict.accepted:
        verdict = mesh_checks()
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
        verdict = fine_checks()
    row = row_for(verdict)
    out = ShapeOutcome(index, row, verdict, early_row=early)
    if verdict.accepted and mesh is not None:
        row["descriptor"] = described or descriptor_to_text(descriptor(mesh))
        watch.lap("describe")
        if staging is not None:
            try:
                out = _with_files(out, mesh, staging, pictures, watch)
            except OSError as exc:  # not a verdict on the shape: the run must stop
                return ShapeOutcome(index, row, verdict, write_error=write_error(exc, staging))
    row["timings"] = _timings(watch)
    if early is not None:
        early["timings"] = row["timings"]
    return out


DUPLICATE = Verdict.reject("duplicate")


def judge_spec(
    spec: SurfaceSpec, config: Config, draw: Draw | None = None, d: float | None = 0.0
) -> tuple[Verdict, dict[str, Any], Mesh | None]:
    """The sampler's verdict on one spec: the cascade of :func:`make_shape` (without the
    near-duplicate check, which needs the run), with ``config``'s filters, cap and walls.

    ``draw``: the draw the spec came from (a sculpture's envelope is measured against it);
    ``d``: its d (None: no d made a surface, rejected as ``no_crossing``). Returns the verdict,
    the metrics measured on the way (rounded as the catalogue stores them: all of them for an
    accepted shape) and the mesh (None when the checks stopped before meshing). Raises what
    evaluation raises for a spec that cannot be evaluated.
    """
    tree = substitute_params(spec.tree(), spec.params)  # the cascade evaluates without params
    verdict, metrics, mesh, (mesh_checks, fine_checks) = _judge(
        tree, spec, d, config, Stopwatch(), draw
    )
    if verdict.accepted:
        verdict = mesh_checks()
    if verdict.accepted:
        verdict = fine_checks()
    return verdict, _round_metrics(metrics), mesh


def _timings(watch: Stopwatch) -> str:
    return json.dumps({k: round(v, 4) for k, v in watch.seconds.items()}, sort_keys=True)


def model_json(draw: Draw, equation) -> str:
    return json.dumps(draw.model_dict(equation), sort_keys=True, separators=(",", ":"))


def _judge(
    tree: Expr,
    spec: SurfaceSpec,
    d: float | None,
    config: Config,
    watch: Stopwatch,
    draw: Draw | None = None,
) -> tuple[Verdict, dict[str, Any], Mesh | None, tuple[Later, Later]]:
    """The cascade: coarse field, full field (and how far it departs from the draw's envelope,
    if any), mesh, cheap mesh checks; then, when called, ``mesh_checks()``: the walls, the full
    mesh checks, the solidity and the outline (plain lumps); then ``fine_checks()``: the
    resolution check (the nested grid twice as fine) and the shape-quality metrics of an
    accepted mesh. Returns the cheap checks' verdict, the metrics (the later checks add to
    them), the mesh (if made) and ``(mesh_checks, fine_checks)``, to be called in that order
    while the verdict accepts."""
    fcfg, run = config.filters, config.run
    metrics: dict[str, Any] = {}
    one_body = draw is not None and get_family(draw.family).one_body
    porous = draw is None or get_family(draw.family).porous
    by_outline = draw is not None and get_family(draw.family).outline

    def stop(verdict: Verdict, mesh: Mesh | None = None):
        return verdict, metrics, mesh, (lambda: verdict, lambda: verdict)

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

    def judged() -> Verdict:  # the verdict on the metrics measured so far
        return judge(metrics, fcfg, capped=capped, one_body=one_body, porous=porous)

    try:
        mesh, edges = extract_with_edges(field_, spec.level, cap=capped)
        extracted = mesh  # before the walls: the resolution check compares like with like
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
    verdict = judged()
    watch.lap("filters")

    def mesh_checks() -> Verdict:
        verdict = ACCEPT
        if "wall_fraction" not in metrics:
            # ...then the walls (root, pole or jump for every crossing: refines with the formula)
            _, crossings = label_walls(
                mesh, edges, field_, tree, {}, spec.level, run.cap, "keep", areas
            )
            metrics["wall_fraction"] = crossings.wall_fraction
            watch.lap("walls")
            verdict = judged()
        if verdict.accepted:  # ...then pymeshlab's topology and the curvature (quick reused)
            metrics.update(shape_metrics(mesh, spec.box, quick=quick))
            verdict = judged()
        if verdict.accepted:  # ...then how much of its convex hull it fills (plain blobs)
            metrics["solidity"] = solidity(mesh, metrics.get("volume"))
            verdict = judged()
        if verdict.accepted and by_outline and judged_by_outline(metrics, fcfg):
            # ...then its outline, for a lump whose every view is convex (plain)
            metrics["outline"] = outline_fill(mesh)
            verdict = judged()
        watch.lap("filters")
        return verdict

    def fine_checks() -> Verdict:
        verdict = ACCEPT
        if fcfg.check_resolution:
            # ...then the surface on the nested grid twice as fine (the costliest check: last,
            # so the blobs and plain shapes, a quarter of the candidates, do not pay for it)
            resolution = measure_resolution(
                tree, field_, extracted, spec.level, cap=capped, band=fcfg.resolution_band
            )
            metrics.update(resolution.to_metrics())
            watch.lap("resolution")
            verdict = judged()
        if verdict.accepted:
            metrics.update(quality_metrics(mesh, metrics))
        watch.lap("filters")
        return verdict

    return verdict, metrics, mesh, (mesh_checks, fine_checks)


def _metric_columns(m: dict[str, Any]) -> dict[str, Any]:
    cols = {
        k: m.get(k) for k in ("faces", "vertices", "components", "genus", "euler", "area", "volume")
    }
    cols["metrics"] = json.dumps(m, sort_keys=True, separators=(",", ":"))
    return cols


def _with_files(
    out: ShapeOutcome, mesh: Mesh, staging: Path, pictures: bool, watch: Stopwatch
) -> ShapeOutcome:
    """Write the accepted shape's files into the run's staging folder; the parent moves them
    into the catalogue when it commits the row (so a discarded index leaves nothing behind).

    Only the thumbnail is rendered here (contact sheets and the gallery grid show every one);
    the 12-view turntable, which most shapes never get hovered for, is rendered the first
    time it is asked for (:func:`surfgen.pipelines.pictures.thumbnails.ensure_turntable`)."""
    key = out.row["key"]
    mesh_file = write_atomic(staging / f"{key}.ply", encode_mesh(mesh, "ply"))
    watch.lap("io")
    thumb = None
    if pictures:
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


def write_error(exc: OSError, staging: Path) -> str:
    return f"{exc.filename or staging}: {exc.strerror}"
