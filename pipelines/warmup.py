"""Load (or compile, the first time on a machine) every numba kernel a shape goes through.

The sampling driver calls :func:`warm_shape_kernels` before it forks its workers, so they
start with the kernels in memory: on a fresh checkout, compiling them took a worker a minute
or more, longer than a shape's ``timeout`` on a loaded machine, and the first shapes were then
rejected as ``timeout`` — a catalogue that depended on the cache. Dask's shape processes get
the same through :mod:`surfgen.pipelines.warm`, imported by their forkserver.
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import time
from collections.abc import Callable

import numpy as np

log = logging.getLogger(__name__)

# A small ball with a pole inside the box (so the walls' classification runs its kernel) and
# one cut by the box (caps).
WARM_FORMULA = "x^2 + y^2 + z^2 - 1 + 0.02*tan(2*x + 0.3)"
WARM_HALF, WARM_POINTS = 1.1, 14

# The child that compiles the grid kernel, and what follows a mesh but the walls, while this
# process compiles the walls' kernels.
_CHILD = "from surfgen.pipelines.warmup import warm_in_child; warm_in_child()"


def _tiny_shape(evaluator: str = "fast"):
    """The warm-up's formula, its box and its field (``evaluator``: fast or reference, the same
    values)."""
    from surfgen.generator.evaluate import evaluate
    from surfgen.generator.grid import Box, Grid
    from surfgen.generator.parser import parse

    tree = parse(WARM_FORMULA)
    box = Box.cube(WARM_HALF)
    return tree, box, evaluate(tree, Grid(box, (WARM_POINTS,) * 3), evaluator=evaluator, threads=1)


def warm_grid_kernel() -> None:
    """Load (or compile) the fast evaluator's grid kernel, as :func:`warm_shape_kernels` uses it."""
    _tiny_shape("fast")


def warm_in_child() -> None:
    """The child's part of a parallel warm-up: the grid kernel, then every kernel after the
    evaluation except the walls' (which the parent compiles meanwhile)."""
    _warm_after_evaluation("fast")


def grid_kernel_cached() -> bool:
    """Whether numba's on-disk cache holds the grid kernel for this machine and this code (then
    loading it takes a fraction of a second). True when that cannot be told: the caller then
    does what it always did."""
    from surfgen.generator import kernels

    return kernel_cached(kernels.run_grid)


def kernel_cached(dispatcher) -> bool:
    """Whether numba's on-disk cache holds a compiled ``dispatcher`` (any signature) for this
    machine and this code. True when that cannot be told (numba's internals moved)."""
    try:
        cache = dispatcher._cache  # numba's own cache (a NullCache where caching is off)
        index = cache._cache_file._load_index()  # empty when missing or stale
        here = cache._index_key(None, dispatcher.targetctx.codegen())[1:]
        return any(key[1:] == here for key in index)
    except Exception:  # numba's internals moved: no way to tell, assume the cache is warm
        log.debug("cannot read numba's cache index of %s", dispatcher, exc_info=True)
        return True


# What a cold start looks like to a user: shown once, before the warm-up compiles.
COMPILE_NOTICE = (
    "compiling surfgen's numba kernels: about 1-2 minutes on the first run on this machine "
    "(or after an update); they are cached for later runs"
)


def compile_notice(echo: Callable[[str], None], *, background: bool = False) -> bool:
    """For a command about to evaluate with the fast evaluator: ``echo`` :data:`COMPILE_NOTICE`
    (also logged) when its grid kernel is not in numba's cache — compiling it and the mesh's
    kernels takes a minute or two, once. ``background``: the compile runs beside the command (a
    server's warm-up). Returns whether it spoke."""
    if grid_kernel_cached():
        return False
    _announce(
        COMPILE_NOTICE + (", in the background: the first step waits for it" if background else ""),
        echo,
    )
    return True


def _announce(text: str, echo: Callable[[str], None] | None) -> None:
    """The library logs a compile notice; the CLI's ``echo`` prints it."""
    log.info(text)
    if echo is not None:
        echo(text)


def shape_kernels_cached() -> bool:
    """Whether numba's on-disk cache holds the kernels a shape goes through (one of each stage:
    the grid, the walls, the mesh, the metrics, the pictures) for this machine and this code,
    so that :func:`warm_shape_kernels` only loads them."""
    from surfgen.filters import geometry
    from surfgen.generator import kernels, mesh, walls
    from surfgen.pipelines import pictures

    stages = (kernels.run_grid, walls._bisect_kernel, mesh._offsets_kernel)
    stages += (geometry.corner_angle_sums, pictures._rasterise)
    return all(kernel_cached(d) for d in stages)


def warm_mesh_kernels() -> None:
    """Every kernel after the evaluation but the walls' (mesh, filters, descriptor, picture),
    on the tiny shape sampled by the reference evaluator: needs no interpreter, so it can be
    compiled while another process compiles that (the test suite's warm-up does)."""
    _warm_after_evaluation("reference")


