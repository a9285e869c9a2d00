"""``surfgen reproduce``: the paper's figures redrawn and its sensitivity claims measured.

:func:`reproduce` writes, into one folder:

- ``figure1.png``: Figure 1.1 (fcc8) and the four panels of Figure 1.2 (:mod:`.plots`);
- ``figure2/``, ``figure3/``, ``figure4/``: every panel (I1, I2; I3, I4, I5; equation C at
  m = 0.25 … 1) at the paper's box and grid (times ``grid_scale``), open as K3DSurf shows it and
  capped, each as a PNG from one fixed camera and as a PLY mesh;
- ``figure2/readings/``: the readings of equation A investigated for Figure 2 (see
  :data:`READINGS`), each with I1 and I2 pictured and compared;
- ``sensitivity.json`` and ``report.html`` (self-contained: pictures inlined): for every pair the
  paper compares, the inside-sample IoU on a common fine grid, the symmetric Hausdorff distance
  relative to the box diagonal, faces, components and genus, and a verdict per claim.

Verdicts. The paper's claims are about *sensitivity*: a small change of a parameter gives a
large change of the shape (Figures 2 and 3: m by 1.2 %, the box by 0.7 %, the grid by 3 %), or a
change of m gives only a small change (Figure 4: m in steps of 0.25). We measure it as an
elasticity, the relative change of the shape over the relative change of the parameter:

    sensitivity = (1 − IoU) / (|a − b| / ((|a| + |b|) / 2))

with the largest relative change among the numbers that differ (parameters, box half-widths,
grid points). Above :data:`SENSITIVITY_HIGH` = 1 the shape changes by a larger fraction than
the parameter did (high sensitivity); below it, by a smaller one (low). Unit elasticity is the
natural divide and needs no tuning. A high sensitivity must also be seen: at least
:data:`MIN_CHANGE` (a tenth) of the solid must change, else a 1 % parameter change that moves a
few boundary voxels would count as "significantly different"; the IoU, the Hausdorff distance (relative to the box
diagonal), faces, components and genus are reported beside it, and ``floor_iou`` gives, per
panel, the IoU of the shape with itself sampled on a grid shifted by half a cell (what sampling
alone changes).
"""

from __future__ import annotations

import base64
import html
import json
import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from surfgen.filters.compare import hausdorff, inside_iou
from surfgen.filters.metrics import measure_mesh
from surfgen.generator.errors import SpecError
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Field, Grid
from surfgen.generator.files import staged_into, write_all_atomic
from surfgen.generator.mesh.exchange import save_mesh
from surfgen.generator.mesh.mesh import Mesh
from surfgen.generator.mesh.realise import realise
from surfgen.generator.model.presets import eq_a_formula, get_preset
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.pictures.plots import plot_constituents
from surfgen.pipelines.pictures.raster import render_image, write_png

log = logging.getLogger(__name__)

FIGURES = (1, 2, 3, 4)
PANELS: dict[int, tuple[str, ...]] = {
    2: ("I1", "I2"),
    3: ("I3", "I4", "I5"),
    4: ("C-m0.25", "C-m0.5", "C-m0.75", "C-m1"),
}
SENSITIVITY_HIGH = 1.0
MIN_CHANGE = 0.1  # 1 - IoU: the least change of the solid that counts as significant
PICTURE_SIZE = 384
VIEW = {"azimuth": 30.0, "elevation": 25.0}  # one camera for every picture
MIN_GRID = 8
FINE_GRID_MAX = 160
HAUSDORFF_SAMPLES = 20000


@dataclass(frozen=True)
class Claim:
    """A statement of the paper about a pair of panels."""

    figure: int
    a: str
    b: str
    expect: str  # "high" or "low" sensitivity
    quote: str


