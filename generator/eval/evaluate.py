"""One entry point to evaluate a formula, whichever evaluator does the work.

Evaluators are registered by name in :data:`EVALUATORS`: ``fast`` (the compiled tape run by the
numba interpreter, :mod:`surfgen.generator.eval.tape`) and ``reference`` (plain numpy,
:mod:`surfgen.generator.eval.reference`); both give the same values bit for bit.  ``sparse``
(:mod:`surfgen.generator.eval.sparse`) samples only the blocks of the grid that the level set
``F = level`` may cross (interval bounds decide the others): its grid operation returns a
:class:`~surfgen.generator.eval.sparse.SparseField` for one level, whose samples are the fast
evaluator's, and its points operation is the fast one's. An evaluator
is a module with two operations, on a grid (:func:`evaluate`) and at points
(:func:`evaluate_points`), and an entry here: a new one (a sparse evaluator) is a module and an
entry. The modules are imported on first use: the fast one imports numba, and importing
surfgen does not.

The fast evaluator also offers what its other callers need, all here:

- a formula compiled once and evaluated on several grids (:func:`evaluate_compiled` of a
  :func:`~surfgen.generator.eval.compiler.compile_tree` program: the families' checks);
- a points evaluator whose kernel numba code of other layers runs (:func:`points_evaluator`,
  then :meth:`~surfgen.generator.eval.tape.PointsEvaluator.kernel_args` with the numba
  functions of :mod:`surfgen.generator.eval.point_driver`: the walls' classification);
- the warm-up's operations: load or compile the interpreter (:func:`warm_interpreter`), ask
  numba's cache about it and the grid kernel (:func:`interpreter_cached`, :func:`grid_kernel`),
  and compile the kernels that call it without loading it (:func:`compiled_not_run`).
"""

from __future__ import annotations

import contextlib
import importlib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from surfgen.generator.errors import FormulaError
from surfgen.generator.eval.compiler import Program
from surfgen.generator.eval.grid import Field, Grid
from surfgen.generator.formula.expr import Expr

# The fast evaluator's modules (numba: imported on first use).
_FAST = "surfgen.generator.eval.tape"
_INTERPRETER = "surfgen.generator.eval.interpreter"
_GRID_DRIVER = "surfgen.generator.eval.grid_driver"


@dataclass(frozen=True)
class Evaluator:
    """An evaluator: the module that implements it (imported on first use) and the names of
    its two operations there.

    - ``on_grid(tree, grid, params[, threads=][, level=])`` returns a :class:`Field` (a
      :class:`~surfgen.generator.eval.sparse.SparseField` for ``sparse``);
    - ``at_points(tree, x, y, z, params)`` returns F at the points (broadcast together).
    """

    module: str
    on_grid: str
    at_points: str
    threads: bool  # whether on_grid takes ``threads``
    level: bool = False  # whether on_grid takes ``level`` (and samples for that level only)

    def load(self) -> ModuleType:
        return importlib.import_module(self.module)

    def evaluate(
        self,
        tree: Expr,
        grid: Grid,
        params: Mapping[str, float] | None = None,
        threads: int | None = None,
        level: float = 0.0,
    ) -> Any:
        on_grid = getattr(self.load(), self.on_grid)
        kwargs: dict[str, Any] = {}
        if self.threads:
            kwargs["threads"] = threads
        if self.level:
            kwargs["level"] = level
        return on_grid(tree, grid, params, **kwargs)

    def evaluate_points(
        self,
        tree: Expr,
        x: np.ndarray | float,
        y: np.ndarray | float,
        z: np.ndarray | float,
        params: Mapping[str, float] | None = None,
    ) -> np.ndarray:
        return getattr(self.load(), self.at_points)(tree, x, y, z, params)


