"""Load (or compile, the first time on a machine) every numba kernel a shape goes through.

The sampling driver calls :func:`warm_shape_kernels` before it forks its workers, so they
start with the kernels in memory: on a fresh checkout, compiling them took a worker a minute
or more, longer than a shape's ``timeout`` on a loaded machine, and the first shapes were then
rejected as ``timeout`` — a catalogue that depended on the cache. Dask's shape processes get
the same through :mod:`surfgen.pipelines.run.dask_preload`, imported by their forkserver. ``render``,
``sweep`` and ``reproduce`` call :func:`compile_first`: on a cold cache, the same warm-up on two
processes before they evaluate.
"""

from __future__ import annotations

import contextlib
import gc
import logging
import os
import subprocess
import sys
import time
from collections.abc import Callable, Iterator

import numpy as np

from surfgen.generator.eval.evaluate import (
    compiled_not_run,
    evaluate,
    grid_kernel,
    interpreter_cached,
    warm_interpreter,
)
from surfgen.generator.eval.grid import Box, Field, Grid
from surfgen.generator.formula.parser import parse
from surfgen.generator.jit.cache import cached_on_disk

# The kernels of the mesh, the walls, the filters and the pictures are imported where they are
# warmed, on purpose: their modules import numba, which a command that computes nothing (and
# imports this module) must not load.

log = logging.getLogger(__name__)

# A small ball with a pole inside the box (so the walls' classification runs its kernel) and
# one cut by the box (caps).
WARM_FORMULA = "x^2 + y^2 + z^2 - 1 + 0.02*tan(2*x + 0.3)"
WARM_HALF, WARM_POINTS = 1.1, 14

# The two children of a parallel warm-up on a cold cache: one compiles the interpreter, the
# grid kernel, the fine band's, the resolution check's distances and the pictures', the other
# every other kernel; this process then loads them all.
_FIRST_CHILD = "from surfgen.pipelines.run.warmup import warm_first_in_child; warm_first_in_child()"
_CHILD = "from surfgen.pipelines.run.warmup import warm_in_child; warm_in_child()"


def _tiny_shape(evaluator: str = "fast"):
    """The warm-up's formula, its box and its field (``evaluator``: fast or reference, the same
    values)."""
    tree = parse(WARM_FORMULA)
    box = Box.cube(WARM_HALF)
    return tree, box, evaluate(tree, Grid(box, (WARM_POINTS,) * 3), evaluator=evaluator, threads=1)


def warm_grid_kernel() -> None:
    """Load (or compile) the fast evaluator's grid kernel, as :func:`warm_shape_kernels` uses it."""
    _tiny_shape("fast")


def warm_first_in_child() -> None:
    """The first child's part of a parallel warm-up: the interpreter, the grid kernel and the
    fine band's evaluation (which calls it), the resolution check's distances, the pictures'
    and the infill's struts' kernels (:func:`_warm_extras`), then the shape descriptor's,
    while the other child (:func:`warm_in_child`) compiles the rest. No mesh kernel is run
    here: the distances, the pictures and the descriptor get the tiny shape's mesh from
    scikit-image's marching cubes, since the other child may not have cached surfgen's yet
    (two processes compiling the same kernel do the work twice). Balanced by the children's
    times on a 2-core Xeon, each run alone: 31.4-31.8 s here, 32.1-32.5 s there (32.7-32.9
    and 31.0 s with the carving here too)."""
    from surfgen.filters.descriptor import descriptor
    from surfgen.filters.resolution import warm_band, warm_distances

    with _collector_paused(collect=False):
        warm_interpreter()
        tree, _, field = _tiny_shape("fast")  # the grid kernel
        warm_band(tree, field)  # the fine band's columns
        mesh = _skimage_mesh(field)
        warm_distances(mesh, field.grid)  # the resolution check's distances
        _warm_extras(field, mesh)
        descriptor(mesh)


def _skimage_mesh(field: Field):
    """The tiny shape's surface by scikit-image's marching cubes (no numba kernel of surfgen's),
    as a :class:`Mesh` with the types of surfgen's."""
    from skimage.measure import marching_cubes

    from surfgen.generator.mesh.mesh import Mesh

    vertices, faces, _, _ = marching_cubes(field.values, 0.0)
    return Mesh(vertices, faces)


def warm_in_child() -> None:
    """The other child's part of a parallel warm-up: every kernel of a shape but those of the
    first child (:func:`warm_first_in_child`), the sparse marching first. The walls' kernel,
    which calls the interpreter, is compiled for the tiny shape's argument types, not run
    (:func:`surfgen.generator.eval.evaluate.compiled_not_run`); the mesh and filter kernels run
    on the field the reference evaluator samples (the same values)."""
    from surfgen.generator.mesh import refine

    with _collector_paused(collect=False), compiled_not_run((refine, "_bisect_kernel")):
        _warm_sparse_marching()
        tree, box, field = _tiny_shape("reference")
        # "mark": the faces labelled, as the sampler's "keep" labels them where it finds walls
        # (here the classification is compiled, not run: it finds none)
        mesh = _warm_mesh(field, tree, "mark")
        _warm_measures(field, box, mesh, tree, resolution=False, descriptor=False)
        _warm_rare_mesh(field)
        _warm_carving(field)