_DIFFERENT_B = "The shapes I3, I4 and I5, are significantly different."
CLAIMS: tuple[Claim, ...] = (
    Claim(2, "I1", "I2", "high", "both shapes are significantly different"),
    Claim(3, "I3", "I4", "high", _DIFFERENT_B),
    Claim(3, "I3", "I5", "high", _DIFFERENT_B),
    Claim(3, "I4", "I5", "high", _DIFFERENT_B),
    *(
        Claim(4, a, b, "low", "a small change will produce a small change in the 3D shape")
        for a, b in (("C-m0.25", "C-m0.5"), ("C-m0.5", "C-m0.75"), ("C-m0.75", "C-m1"))
    ),
)


# ----------------------------------------------------------------------------- readings of eq. A


@dataclass(frozen=True)
class Reading:
    """One way to read equation A as printed, to be tested against Figure 2's claim."""

    name: str
    text: str
    formula: str
    half: float = 155.0
    points: int = 82
    float32: bool = False


READINGS: tuple[Reading, ...] = (
    Reading("literal", "as printed, evaluated in double precision", eq_a_formula()),
    Reading(
        "float32",
        "as printed, evaluated in single precision (K3DSurf-era float arithmetic)",
        eq_a_formula(),
        float32=True,
    ),
    Reading(
        "intervals",
        "Grid [82,82,82] read as 82 intervals (83 points per axis) instead of 82 points",
        eq_a_formula(),
        points=83,
    ),
    Reading(
        "degrees",
        "m·x in degrees: cot(m x π/180)",
        eq_a_formula(b_form="(abs({v})^0.3/abs(cot(m*{v}*pi/180)))^0.3"),
    ),
    Reading(
        "split-exponent",
        "B = |x|^0.3 / |cot(m x)|^0.3: the outer 0.3 applied to each part",
        eq_a_formula(b_form="abs({v})^0.3/abs(cot(m*{v}))^0.3"),
    ),
    Reading(
        "b-no-outer",
        "B = |x|^0.3 / |cot(m x)|: the outer exponent 0.3 dropped",
        get_preset("I1-b1").formula,
    ),
    Reading(
        "b-outer-3",
        "B = (|x|^0.3 / |cot(m x)|)^3: the outer 0.3 read as 3",
        eq_a_formula(b_form="(abs({v})^0.3/abs(cot(m*{v})))^3"),
    ),
    Reading(
        "no-constants",
        "without the −600 and the +100",
        eq_a_formula(shift_in="", shift_out=""),
    ),
    Reading("plus-0.51", "+0.51 instead of −0.51 before the B terms", eq_a_formula(sign="+")),
    Reading("box-15.5", "the box ±15.5 (a tenth: another unit)", eq_a_formula(), half=15.5),
)


# ----------------------------------------------------------------------------- results


@dataclass(frozen=True)
class Shape:
    """One rendered panel: its field and meshes (None where the surface is empty)."""

    name: str
    spec: SurfaceSpec
    field: Field
    mesh: Mesh | None
    capped: Mesh | None
    files: dict[str, str] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "name": self.name,
            "formula": self.spec.formula,
            "params": dict(self.spec.params),
            "box": list(self.spec.box),
            "grid": list(self.spec.grid),
            "nonfinite": self.field.nonfinite,
            "inside_fraction": _inside_fraction(self.field),
            "files": dict(self.files),
        }
        out.update(_mesh_summary(self.capped))
        out["open_faces"] = None if self.mesh is None else self.mesh.n_faces
        return out


@dataclass(frozen=True)
class ReproduceResult:
    folder: Path
    sensitivity: dict[str, Any]
    seconds: float


# ----------------------------------------------------------------------------- the command


