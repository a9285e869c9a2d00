"""One entry point to sample a formula on a grid, whichever evaluator does the work."""

from __future__ import annotations

from collections.abc import Mapping

from surfgen.generator.errors import FormulaError
from surfgen.generator.eval.grid import Field, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.expr import Expr

EVALUATORS = ("fast", "reference")


def evaluate(
    tree: Expr,
    grid: Grid,
    params: Mapping[str, float] | None = None,
    evaluator: str = "fast",
    threads: int | None = None,
) -> Field:
    """Sample ``tree`` on ``grid`` with the named evaluator (``fast`` or ``reference``).

    ``threads`` is for the fast evaluator: 1 in worker processes, ``None`` for numba's default.
    """
    if evaluator == "reference":
        return evaluate_reference(tree, grid, params)
    if evaluator == "fast":
        from surfgen.generator.eval.tape import evaluate_fast  # imports numba: only when asked for

        return evaluate_fast(tree, grid, params, threads=threads)
    raise FormulaError(f"unknown evaluator '{evaluator}' (allowed: {', '.join(EVALUATORS)})")
