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

import subprocess
import sys
import time

import numpy as np

MIN_TESTS = 100  # smaller sessions (a module, a -k selection) compile only what they use

# The sparse path's kernels (interval bounds, the block octree, the sparse marching cubes) take
# about 100 s to compile, alone.  They are compiled by a child once the interpreter is in the
# cache, while the first test folders (these, which mesh densely) run; the first test outside
# them waits for the child (``tests/conftest.py``).
BEFORE_SPARSE = ("tests/api/", "tests/benchmarks/", "tests/filters/", "tests/generator/elementary/")
_SPARSE_CHILD = "from tests.support.kernel_warmup import warm_sparse_kernels; warm_sparse_kernels()"


def warm_points_kernels() -> None:
    """Every row of the interpreter (the sampler's warm-up loads those of equation (13) only;
    the tests call them all), then the points kernels the tests call from Python, with the
    tests' argument types (contiguous, writable float64 and int64 arrays)."""
    from surfgen.generator.eval import point_driver as points
    from surfgen.generator.eval.row_functions import load_rows
    from surfgen.generator.eval.tape import points_evaluator
    from surfgen.generator.formula.parser import parse

    load_rows()
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
    from surfgen.generator.eval.row_functions import rows_cached
    from surfgen.pipelines.run.warmup import kernel_cached, shape_kernels_cached

    return not (
        shape_kernels_cached()
        and rows_cached()
        and all(kernel_cached(d) for d in (points.eval_points, points.eval_edges))
    )


def warm_for_suite() -> float:
    """Compile everything above, on two processes while the interpreter compiles; returns the
    seconds it took."""
    from surfgen.pipelines.run.warmup import warm_shape_kernels

    t0 = time.perf_counter()
    warm_shape_kernels(parallel=True, meanwhile=warm_points_kernels)
    return time.perf_counter() - t0


def warm_sparse_kernels() -> None:
    """The interval bounds and the sparse evaluation and marching (with and without the walls'
    labels) on a small shape with a pole, as ``render --evaluator sparse`` runs them."""
    from surfgen.generator.eval.intervals import tree_bounds
    from surfgen.generator.mesh.realise import realise
    from surfgen.generator.model.spec import SurfaceSpec

    spec = SurfaceSpec("x^2+y^2+z^2-1+0.1*sin(3*x)/y", (-1.5, 1.5) * 3, (40,) * 3)
    lo = np.array([[-1.0, -1.0, -1.0], [0.0, 0.0, 0.0]])
    tree_bounds(spec.tree(), None, lo, lo + 0.5)
    realise(spec, evaluator="sparse", cap=True)
    realise(spec, evaluator="sparse", cap=True, walls="mark")


def sparse_kernels_cached() -> bool:
    """Whether numba's cache holds the sparse path's kernels (the interval interpreter's and the
    sparse marcher's)."""
    from surfgen.generator.eval import interval_kernels
    from surfgen.generator.mesh import sparse_lewiner
    from surfgen.pipelines.run.warmup import kernel_cached

    return kernel_cached(interval_kernels.run_boxes) and kernel_cached(sparse_lewiner.lewiner_range)


def start_sparse_child() -> subprocess.Popen | None:
    """Start compiling the sparse path's kernels in a child (None: cached, or no child)."""
    if sparse_kernels_cached():
        return None
    try:
        return subprocess.Popen(
            [sys.executable, "-c", _SPARSE_CHILD],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    except OSError:  # the tests compile them themselves, as they always could
        return None