def reproduce(
    out: Path,
    *,
    grid_scale: float = 1.0,
    figures: Sequence[int] = FIGURES,
    progress: Callable[[str], None] | None = None,
) -> ReproduceResult:
    """Redraw ``figures`` of the paper into ``out`` and measure its sensitivity claims.

    Raises :class:`SpecError` for an unknown figure or a ``grid_scale`` outside (0, 4].
    """
    figures = _check_figures(figures)
    if not (isinstance(grid_scale, (int, float)) and 0.0 < grid_scale <= 4.0):
        raise SpecError(f"--grid-scale must be a number in (0, 4], got {grid_scale}")
    out = Path(out)
    # Everything is drawn in a folder beside ``out`` and moved in at the end, all together:
    # figures of an earlier run that this one does not redraw are kept, and a failure (a
    # full disk half-way) leaves ``out`` as it was.
    try:
        with staged_into(out) as work:
            sensitivity, seconds = _reproduce_into(work, figures, grid_scale, progress)
    except OSError as exc:
        raise SpecError(
            f"cannot write to {out}: {exc.strerror or exc}"
            + (f" ({exc.filename})" if exc.filename else "")
            + "; it was left as it was"
        ) from None
    log.info("reproduced figures %s in %.1f s", list(figures), seconds)
    return ReproduceResult(out, sensitivity, seconds)


def _reproduce_into(
    out: Path,
    figures: tuple[int, ...],
    grid_scale: float,
    progress: Callable[[str], None] | None,
) -> tuple[dict[str, Any], float]:
    """Draw ``figures`` and write every file of :func:`reproduce` into the folder ``out``."""
    say = progress or (lambda _msg: None)
    start = time.perf_counter()

    if 1 in figures:
        say("figure 1: constituent functions")
        plot_constituents(out / "figure1.png")
    shapes: dict[str, Shape] = {}
    for fig in (f for f in figures if f in PANELS):
        for name in PANELS[fig]:
            say(f"figure {fig}: {name}")
            shapes[name] = _render_panel(out / f"figure{fig}", name, grid_scale)
    pairs = [
        _compare(c, shapes[c.a], shapes[c.b], grid_scale) for c in CLAIMS if c.figure in figures
    ]
    readings = []
    if 2 in figures:
        for reading in READINGS:
            say(f"figure 2 reading: {reading.name}")
            readings.append(_investigate(out / "figure2" / "readings", reading, grid_scale))
    seconds = time.perf_counter() - start
    sensitivity = {
        "grid_scale": grid_scale,
        "figures": list(figures),
        "sensitivity_high": SENSITIVITY_HIGH,
        "min_change": MIN_CHANGE,
        "shapes": {name: s.summary() for name, s in shapes.items()},
        "pairs": pairs,
        "figure2_readings": readings,
        "seconds": round(seconds, 1),
    }
    write_all_atomic(
        [
            (out / "sensitivity.json", (json.dumps(sensitivity, indent=2) + "\n").encode()),
            (out / "report.html", _report_html(out, sensitivity).encode()),
        ]
    )
    return sensitivity, seconds


def _check_figures(figures: Sequence[int]) -> tuple[int, ...]:
    chosen = tuple(sorted(set(int(f) for f in figures)))
    bad = [f for f in chosen if f not in FIGURES]
    if bad or not chosen:
        raise SpecError(
            f"unknown figure {bad[0] if bad else 'none'} (figures: {', '.join(map(str, FIGURES))})"
        )
    return chosen


def scaled_grid(points: int, grid_scale: float) -> int:
    """The grid size ``points`` times ``grid_scale``, at least :data:`MIN_GRID`."""
    return max(MIN_GRID, round(points * grid_scale))


def _render_panel(folder: Path, name: str, grid_scale: float) -> Shape:
    preset = get_preset(name)
    spec = preset.spec()
    spec = spec.replace(grid=tuple(scaled_grid(n, grid_scale) for n in spec.grid))
    field_ = evaluate(spec.tree(), spec.to_grid(), spec.params)
    return _draw_shape(folder, name, spec, field_)


