"""``surfgen sweep``: a shape along a range of one of its numbers — the paper's sensitivity as a curve.

:func:`run_sweep` evaluates a base spec with one change (:func:`surfgen.pipelines.studies.knobs.apply_changes`:
a named parameter, ``box`` half-width, ``grid``, ``level``, ``d`` or a literal ``#K``) at each value of
a range and writes to one folder:

- ``meshes/step-NNN.ply`` (one mesh per step; none where the surface left the box),
- ``frames/step-NNN.png`` (256², every frame framed on the union of the steps' boxes, so sizes compare),
- ``contact-sheet.png``, ``sweep.gif`` (the morph, Pillow),
- ``sweep.json``: per step the value, key, faces, components, genus, and the distance to the
  previous step and to the first: ``iou_*`` (intersection over union of the inside samples on one
  comparison grid over the union of the boxes, each field read as the trilinear interpolant of its
  own samples — :func:`surfgen.filters.compare.inside_samples` — so grid and box sweeps compare
  too), ``distance_*`` (symmetric mean distance between points sampled on the two surfaces, box
  units) and ``hausdorff_prev`` (the largest such distance),
- ``distance.png``: those distances along the sweep.
"""

from __future__ import annotations

import io
import json
import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from surfgen.filters.compare import inside_samples, surface_samples
from surfgen.generator.errors import SpecError, SurfgenError
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.sparse import SparseField
from surfgen.generator.files import staged_into, write_atomic
from surfgen.generator.formula.expr import params_of
from surfgen.generator.formula.limits import MemoryBudget, check_memory, estimate_memory
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.exchange import save_mesh
from surfgen.generator.mesh.mesh import Mesh
from surfgen.generator.mesh.realise import realise, resolve_evaluator
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.pictures.raster import _BACKGROUND, contact_sheet, render_image, write_png
from surfgen.pipelines.studies.explore import mesh_stats
from surfgen.pipelines.studies.knobs import apply_changes

log = logging.getLogger(__name__)

MAX_STEPS = 200
COMPARE_POINTS = 64  # comparison grid per axis (at most; never finer than the finest step)
SURFACE_SAMPLES = 4000  # points sampled on each surface for the mesh distance
FRAME_SIZE = 256


_SPEC_CHANGES = ("box", "grid", "level", "d")


class SweepError(SurfgenError):
    """A sweep that cannot run: bad range, unwritable folder..."""


def uses_param(formula: str | None, name: str) -> bool:
    """Whether a pasted formula uses ``name`` as a parameter (then the sweep binds it)."""

    if formula is None or name in _SPEC_CHANGES or not name.isidentifier():
        return False
    try:
        return name in params_of(parse(formula, [name]))
    except SurfgenError:
        return False  # the formula's own error is reported when the spec is built


def parse_range(text: str) -> tuple[str, list[float]]:
    """``NAME=START:STOP:STEP`` → name and values ``START, START+STEP, ...`` up to STOP
    (included when it lands on a step, to 1e-9 of a step). Raises :class:`SweepError`."""
    name, sep, rest = text.partition("=")
    name = name.strip()
    parts = rest.split(":")
    if not sep or not name or len(parts) != 3:
        raise SweepError(f"--param takes NAME=START:STOP:STEP, got '{text}'")
    try:
        start, stop, step = (float(p) for p in parts)
    except ValueError:
        raise SweepError(
            f"--param {name}: START, STOP and STEP must be numbers, got '{rest}'"
        ) from None
    if not all(math.isfinite(v) for v in (start, stop, step)):
        raise SweepError(f"--param {name}: START, STOP and STEP must be finite")
    if step == 0 or (stop - start) * step < 0:
        raise SweepError(f"--param {name}: STEP {step:g} does not lead from {start:g} to {stop:g}")
    count = math.floor((stop - start) / step + 1e-9) + 1
    if count < 2 or count > MAX_STEPS:
        raise SweepError(f"--param {name}: {count} steps; a sweep has 2 to {MAX_STEPS}")
    values = [float(f"{start + i * step:.12g}") for i in range(count)]
    if name == "grid" and any(v != int(v) for v in values):
        raise SweepError("--param grid: the values must be whole numbers")
    return name, values


