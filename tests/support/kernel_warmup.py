"""The suite's warm-up: on a cold numba cache, compile the kernels the tests need on both CPUs
before the first test, instead of one at a time inside the first tests that call them.

From a clean clone the tests spent about 3.5 of their 10 minutes (Zen 3) compiling: the tape
interpreter, the grid kernel, the walls' kernels, the mesh and picture kernels, and the points
kernels only tests call directly (:meth:`PointsEvaluator.__call__` and ``.plain``,
:func:`points.edge_lattice` and :func:`points.eval_edges`).  Here
:func:`warmup.warm_shape_kernels` compiles the interpreter while a child compiles every kernel of
a shape but that one; once the interpreter is ready, this process compiles the test-only points
kernels (:func:`warm_points_kernels`, about 10 s: the interpreter is called, not compiled into
them) while the child finishes.

Nothing is compiled when the cache is warm (a fraction of a second to tell).  ``tests/conftest.py``
runs it for sessions of :data:`MIN_TESTS` tests or more; ``SURFGEN_TEST_WARMUP=0`` turns it off,
``=1`` runs it for any session.  A child that fails changes nothing: the tests then compile what
is missing themselves, as they always could.
"""

from __future__ import annotations

import time

import numpy as np

MIN_TESTS = 100  # smaller sessions (a module, a -k selection) compile only what they use


def warm_points_kernels() -> None:
    """The points kernels the tests call from Python, with the tests' argument types
    (contiguous, writable float64 and int64 arrays)."""
    from surfgen.generator.eval import point_driver as points
    from surfgen.generator.eval.tape import points_evaluator
    from surfgen.generator.formula.parser import parse

    evaluator = points_evaluator(parse("sin(x*y) + z"))
    x = np.linspace(-1.0, 1.0, 5)
    evaluator(x, x, x)  # points.eval_points
    evaluator.plain(x, x, x)  # points.run_points
    prog, tile, active, rows = evaluator.kernel_args()
    axes = (np.array([-1.0, 0.0, 1.0]), np.array([-1.0, 0.5]), np.array([0.0, 2.0]))
    ijk = np.zeros((2, 3), dtype=np.int64)
    ctx = points.edge_lattice(prog, tile, active, rows, 0, ijk, axes)
    sel, u, out = np.zeros(2, dtype=np.int64), np.zeros(2), np.zeros(2)
    points.eval_edges(prog, tile, active, rows, ctx, sel, u, out)


def needed() -> bool:
    """Whether any of the kernels this warm-up compiles is missing from numba's cache."""
    from surfgen.generator.eval import point_driver as points
    from surfgen.pipelines.run.warmup import kernel_cached, shape_kernels_cached

    return not (
        shape_kernels_cached()
        and all(kernel_cached(d) for d in (points.eval_points, points.eval_edges))
    )


def warm_for_suite() -> float:
    """Compile everything above, on two processes while the interpreter compiles; returns the
    seconds it took."""
    from surfgen.pipelines.run.warmup import warm_shape_kernels

    t0 = time.perf_counter()
    warm_shape_kernels(parallel=True, meanwhile=warm_points_kernels)
    return time.perf_counter() - t0