def _draw_shape(folder: Path, name: str, spec: SurfaceSpec, field_: Field) -> Shape:

    folder.mkdir(parents=True, exist_ok=True)
    meshes: dict[str, Mesh | None] = {}
    files: dict[str, str] = {}
    for suffix, cap in (("", False), ("-capped", True)):
        mesh = realise(spec, field=field_, cap=cap, allow_empty=True).mesh
        meshes[suffix] = mesh
        if mesh is None or mesh.n_faces == 0:
            continue
        save_mesh(mesh, folder / f"{name}{suffix}.ply")
        write_png(render_image(mesh, size=PICTURE_SIZE, **VIEW), folder / f"{name}{suffix}.png")
        files[f"mesh{suffix}"] = str((folder / f"{name}{suffix}.ply").name)
        files[f"png{suffix}"] = str((folder / f"{name}{suffix}.png").name)
    return Shape(name, spec, field_, meshes[""], meshes["-capped"], files)


def _compare(claim: Claim, a: Shape, b: Shape, grid_scale: float) -> dict[str, Any]:

    fine = min(FINE_GRID_MAX, scaled_grid(2 * max(*a.spec.grid, *b.spec.grid), grid_scale))
    iou = inside_iou(a.field, b.field, fine, a.spec.level)
    diag = _diagonal(a.field.grid.box, b.field.grid.box)
    if a.capped is None or b.capped is None:
        rel_h = None if a.capped is b.capped else 1.0  # one empty, one not: as far as can be
    else:
        rel_h = hausdorff(a.capped, b.capped, HAUSDORFF_SAMPLES) / diag
    change = relative_change(a.spec, b.spec)
    sensitivity = (1.0 - iou) / change if change > 0 else 0.0
    seen = 1.0 - iou >= MIN_CHANGE
    found = "high" if sensitivity > SENSITIVITY_HIGH and seen else "low"
    return {
        "figure": claim.figure,
        "a": claim.a,
        "b": claim.b,
        "paper": claim.expect,
        "quote": claim.quote,
        "iou": round(iou, 4),
        "relative_change": round(change, 5),
        "sensitivity": round(sensitivity, 3),
        "hausdorff_rel": None if rel_h is None else round(rel_h, 4),
        "fine_grid": fine,
        "faces": [_faces(a.capped), _faces(b.capped)],
        "components": [
            _mesh_summary(a.capped)["components"],
            _mesh_summary(b.capped)["components"],
        ],
        "genus": [_mesh_summary(a.capped)["genus"], _mesh_summary(b.capped)["genus"]],
        "floor_iou": [_floor_iou(a, fine), _floor_iou(b, fine)],
        "found": found,
        "verdict": "reproduced" if found == claim.expect else "not reproduced",
    }


def relative_change(a: SurfaceSpec, b: SurfaceSpec) -> float:
    """The largest relative change ``|p - q| / mean(|p|, |q|)`` among the parameters, box
    bounds and grid sizes of two specs (0 when they are the same)."""
    pairs = [(a.params.get(k, 0.0), b.params.get(k, 0.0)) for k in set(a.params) | set(b.params)]
    pairs += list(zip(a.box, b.box, strict=True)) + list(zip(a.grid, b.grid, strict=True))
    changes = [abs(p - q) / ((abs(p) + abs(q)) / 2) for p, q in pairs if p != q]
    return max(changes, default=0.0)


def _floor_iou(shape: Shape, fine: int) -> float:
    """IoU of ``shape`` with itself sampled on its grid shifted by half a cell: what sampling
    alone changes (near 1 for a smooth shape; low where the paper's poles and jumps rule)."""

    grid = shape.field.grid
    half = [0.5 * s for s in grid.spacing]
    box = Box(
        tuple(lo + h for lo, h in zip(grid.box.lo, half, strict=True)),
        tuple(hi + h for hi, h in zip(grid.box.hi, half, strict=True)),
    )
    shifted = evaluate(shape.spec.tree(), Grid(box, grid.shape), shape.spec.params)
    return round(inside_iou(shape.field, shifted, fine, shape.spec.level), 4)