@dataclass(frozen=True)
class Step:
    """One step of a sweep (a JSON-ready record in ``sweep.json``)."""

    value: float
    spec: SurfaceSpec
    stats: dict[str, Any]
    empty: str | None
    iou_prev: float | None
    distance_prev: float | None
    hausdorff_prev: float | None
    iou_first: float | None
    distance_first: float | None
    mesh: str | None
    frame: str
    seconds: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "value": self.value,
            "key": self.spec.key,
            "formula": self.spec.formula,
            "params": dict(self.spec.params),
            "box": list(self.spec.box),
            "grid": list(self.spec.grid),
            "level": self.spec.level,
            "faces": self.stats["faces"],
            "vertices": self.stats["vertices"],
            "components": self.stats["components"],
            "genus": self.stats["genus"],
            "euler": self.stats["euler"],
            "nonfinite": self.stats.get("nonfinite"),
            "empty": self.empty,
            "iou_prev": self.iou_prev,
            "distance_prev": self.distance_prev,
            "hausdorff_prev": self.hausdorff_prev,
            "iou_first": self.iou_first,
            "distance_first": self.distance_first,
            "mesh": self.mesh,
            "frame": self.frame,
            "seconds": round(self.seconds, 4),
        }


@dataclass(frozen=True)
class SweepResult:
    name: str
    steps: list[Step]
    out: Path
    files: dict[str, str]


def _change(name: str, value: float) -> Any:
    return int(value) if name == "grid" else value


def sweep_specs(base: SurfaceSpec, name: str, values: Sequence[float]) -> list[SurfaceSpec]:
    """The spec of each step. Raises the change set's errors (unknown name, bad value)."""
    # The CLI's own grid limits, not the web explorer's cap: a sweep runs on its own machine.
    return [apply_changes(base, {name: _change(name, v)}, capped=False) for v in values]


def union_box(specs: Sequence[SurfaceSpec]) -> tuple[float, ...]:
    lo = np.min([s.box[0::2] for s in specs], axis=0)
    hi = np.max([s.box[1::2] for s in specs], axis=0)
    return tuple(float(v) for pair in zip(lo, hi, strict=True) for v in pair)


def step_memory(grid: Grid) -> dict[str, int]:
    """The memory one step needs on ``grid``, by part: its field and mesh
    (:func:`~surfgen.generator.formula.limits.estimate_memory`, sparse from where ``auto``
    is), and for a sparse field the dense sign proxy the comparisons read (8 bytes a point)."""
    sparse = resolve_evaluator("auto", grid) == "sparse"
    parts = estimate_memory(grid.size, mesh=True, sparse=sparse)
    if sparse:
        parts["sign proxy"] = 8 * grid.size
    return parts


def _step_name(spec: SurfaceSpec) -> str:
    return f"sweep step on a {'x'.join(map(str, spec.grid))} grid"


def comparison_grid(specs: Sequence[SurfaceSpec]) -> Grid:
    """One grid over the union of the boxes, :data:`COMPARE_POINTS` per axis at most."""
    n = min(COMPARE_POINTS, max(max(s.grid) for s in specs))
    return Grid(Box.from_bounds(union_box(specs)), (n, n, n))


def iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two inside masks (1 when both are empty)."""
    union = np.count_nonzero(a | b)
    return 1.0 if union == 0 else float(np.count_nonzero(a & b) / union)


def points_on(mesh: Mesh | None, n: int = SURFACE_SAMPLES) -> np.ndarray:
    """``n`` area-uniform points on ``mesh`` (seeded), ``(0, 3)`` for no mesh."""

    if mesh is None or mesh.n_faces == 0:
        return np.empty((0, 3))
    return surface_samples(mesh, n, seed=0)


def mesh_distances(a: np.ndarray, b: np.ndarray) -> tuple[float | None, float | None]:
    """Between two surfaces given as point samples: the symmetric mean nearest-neighbour
    distance (the mean of both directions) and the Hausdorff distance (the largest); None when
    one side is empty."""
    from scipy.spatial import cKDTree

    if len(a) == 0 or len(b) == 0:
        return None, None
    ab = cKDTree(b).query(a)[0]
    ba = cKDTree(a).query(b)[0]
    return float(0.5 * (ab.mean() + ba.mean())), float(max(ab.max(), ba.max()))


def _blank_frame(size: int) -> np.ndarray:

    return np.full((size, size, 3), _BACKGROUND, dtype=np.uint8)


def run_sweep(
    base: SurfaceSpec,
    name: str,
    values: Sequence[float],
    out: Path,
    cap: bool = True,
    progress: Callable[[int, int], None] | None = None,
    max_memory: int | None = None,
) -> SweepResult:
    """Evaluate ``base`` with ``{name: value}`` for each value and write the sweep's files to
    ``out`` (see the module docstring). Every step's spec, and the memory its grid needs
    (``max_memory`` bytes; None: the available memory), is checked before anything is
    evaluated or written; a sparse step checks again as it learns the surface's size
    (:class:`~surfgen.generator.formula.limits.MemoryBudget`). Raises the change set's errors,
    ``LimitError`` and :class:`SweepError`."""
    specs = sweep_specs(base, name, values)
    for spec in specs:
        check_memory(step_memory(spec.to_grid()), max_memory, _step_name(spec))
    target = comparison_grid(specs)
    frame_box = union_box(specs)
    out = Path(out)
    try:
        # Every file goes to a folder beside ``out`` first and replaces ``out``'s sweep files
        # at the end, all together: a failure leaves ``out`` as it was.
        with staged_into(out) as work:
            steps, files = _sweep_into(work, base, name, values, specs, target, frame_box, cap,
                                       progress, max_memory)  # fmt: skip
    except OSError as exc:
        raise SweepError(
            f"cannot write the sweep to {out}: {exc.strerror or exc}"
            + (f" ({exc.filename})" if exc.filename else "")
            + "; it was left as it was"
        ) from None
    return SweepResult(name, steps, out, files)


def _sweep_into(
    out: Path,
    base: SurfaceSpec,
    name: str,
    values: Sequence[float],
    specs: list[SurfaceSpec],
    target: Grid,
    frame_box: tuple[float, ...],
    cap: bool,
    progress: Callable[[int, int], None] | None,
    max_memory: int | None = None,
) -> tuple[list[Step], dict[str, str]]:
    """Evaluate every step and write all the sweep's files into the (new) folder ``out``."""

    (out / "meshes").mkdir()
    (out / "frames").mkdir()
    steps: list[Step] = []
    first_inside = first_points = prev_inside = prev_points = None
    for i, (value, spec) in enumerate(zip(values, specs, strict=True)):
        t0 = time.perf_counter()
        budget = MemoryBudget.begin(max_memory, _step_name(spec))
        made = realise(spec, evaluator="auto", cap=cap, allow_empty=True, budget=budget)
        field, mesh, empty = made.field, made.mesh, made.empty
        # the comparisons read the sides of cells (a sparse field's proxy gives the same)
        dense = field.sign_proxy() if isinstance(field, SparseField) else field
        inside = inside_samples(dense, target, spec.level)
        points = points_on(mesh)
        stem = f"step-{i:03d}"
        mesh_rel = None
        frame_rel = f"frames/{stem}.png"
        if mesh is not None:
            mesh_rel = f"meshes/{stem}.ply"
            save_mesh(mesh, out / mesh_rel)
            image = render_image(mesh, size=FRAME_SIZE, bounds=frame_box)
        else:
            image = _blank_frame(FRAME_SIZE)
        write_png(image, out / frame_rel)
        if i == 0:
            first_inside, first_points = inside, points
            prev_inside, prev_points = inside, points
        distance_prev, hausdorff_prev = mesh_distances(prev_points, points)
        steps.append(
            Step(
                value=float(value),
                spec=spec,
                stats=mesh_stats(mesh) | {"nonfinite": field.nonfinite},
                empty=empty,
                iou_prev=None if i == 0 else iou(prev_inside, inside),  # type: ignore[arg-type]
                distance_prev=None if i == 0 else distance_prev,
                hausdorff_prev=None if i == 0 else hausdorff_prev,
                iou_first=iou(first_inside, inside),  # type: ignore[arg-type]
                distance_first=mesh_distances(first_points, points)[0],  # type: ignore[arg-type]
                mesh=mesh_rel,
                frame=frame_rel,
                seconds=time.perf_counter() - t0,
            )
        )
        prev_inside, prev_points = inside, points
        if progress is not None:
            progress(i + 1, len(specs))
    return steps, _write_summary(base, name, steps, out, cap, target)