def grid_kernel_cached() -> bool:
    """Whether numba's on-disk cache holds the grid kernel and the interpreter it calls for this
    machine and this code (then loading them takes a fraction of a second). True when that
    cannot be told: the caller then does what it always did."""
    return interpreter_cached() and kernel_cached(grid_kernel())


def kernel_cached(dispatcher) -> bool:
    """Whether numba's on-disk cache holds a compiled ``dispatcher`` (any signature) for this
    machine and this code. True when that cannot be told (numba's internals moved)."""
    # dispatcher._cache: numba's own cache (a NullCache where caching is off)
    return cached_on_disk(lambda: (dispatcher._cache, dispatcher.targetctx.codegen()), dispatcher)


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


def compile_first(echo: Callable[[str], None]) -> bool:
    """For a command about to evaluate with the fast evaluator (render, sweep, reproduce): on a
    cold cache, ``echo`` :data:`COMPILE_NOTICE` and, with a second CPU, compile every kernel of
    a shape first, on two processes (:func:`warm_shape_kernels`), instead of one after the other
    as the command reaches them: a first ``surfgen render`` with a PNG took 107 s that way on a
    2-core Zen 3, the warm-up on two processes 76 s. Returns whether the cache was cold."""
    if not compile_notice(echo):
        return False
    if _cpus() >= 2:
        warm_shape_kernels(parallel=True)
    return True


def _announce(text: str, echo: Callable[[str], None] | None) -> None:
    """The library logs a compile notice; the CLI's ``echo`` prints it."""
    log.info(text)
    if echo is not None:
        echo(text)


def shape_kernels_cached() -> bool:
    """Whether numba's on-disk cache holds the interpreter and the kernels a shape goes through
    (one of each stage: the grid, the walls, the mesh, the metrics, the pictures) for this
    machine and this code, so that :func:`warm_shape_kernels` only loads them."""
    return interpreter_cached() and _kernels_cached()


def _kernels_cached() -> bool:
    """:func:`shape_kernels_cached` but the interpreter."""
    from surfgen.filters import fine_band, geometry
    from surfgen.generator.eval import grid_driver
    from surfgen.generator.mesh import marching, refine, sparse_lewiner
    from surfgen.pipelines.pictures import raster as pictures

    stages = (grid_kernel(), refine._bisect_kernel, marching._offsets_kernel)
    stages += (geometry.corner_angle_sums, pictures._rasterise)
    stages += (grid_driver.run_columns, fine_band._fill_bricks, sparse_lewiner.lewiner_range)
    return all(kernel_cached(d) for d in stages)