def _investigate(folder: Path, reading: Reading, grid_scale: float) -> dict[str, Any]:
    shapes = []
    for name, m in (("I1", 0.851), ("I2", 0.861)):
        spec = SurfaceSpec(
            formula=reading.formula,
            box=(-reading.half, reading.half) * 3,
            grid=(scaled_grid(reading.points, grid_scale),) * 3,
            params={"m": m},
            provenance={"reading": reading.name},
        )
        if reading.float32:
            values = eq_a_float32(m, spec.to_grid())
            field_ = Field(spec.to_grid(), values)
        else:
            field_ = evaluate(spec.tree(), spec.to_grid(), spec.params)
        shapes.append(_draw_shape(folder / reading.name, name, spec, field_))
    claim = CLAIMS[0]
    pair = _compare(claim, shapes[0], shapes[1], grid_scale)
    return {
        "reading": reading.name,
        "text": reading.text,
        "formula": reading.formula,
        "box": reading.half,
        "grid": shapes[0].spec.grid[0],
        "float32": reading.float32,
        "I1": shapes[0].summary(),
        "I2": shapes[1].summary(),
        **{
            k: pair[k]
            for k in ("iou", "sensitivity", "hausdorff_rel", "found", "verdict", "floor_iou")
        },
    }


def eq_a_float32(m: float, grid: Grid) -> np.ndarray:
    """Equation A as printed, every operation in float32 (single precision); float64 result."""
    f4 = np.float32
    x, y, z = (a.astype(f4) for a in grid.open_axes())
    ax, ay, az = np.abs(x), np.abs(y), np.abs(z)
    with np.errstate(all="ignore"):
        denom = np.abs(ax ** f4(1.3) + ay ** f4(1.3) + az ** f4(1.3))

        def a_term(u: np.ndarray) -> np.ndarray:
            inner = f4(1) - u ** f4(0.31) + f4(5.76) * u ** f4(1.38) / denom
            return np.arctan(np.tan(inner)) ** f4(3)

        def b_term(v: np.ndarray, u: np.ndarray) -> np.ndarray:
            return (u ** f4(0.3) / np.abs(f4(1) / np.tan(f4(m) * v))) ** f4(0.3)

        envelope = ax ** f4(3.3) + ay ** f4(3.3) + az ** f4(3.3) - f4(600)
        ornament = (a_term(ax) + a_term(ay) + a_term(az)) ** f4(3)
        poles = (b_term(x, ax) + b_term(y, ay) + b_term(z, az)) ** f4(3)
        values = envelope + ornament - f4(0.51) * poles + f4(100)
    return np.broadcast_to(values, grid.shape).astype(np.float64)


# ----------------------------------------------------------------------------- helpers


def _inside_fraction(field_: Field) -> float:
    v = field_.values
    return round(float(np.count_nonzero(np.isfinite(v) & (v < 0.0))) / v.size, 6)


def _faces(mesh: Mesh | None) -> int:
    return 0 if mesh is None else mesh.n_faces


def _mesh_summary(mesh: Mesh | None) -> dict[str, Any]:

    if mesh is None or mesh.n_faces == 0:
        return {"faces": 0, "components": 0, "genus": None}
    m = measure_mesh(mesh)
    return {"faces": m.faces, "components": m.components, "genus": m.genus}


def _diagonal(a: Box, b: Box) -> float:
    lo = np.minimum(a.lo, b.lo)
    hi = np.maximum(a.hi, b.hi)
    return float(math.sqrt(float(((hi - lo) ** 2).sum())))


# ----------------------------------------------------------------------------- the report


def _img(path: Path, width: int = 220) -> str:
    if not path.exists():
        return '<div class="empty">empty</div>'
    data = base64.b64encode(path.read_bytes()).decode()
    return (
        f'<img src="data:image/png;base64,{data}" width="{width}" alt="{html.escape(path.stem)}">'
    )


def _fmt(v: Any) -> str:
    return "—" if v is None else html.escape(str(v))


