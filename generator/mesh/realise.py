"""A spec made into a mesh in one call: evaluate → extract → walls → caps.

:func:`realise` is the one path from a :class:`~surfgen.generator.model.spec.SurfaceSpec` to its
mesh for every command that shows, writes or re-makes a shape (render, export, explore, sweep,
reproduce, MathMod models, catalogue repair).  The sampler's cascade, which screens a coarse
field before the full one and classifies the walls only for the shapes that pass its cheap
checks, calls the same steps (:func:`~surfgen.generator.mesh.mesh.extract_with_edges`,
:func:`~surfgen.generator.mesh.walls.label_walls`) in its own order.
"""

from __future__ import annotations

import dataclasses
import time

from surfgen.generator.errors import EmptySurface
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Field, Grid
from surfgen.generator.mesh.mesh import Mesh, extract_mesh
from surfgen.generator.mesh.walls import WallReport, check_walls_mode, extract_labelled
from surfgen.generator.model.spec import SurfaceSpec


@dataclasses.dataclass(frozen=True)
class Realised:
    """What :func:`realise` made: the field, the mesh (None when the surface is empty and that
    was allowed: ``empty`` says why), the walls' report (None when the crossings were not
    classified), and the seconds spent evaluating and meshing."""

    spec: SurfaceSpec
    field: Field
    mesh: Mesh | None
    walls: WallReport | None = None
    empty: str | None = None
    seconds: dict[str, float] = dataclasses.field(default_factory=dict)


def realise(
    spec: SurfaceSpec,
    *,
    grid: Grid | None = None,
    field: Field | None = None,
    evaluator: str = "fast",
    threads: int | None = None,
    cap: bool = False,
    walls: str | None = None,
    allow_empty: bool = False,
) -> Realised:
    """Evaluate ``spec`` and extract ``F = spec.level`` (with box caps when ``cap``).

    ``grid``: evaluate there instead of ``spec.to_grid()`` (a re-gridded export); ``field``: an
    already evaluated field of ``spec`` (nothing is evaluated); ``evaluator``/``threads``: as
    :func:`~surfgen.generator.eval.evaluate.evaluate`. ``walls``: None extracts without
    classifying the crossings (:func:`~surfgen.generator.mesh.mesh.extract_mesh`); ``keep``,
    ``mark`` or ``remove`` classifies them and keeps, labels or removes the walls
    (:func:`~surfgen.generator.mesh.walls.extract_labelled`). ``allow_empty``: an empty surface
    gives ``mesh=None`` and its message in ``empty`` instead of raising.

    Raises :class:`EmptySurface` (unless ``allow_empty``), ``SpecError`` for an unknown walls
    mode, and what evaluation raises (``FormulaError``, ``LimitError``...).
    """
    if walls is not None:
        check_walls_mode(walls)
    t0 = time.perf_counter()
    tree = spec.tree()
    if field is None:
        grid = spec.to_grid() if grid is None else grid
        field = evaluate(tree, grid, spec.params, evaluator=evaluator, threads=threads)
    t1 = time.perf_counter()
    mesh: Mesh | None = None
    report: WallReport | None = None
    empty: str | None = None
    try:
        if walls is None:
            mesh = extract_mesh(field, spec.level, cap=cap)
        else:
            mesh, report = extract_labelled(field, tree, spec.params, spec.level, cap, walls)
    except EmptySurface as exc:
        if not allow_empty:
            raise
        empty = str(exc)
    t2 = time.perf_counter()
    seconds = {"evaluate": t1 - t0, "mesh": t2 - t1}
    return Realised(spec, field, mesh, report, empty, seconds)