def _cpus() -> int:
    """The CPUs this process may run on (all of them where the OS cannot tell, as on macOS)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def _start_children() -> tuple[subprocess.Popen | None, subprocess.Popen | None]:
    """On a cold cache with a second CPU: start the two children of a parallel warm-up
    (:func:`warm_first_in_child`, :func:`warm_in_child`); ``None`` for a child not started
    (one CPU, the kernels cached, or no process to be had: this process compiles its part)."""
    if _cpus() < 2 or _kernels_cached():
        return None, None
    return _start(_FIRST_CHILD), _start(_CHILD)


def _start(code: str) -> subprocess.Popen | None:
    try:
        return subprocess.Popen(
            [sys.executable, "-c", code],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        )
    except OSError as exc:  # compiled here instead, by what follows
        log.debug("cannot start a warm-up's child process: %s", exc)
        return None


def _join_child(child: subprocess.Popen) -> None:
    _, err = child.communicate()
    if child.returncode != 0:  # compiled here instead, by what follows
        log.debug("a warm-up's child process failed: %s", err.decode(errors="replace"))


def warm_shape_kernels(
    parallel: bool = True,
    notice: Callable[[str], None] | None = None,
    meanwhile: Callable[[], None] | None = None,
) -> float:
    """Evaluate, mesh, classify, measure, describe and draw a tiny shape once; returns the
    seconds it took. When that means compiling (:func:`shape_kernels_cached` is false),
    ``notice`` is called first with :data:`COMPILE_NOTICE`, which is also logged.

    The first time on a machine this compiles every kernel, about a minute on one CPU. With
    ``parallel`` and a second CPU, about half that (``benchmarks/cold_start.py``): two child
    processes compile into numba's on-disk cache, one the interpreter, the grid kernel, the
    fine band's, the distances' and the pictures' (:func:`warm_first_in_child`), the other
    every other kernel (:func:`warm_in_child`), and this process then loads them all from the
    cache, as a warm start does. A process that compiled is slower afterwards: the main job's
    shapes took 6-10 % longer in a process (and in workers forked from one) that had compiled
    the kernels than in one that loaded them (numba's compiler leaves the Python heap
    scattered). Python's cycle collector is paused while this process compiles
    (:func:`_collector_paused`).
    ``meanwhile`` (the suite's own kernels) runs once the interpreter is ready, before this
    process waits for the second child: only the interpreter need be loaded for it."""
    t0 = time.perf_counter()
    compiling = not shape_kernels_cached()
    if compiling:
        _announce(COMPILE_NOTICE, notice)
    first, rest = _start_children() if parallel else (None, None)
    with _collector_paused(compiling):
        _warm_here(t0, first, rest, meanwhile)
    seconds = time.perf_counter() - t0
    log.debug("shape kernels ready in %.2f s", seconds)
    return seconds


@contextlib.contextmanager
def _collector_paused(pause: bool = True, collect: bool = True) -> Iterator[None]:
    """Python's cycle collector off while numba compiles (``pause``), then one collection
    (``collect``; a process about to exit skips it): numba's compiler makes millions of
    objects, many in cycles, and the collector walking them again and again took a tenth of a
    cold warm-up's compile (measured: the interpreter 21 -> 18.6 s, the sparse marching 19.5 ->
    16.9 s; the one collection after, 0.2-1.6 s)."""
    if not pause or not gc.isenabled():
        yield
        return
    gc.disable()
    try:
        yield
    finally:
        gc.enable()
        if collect:
            gc.collect()


def _warm_here(
    t0: float, first: subprocess.Popen | None, rest: subprocess.Popen | None, meanwhile
) -> None:
    """This process's part of :func:`warm_shape_kernels`: with children (``first`` compiling
    the interpreter, the grid, the fine band, the distances and the pictures, ``rest`` the
    other kernels), load what they compiled as each ends; without one, compile its part
    here."""
    try:
        if first is not None:
            _join_child(first)
            log.debug("the first child's kernels ready at %.1f s", time.perf_counter() - t0)
        log.debug("interpreter ready in %.1f s", warm_interpreter())
        if meanwhile is not None:
            meanwhile()
        if rest is not None:
            _join_child(rest)
            log.debug("the other child's kernels ready at %.1f s", time.perf_counter() - t0)
        _warm_sparse_marching()
        tree, box, field = _tiny_shape("fast")  # loaded from the cache after a child
        _warm_the_rest(field, box, _warm_mesh(field, tree), tree)
    finally:
        for child in (first, rest):
            if child is not None and child.poll() is None:  # interrupted: no compiler left
                child.kill()
                child.wait()


def _warm_mesh(field, tree, walls: str = "keep"):
    """The mesh kernels and the walls' classification and labels (``walls``: the mode) on the
    tiny shape's field; returns the mesh."""
    from surfgen.generator.mesh.mesh import extract_with_edges
    from surfgen.generator.mesh.walls import label_walls

    mesh, edges = extract_with_edges(field, 0.0, cap=True)
    label_walls(mesh, edges, field, tree, {}, 0.0, True, walls)
    return mesh


def _doctored(values: np.ndarray) -> np.ndarray:
    """A copy of the tiny shape's samples with a crossing a hair from its sample (raised off
    it: the crossings' raises) and a non-finite sample beside the surface (mirrored)."""
    values = values.copy()
    inside = values < 0
    i, j, k = np.argwhere(inside[:, :, :-1] & ~inside[:, :, 1:])[0]
    values[i, j, k + 1] = 1e-12  # a crossing a hair from its sample
    i, j, k = np.argwhere(~inside[:, :, :-1] & inside[:, :, 1:])[-1]
    values[i, j, k] = np.nan  # a non-finite sample beside the surface
    return values