def _label(name: str, step: Step) -> str:
    faces = step.stats["faces"]
    return (
        f"{name}={step.value:g} · {faces // 1000}k f"
        if faces >= 1000
        else f"{name}={step.value:g} · {faces} f"
    )


def _write_summary(
    base: SurfaceSpec, name: str, steps: list[Step], out: Path, cap: bool, target: Grid
) -> dict[str, str]:
    from PIL import Image, ImageDraw, ImageFont

    files = {}
    sheet = contact_sheet(
        [(out / s.frame, _label(name, s)) for s in steps],
        out / "contact-sheet.png",
        columns=min(len(steps), 6),
    )
    files["contact_sheet"] = sheet.name
    # The GIF: each frame labelled with its value.
    font = ImageFont.load_default(size=14)
    frames = []
    for s in steps:
        with Image.open(out / s.frame) as im:
            frame = im.convert("RGB")
        ImageDraw.Draw(frame).text((8, 6), _label(name, s), fill=(60, 60, 60), font=font)
        frames.append(frame.convert("P", palette=Image.Palette.ADAPTIVE, colors=255))
    buf = io.BytesIO()
    frames[0].save(buf, format="GIF", save_all=True, append_images=frames[1:], duration=600, loop=0)
    write_atomic(out / "sweep.gif", buf.getvalue())
    files["gif"] = "sweep.gif"
    _plot(name, steps, out / "distance.png")
    files["plot"] = "distance.png"
    summary = {
        "param": name,
        "values": [s.value for s in steps],
        "base": base.to_dict(),
        "cap": cap,
        "comparison_grid": {"box": list(target.box.bounds()), "grid": list(target.shape)},
        "surface_samples": SURFACE_SAMPLES,
        "steps": [s.to_dict() for s in steps],
        "files": files,
    }
    write_atomic(out / "sweep.json", json.dumps(summary, indent=1).encode())
    files["json"] = "sweep.json"
    return files


def _plot(name: str, steps: list[Step], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = [s.value for s in steps]

    def series(attr: str, transform: Callable[[float], float] = lambda v: v) -> list[float]:
        return [
            math.nan if getattr(s, attr) is None else transform(getattr(s, attr)) for s in steps
        ]

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 5.2), sharex=True, constrained_layout=True)
    top.plot(x, series("distance_prev"), "o-", color="#2f6f8f", label="to the previous step")
    top.plot(x, series("distance_first"), "s--", color="#b3402e", label="to the first step")
    top.set_ylabel("mesh distance (box units)")
    top.legend(frameon=False)
    top.grid(alpha=0.3)
    bottom.plot(
        x, series("iou_prev", lambda v: 1 - v), "o-", color="#2f6f8f", label="to the previous step"
    )
    bottom.plot(
        x, series("iou_first", lambda v: 1 - v), "s--", color="#b3402e", label="to the first step"
    )
    bottom.set_ylabel("1 − IoU of inside samples")
    bottom.set_xlabel(name)
    bottom.grid(alpha=0.3)
    fig.suptitle(f"sensitivity of the shape to {name}")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    write_atomic(path, buf.getvalue())


__all__ = ["SpecError", "SweepError", "parse_range", "run_sweep", "sweep_specs"]
