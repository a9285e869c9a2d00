"""A spec made into a mesh in one call: evaluate → extract → walls → caps.

:func:`realise` is the one path from a :class:`~surfgen.generator.model.spec.SurfaceSpec` to its
mesh for every command that shows, writes or re-makes a shape (render, export, explore, sweep,
reproduce, MathMod models, catalogue repair).  The sampler's cascade, which screens a coarse
field before the full one and classifies the walls only for the shapes that pass its cheap
checks, calls the same steps (:func:`~surfgen.generator.mesh.mesh.extract_with_edges`,
:func:`~surfgen.generator.mesh.walls.label_walls`) in its own order.

``evaluator="sparse"`` samples only the blocks of the grid the surface may cross
(:mod:`surfgen.generator.eval.sparse`) and meshes them
(:mod:`surfgen.generator.mesh.sparse_marching`): the same mesh as the dense path, bit for bit,
in time and memory that grow with the surface rather than the grid.  ``"auto"`` picks it for
grids of :data:`AUTO_SPARSE_FROM` points or more (:func:`resolve_evaluator`), whatever share of
the grid its bounds leave to sample (``benchmarks/bench_auto.py``).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

from surfgen.generator.errors import EmptySurface, FormulaError
from surfgen.generator.eval.evaluate import EVALUATORS, evaluate
from surfgen.generator.eval.grid import Field, Grid
from surfgen.generator.eval.sparse import SparseField, evaluate_sparse, thread_count
from surfgen.generator.formula.limits import MemoryBudget
from surfgen.generator.mesh.mesh import Mesh, extract_mesh
from surfgen.generator.mesh.sparse_marching import extract_sparse, extract_sparse_labelled
from surfgen.generator.mesh.walls import WallReport, check_walls_mode, extract_labelled
from surfgen.generator.model.spec import SurfaceSpec

#: ``auto`` meshes grids of at least this many points sparsely, whatever share of them its
#: bounds leave to sample (``benchmarks/bench_auto.py``, docs/performance: the sparse path was
#: faster for 2 of 22 shapes at 96^3, 8 at 128^3, 13 at 160^3, 16 at 192^3 and 19 at 256^3, and
#: for 6 of 7 shapes whose bounds leave more than half of a 512^3 grid to sample, by 1.0-2.5x
#: (the seventh, a long formula, 0.94x): its meshing runs on every core and skips the leaves
#: one side holds).
AUTO_SPARSE_FROM = 160**3

#: The names :func:`realise` takes for ``evaluator``: ``dense`` is ``fast`` (every grid point).
EVALUATOR_CHOICES = ("auto", "dense", *EVALUATORS)


def resolve_evaluator(evaluator: str, grid: Grid) -> str:
    """The evaluator ``evaluator`` means on ``grid``: ``auto`` is ``sparse`` from
    :data:`AUTO_SPARSE_FROM` points on, else ``fast``; ``dense`` is ``fast``; others are
    themselves.  Raises :class:`FormulaError` for an unknown name."""
    if evaluator == "auto":
        return "sparse" if grid.size >= AUTO_SPARSE_FROM else "fast"
    if evaluator == "dense":
        return "fast"
    if evaluator not in EVALUATORS:
        raise FormulaError(
            f"unknown evaluator '{evaluator}' (allowed: {', '.join(EVALUATOR_CHOICES)})"
        )
    return evaluator


@dataclasses.dataclass(frozen=True)
class Realised:
    """What :func:`realise` made: the field (a :class:`SparseField` on the sparse path), the
    mesh (None when the surface is empty and that was allowed: ``empty`` says why), the walls'
    report (None when the crossings were not classified), and the seconds spent evaluating and
    meshing."""

    spec: SurfaceSpec
    field: Field | SparseField
    mesh: Mesh | None
    walls: WallReport | None = None
    empty: str | None = None
    seconds: dict[str, float] = dataclasses.field(default_factory=dict)

    @property
    def sparse(self) -> bool:
        return isinstance(self.field, SparseField)


#: A long run's progress: its stage's name, and the share of it done where that is known.
StageProgress = Callable[[str, float | None], None]


def _stage(progress: StageProgress | None, name: str) -> None:
    if progress is not None:
        progress(name, None)


def realise(
    spec: SurfaceSpec,
    *,
    grid: Grid | None = None,
    field: Field | SparseField | None = None,
    evaluator: str = "fast",
    threads: int | None = None,
    cap: bool = False,
    walls: str | None = None,
    allow_empty: bool = False,
    keep_samples: bool = True,
    budget: MemoryBudget | None = None,
    progress: StageProgress | None = None,
) -> Realised:
    """Evaluate ``spec`` and extract ``F = spec.level`` (with box caps when ``cap``).

    ``grid``: evaluate there instead of ``spec.to_grid()`` (a re-gridded export); ``field``: an
    already evaluated field of ``spec`` (nothing is evaluated; a :class:`SparseField` must have
    been sampled at ``spec.level``, with ``faces=True`` for ``cap``); ``evaluator``: ``fast``,
    ``reference``, ``sparse`` or ``auto`` (:func:`resolve_evaluator`); ``threads``: as
    :func:`~surfgen.generator.eval.evaluate.evaluate`. ``walls``: None extracts without
    classifying the crossings (:func:`~surfgen.generator.mesh.mesh.extract_mesh`); ``keep``,
    ``mark`` or ``remove`` classifies them and keeps, labels or removes the walls
    (:func:`~surfgen.generator.mesh.walls.extract_labelled`). ``allow_empty``: an empty surface
    gives ``mesh=None`` and its message in ``empty`` instead of raising.  ``keep_samples=False``
    (for a caller that keeps only the mesh and the counts: ``render``, ``export``) frees a
    sparse field's samples as soon as the meshing has read them
    (:meth:`~surfgen.generator.eval.sparse.SparseField.release_samples`; ``field.stats`` and
    ``field.nonfinite`` stay).  ``budget`` (``render``, ``export``): the sparse path checks
    each step's memory against it once it knows its size, before the step allocates
    (:class:`~surfgen.generator.formula.limits.MemoryBudget`).  ``progress``: called with
    each stage's name as it starts (``bounding``, ``sampling``, ``evaluating``, ``meshing``)
    and the share done where it is known (a sparse run's leaves sampled), else None.  Every
    evaluator gives the same mesh, bit for bit.

    Raises :class:`EmptySurface` (unless ``allow_empty``), ``SpecError`` for an unknown walls
    mode, and what evaluation raises (``FormulaError``, ``LimitError``...).
    """
    if walls is not None:
        check_walls_mode(walls)
    t0 = time.perf_counter()
    tree = spec.tree()
    if field is None:
        grid = spec.to_grid() if grid is None else grid
        name = resolve_evaluator(evaluator, grid)
        if name == "sparse":
            _stage(progress, "bounding")
            field = evaluate_sparse(
                tree,
                grid,
                spec.params,
                threads=threads,
                level=spec.level,
                faces=cap,
                budget=budget,
                progress=None if progress is None else lambda done: progress("sampling", done),
            )
        else:
            _stage(progress, "evaluating")
            field = evaluate(tree, grid, spec.params, evaluator=name, threads=threads)
    elif isinstance(field, SparseField) and field.level != spec.level:
        raise ValueError(f"sparse field sampled at level {field.level}, not {spec.level}")
    t1 = time.perf_counter()
    mesh: Mesh | None = None
    report: WallReport | None = None
    empty: str | None = None
    _stage(progress, "meshing")
    try:
        if isinstance(field, SparseField):
            if walls is None:
                mesh = extract_sparse(field, cap, threads, not keep_samples, budget)
            else:
                mesh, report = extract_sparse_labelled(
                    field, tree, spec.params, cap, walls, threads, not keep_samples, budget
                )
        elif walls is None:
            mesh = extract_mesh(field, spec.level, cap=cap)
        else:
            mesh, report = extract_labelled(
                field, tree, spec.params, spec.level, cap, walls, thread_count(threads)
            )
    except EmptySurface as exc:
        if not allow_empty:
            raise
        empty = str(exc)
    t2 = time.perf_counter()
    seconds = {"evaluate": t1 - t0, "mesh": t2 - t1}
    return Realised(spec, field, mesh, report, empty, seconds)