def _warm_after_evaluation(evaluator: str) -> None:
    """Every kernel after the evaluation but the walls', on the tiny shape's field as
    ``evaluator`` samples it (fast: the grid kernel too)."""
    tree, box, field = _tiny_shape(evaluator)
    _warm_the_rest(field, box, _warm_mesh(field, tree, walls=False))


def _cpus() -> int:
    """The CPUs this process may run on (all of them where the OS cannot tell, as on macOS)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def _start_child() -> subprocess.Popen | None:
    """On a cold cache with a second CPU: compile the interpreter here (the grid kernel and the
    points kernels each need it), then start the child (:func:`warm_in_child`)."""
    if _cpus() < 2 or grid_kernel_cached():
        return None
    from surfgen.generator.fast import warm_interpreter

    log.debug("interpreter compiled in %.1f s", warm_interpreter())
    try:
        return subprocess.Popen(
            [sys.executable, "-c", _CHILD],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        )
    except OSError as exc:  # no second process: compile it all here, as before
        log.debug("cannot start the warm-up's child process: %s", exc)
        return None


def _join_child(child: subprocess.Popen) -> None:
    _, err = child.communicate()
    if child.returncode != 0:  # compiled here instead, by what follows
        log.debug("the warm-up's child process failed: %s", err.decode(errors="replace"))


def warm_shape_kernels(parallel: bool = True, notice: Callable[[str], None] | None = None) -> float:
    """Evaluate, mesh, classify, measure, describe and draw a tiny shape once; returns the
    seconds it took. When that means compiling (:func:`shape_kernels_cached` is false),
    ``notice`` is called first with :data:`COMPILE_NOTICE`, which is also logged.

    The first time on a machine this compiles every kernel, about two minutes on one CPU. With
    ``parallel`` and a second CPU it takes about 0.7 of that (``benchmarks/bench_cold_start.py``):
    this process compiles the interpreter, then a child process (:func:`warm_in_child`)
    compiles the grid kernel and the mesh, filter and picture kernels into numba's on-disk cache
    while this one compiles the walls' kernels on the tiny shape sampled by the reference
    evaluator (the same values); then this process loads the child's kernels from the cache."""
    t0 = time.perf_counter()
    if not shape_kernels_cached():
        _announce(COMPILE_NOTICE, notice)
    child = _start_child() if parallel else None
    try:
        if child is not None:
            tree, _, field = _tiny_shape("reference")
            _warm_mesh(field, tree)
            _join_child(child)
            child = None
        tree, box, field = _tiny_shape("fast")  # loaded from the cache after a child
        _warm_the_rest(field, box, _warm_mesh(field, tree))
    finally:
        if child is not None:  # interrupted: leave no compiler behind
            child.kill()
            child.wait()
    seconds = time.perf_counter() - t0
    log.debug("shape kernels ready in %.2f s", seconds)
    return seconds


def _warm_mesh(field, tree, walls: bool = True):
    """The mesh kernels and (``walls``) the walls' classification on the tiny shape's field;
    returns the mesh."""
    from surfgen.generator.mesh import extract_with_edges
    from surfgen.generator.walls import label_walls

    mesh, edges = extract_with_edges(field, 0.0, cap=True)
    if walls:
        label_walls(mesh, edges, field, tree, {}, 0.0, True, "keep")
    return mesh


def _warm_the_rest(field, box, mesh) -> None:
    """Every kernel after the mesh and the walls, on the tiny shape."""
    from surfgen.filters.descriptor import descriptor
    from surfgen.filters.shape import quality_metrics
    from surfgen.filters.verdict import quick_metrics, shape_metrics
    from surfgen.generator.families import envelope_departure, pieces
    from surfgen.generator.grid import Field
    from surfgen.generator.mesh import _merge_same, extract_with_edges
    from surfgen.pipelines.pictures import render_image

    quick = quick_metrics(mesh, box.bounds())
    quality_metrics(mesh, shape_metrics(mesh, box.bounds(), quick=quick))
    descriptor(mesh)
    render_image(mesh, size=16)
    # read-only fields (the sampler's) and a carved copy (the ornament checks'): two signatures
    envelope_departure(field.values, field.values)
    envelope_departure(field.values + 0.0, field.values)
    pieces(field.values)
    # Kernels only some shapes run: vertices of one grid edge given one index (a crossing on a
    # box edge of a capped shape, an ambiguous cell), and non-finite samples (a pole on a
    # sample) given an offset from their neighbours; the warm ball has neither.
    _merge_same(np.zeros((3, 3)), np.array([[0, 1, 2]], dtype=np.int64), np.arange(3))
    holed = field.values.copy()
    holed[7, 7, 7] = np.nan
    extract_with_edges(Field(field.grid, holed), 0.0, cap=True)  # read-only, as the sampler's