EVALUATORS: dict[str, Evaluator] = {
    "fast": Evaluator(_FAST, "evaluate_fast", "evaluate_points", threads=True),
    "reference": Evaluator(
        "surfgen.generator.eval.reference", "evaluate_reference", "evaluate_points", False
    ),
    "sparse": Evaluator(
        "surfgen.generator.eval.sparse", "evaluate_sparse", "evaluate_points", True, level=True
    ),
}


def evaluator(name: str) -> Evaluator:
    """The evaluator called ``name``; raises :class:`FormulaError` for an unknown one."""
    if name not in EVALUATORS:
        raise FormulaError(f"unknown evaluator '{name}' (allowed: {', '.join(EVALUATORS)})")
    return EVALUATORS[name]


_evaluator = evaluator  # the argument ``evaluator`` of evaluate() hides the function there


def evaluate(
    tree: Expr,
    grid: Grid,
    params: Mapping[str, float] | None = None,
    evaluator: str = "fast",
    threads: int | None = None,
    level: float = 0.0,
) -> Any:
    """Sample ``tree`` on ``grid`` with the named evaluator (``fast``, ``reference`` or
    ``sparse``): a :class:`Field`, or for ``sparse`` a
    :class:`~surfgen.generator.eval.sparse.SparseField` sampled where ``F = level`` may pass.

    ``threads`` is for the fast and sparse evaluators: 1 in worker processes, ``None`` for
    numba's default.
    """
    return _evaluator(evaluator).evaluate(tree, grid, params, threads, level)


def evaluate_points(
    tree: Expr,
    x: np.ndarray | float,
    y: np.ndarray | float,
    z: np.ndarray | float,
    params: Mapping[str, float] | None = None,
    evaluator: str = "fast",
) -> np.ndarray:
    """``tree`` at the points ``(x, y, z)`` (broadcast together), float64, with the named
    evaluator: the values :func:`evaluate` gives at grid points, bit for bit."""
    return _evaluator(evaluator).evaluate_points(tree, x, y, z, params)


# ----------------------------------------------------------------------------- the fast evaluator's


def _fast(module: str = _FAST) -> Any:
    """A module of the fast evaluator, imported on first use (it imports numba)."""
    return importlib.import_module(module)


def evaluate_compiled(program: Program, grid: Grid, threads: int | None = None) -> Field:
    """Run a compiled ``program`` (:func:`~surfgen.generator.eval.compiler.compile_tree`) on
    ``grid`` with the fast evaluator: a formula compiled once, evaluated on several grids."""
    return _fast().evaluate_program(program, grid, threads)


def points_evaluator(tree: Expr, params: Mapping[str, float] | None = None) -> Any:
    """The fast evaluator of ``tree`` at arbitrary points
    (:class:`~surfgen.generator.eval.tape.PointsEvaluator`: call it, or give its
    ``kernel_args()`` to numba code that calls :mod:`~surfgen.generator.eval.point_driver`)."""
    return _fast().points_evaluator(tree, params)


def warm_interpreter() -> float:
    """Load (or compile) the fast evaluator's interpreter; returns the seconds it took."""
    return _fast().warm_interpreter()


def interpreter_cached() -> bool:
    """Whether numba's on-disk cache holds the interpreter (and its rows) for this machine and
    this code. True when that cannot be told."""
    return _fast(_INTERPRETER).interpreter_cached()


def grid_kernel() -> Any:
    """The fast evaluator's grid kernel (a numba dispatcher: for questions to numba's cache)."""
    return _fast(_GRID_DRIVER).run_grid


@contextlib.contextmanager
def compiled_not_run(*others: tuple[object, str]) -> Iterator[None]:
    """Within the block the interpreter is not loaded, and the kernels that call it (the grid
    kernel, and each ``(module, name)`` numba dispatcher of ``others``: the walls') are compiled
    (or loaded from numba's cache) for the types of their arguments, not run: a call returns 0
    and writes nothing. A kernel's compile needs the interpreter's calling convention only."""
    with _fast().compiled_not_run(*others):
        yield