def _report_html(out: Path, s: dict[str, Any]) -> str:
    e = html.escape
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>surfgen reproduce</title>",
        "<style>body{font:14px system-ui,sans-serif;margin:2em;max-width:1200px}"
        "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:4px 8px}"
        ".ok{color:#1b7a3a;font-weight:600}.no{color:#b3402e;font-weight:600}"
        "figure{display:inline-block;margin:4px;text-align:center}.empty{width:220px;height:60px;"
        "background:#eee;line-height:60px}</style></head><body>",
        "<h1>The paper, reproduced</h1>",
        f"<p>grid scale {s['grid_scale']}, {s['seconds']} s. Sensitivity = (1 − IoU) / the "
        "relative change of the parameter; <i>high</i> above "
        f"{SENSITIVITY_HIGH} (the shape changes by a larger fraction than the parameter), "
        f"<i>low</i> below, or when less than {MIN_CHANGE:.0%} of the solid changes.</p>",
    ]
    if (out / "figure1.png").exists():
        parts.append("<h2>Figure 1</h2>" + _img(out / "figure1.png", 700))
    for fig, names in PANELS.items():
        if fig not in s["figures"]:
            continue
        parts.append(f"<h2>Figure {fig}</h2>")
        for name in names:
            for suffix, label in (("", "open"), ("-capped", "capped")):
                parts.append(
                    f"<figure>{_img(out / f'figure{fig}' / f'{name}{suffix}.png')}"
                    f"<figcaption>{e(name)} ({label})</figcaption></figure>"
                )
    parts.append(
        "<h2>Sensitivity claims</h2><table><tr><th>figure</th><th>pair</th>"
        "<th>paper</th><th>IoU</th><th>Δp/p</th><th>sensitivity</th><th>Hausdorff / diag</th><th>faces</th>"
        "<th>components</th><th>genus</th><th>half-cell floor IoU</th><th>verdict</th></tr>"
    )
    for p in s["pairs"]:
        cls = "ok" if p["verdict"] == "reproduced" else "no"
        parts.append(
            f"<tr><td>{p['figure']}</td><td>{e(p['a'])} / {e(p['b'])}</td><td>{e(p['paper'])}</td>"
            f"<td>{p['iou']}</td><td>{p['relative_change']}</td><td>{p['sensitivity']}</td>"
            f"<td>{_fmt(p['hausdorff_rel'])}</td><td>{_fmt(p['faces'])}</td>"
            f"<td>{_fmt(p['components'])}</td><td>{_fmt(p['genus'])}</td>"
            f"<td>{_fmt(p['floor_iou'])}</td><td class='{cls}'>{e(p['verdict'])}</td></tr>"
        )
    parts.append("</table>")
    if s["figure2_readings"]:
        parts.append(
            "<h2>Figure 2: readings of equation A</h2><table><tr><th>reading</th>"
            "<th>what</th><th>I1</th><th>I2</th><th>IoU</th><th>Hausdorff / diag</th>"
            "<th>faces</th><th>I1 ≠ I2?</th></tr>"
        )
        for r in s["figure2_readings"]:
            folder = out / "figure2" / "readings" / r["reading"]
            cls = "ok" if r["verdict"] == "reproduced" else "no"
            parts.append(
                f"<tr><td>{e(r['reading'])}</td><td>{e(r['text'])}</td>"
                f"<td>{_img(folder / 'I1-capped.png', 160)}</td>"
                f"<td>{_img(folder / 'I2-capped.png', 160)}</td><td>{r['iou']}</td>"
                f"<td>{r['sensitivity']}</td><td>{_fmt(r['hausdorff_rel'])}</td>"
                f"<td>{r['I1']['faces']} / {r['I2']['faces']}</td>"
                f"<td class='{cls}'>{e(r['found'])}</td></tr>"
            )
        parts.append("</table>")
    parts.append("</body></html>\n")
    return "\n".join(parts)