def _warm_sparse_marching() -> None:
    """The resolution check's sparse marching (:mod:`surfgen.generator.mesh.sparse_marching`)
    on the tiny shape's field as one brick per leaf, with a non-finite sample beside the
    surface (mirrored) and one a hair outside it (a crossing raised off the sample), capped:
    every kernel of it, without the fine band's (the child compiles those); and Lewiner's pass
    in runs of planes joined (render's, on threads)."""
    from surfgen.generator.eval.sparse import (
        BLOCK,
        SAMPLED,
        SparseField,
        brick_layout,
        leaf_counts,
    )
    from surfgen.generator.mesh.lewiner_chunks import lewiner_cells
    from surfgen.generator.mesh.sparse_marching import extract_sparse

    _, _, field = _tiny_shape("reference")
    values = _doctored(field.values)
    state = np.full(leaf_counts(field.grid), SAMPLED, dtype=np.int8)
    _, slot, corner, extent = brick_layout(state, field.grid, BLOCK)
    bricks = np.full((len(corner),) + (BLOCK + 1,) * 3, np.nan)
    for b, ((c0, c1, c2), (e0, e1, e2)) in enumerate(zip(corner, extent, strict=True)):
        bricks[b, :e0, :e1, :e2] = values[c0 : c0 + e0, c1 : c1 + e1, c2 : c2 + e2]
    sf = SparseField(field.grid, 0.0, BLOCK, state, slot, corner, extent, bricks)
    extract_sparse(sf, cap=True)
    # and on threads (render's): two cells on two planes, a run each, joined
    corners = np.ones((2, 8), dtype=np.float32)
    corners[:, 0] = -1.0
    lewiner_cells([np.array([0, 4], dtype=np.int64), corners], 2, 2, threads=2, min_cells=1)


def _warm_the_rest(field, box, mesh, tree) -> None:
    """Every kernel after the mesh and the walls, on the tiny shape."""
    _warm_measures(field, box, mesh, tree)
    _warm_rare_mesh(field)
    _warm_carving(field)
    _warm_extras(field, mesh)


def _warm_measures(
    field, box, mesh, tree, resolution: bool = True, descriptor: bool = True
) -> None:
    """The filters', (with ``descriptor``) the descriptor's and (with ``resolution``) the
    resolution check's kernels on the tiny shape; the warm-up's other child leaves both out
    (the first one compiles the descriptor, the fine band and the distances, this one the
    sparse marching)."""
    from surfgen.filters import descriptor as shape_descriptor
    from surfgen.filters.resolution import warm_kernels
    from surfgen.filters.shape import quality_metrics
    from surfgen.filters.verdict import quick_metrics, shape_metrics
    from surfgen.generator.mesh.outline import outline_fill

    quick = quick_metrics(mesh, box.bounds())
    quality_metrics(mesh, shape_metrics(mesh, box.bounds(), quick=quick))
    outline_fill(mesh)
    if descriptor:
        shape_descriptor.descriptor(mesh)
    if resolution:
        warm_kernels(tree, field, mesh)


def _warm_extras(field, mesh) -> None:
    """The pictures' and the infill's struts' kernels on the tiny shape (``mesh``: its
    surface). The workers' mesh files are PLY, which surfgen writes without trimesh
    (:func:`~surfgen.generator.mesh.exchange.ply_bytes`): nothing to load for them."""
    from surfgen.generator.model.ridges import ridge_distances
    from surfgen.pipelines.pictures.raster import render_image

    render_image(mesh, size=16)
    ridge_distances(field.values < 0.0, 2, 8)  # the infill's struts


def _warm_carving(field) -> None:
    """The carving's and the families' slopes' kernels on the tiny shape's samples."""
    from surfgen.generator.model.families.carving import envelope_departure, pieces
    from surfgen.generator.model.slope import gradient_norm

    # read-only fields (the sampler's) and a carved copy (the ornament checks'): two signatures
    envelope_departure(field.values, field.values)
    envelope_departure(field.values + 0.0, field.values)
    pieces(field.values)
    gradient_norm(field.values, 0.1)  # the families' slopes (of any samples: one signature)


def _warm_rare_mesh(field) -> None:
    """The mesh kernels only some shapes run: vertices of one grid edge given one index (a
    crossing on a box edge of a capped shape, an ambiguous cell), non-finite samples (a pole
    on a sample) given an offset from their neighbours, and a crossing a hair from its sample
    raised off it (the dense path's raises run only then); the warm ball has none of them."""
    from surfgen.generator.mesh.mesh import extract_with_edges
    from surfgen.generator.mesh.placement import merge_same, same_targets

    merge_same(
        np.zeros((3, 3)),
        np.array([[0, 1, 2]], dtype=np.int64),
        np.full((3, 4), -1, dtype=np.int64),
        np.arange(3),
    )
    # two cap copies on one box sample (moved) and a cell's centre on a crossing's edge
    same_targets(
        np.array([[-0.5, 1.0, 1.0], [1.0, -0.5, 1.0], [2.0, 1.5, 1.0], [2.0, 1.5, 1.0]],
                 dtype=np.float32),
        1.0,
        np.array([[-1, -1, -1, -1], [-1, -1, -1, -1], [1, 1, 0, 0], [1, 1, 0, 0]]),
        np.array([True, True, False, False]),
        np.array([3], dtype=np.int64),
        np.array([4, 4, 4], dtype=np.int64),
    )  # fmt: skip
    holed = _doctored(field.values)
    holed[7, 7, 7] = np.nan
    extract_with_edges(Field(field.grid, holed), 0.0, cap=True)  # read-only, as the sampler's
