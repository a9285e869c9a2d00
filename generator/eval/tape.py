"""The fast evaluator: compile a tree once (:mod:`.compiler`), run it with the numba interpreter
(:mod:`.grid_driver`) on any number of grids.

    program = compile_program(tree, params)                  # once per formula
    coarse = evaluate_program(program, coarse_grid)          # then any grid,
    fine = evaluate_program(program, fine_grid, threads=1)   # in a worker process: one thread

The only full-size array is the output; scratch is a few tiles per thread plus one (Ny, Nz)
plane per yz-level value that the per-point code reads. ``threads=1`` runs in the calling
thread (the sampler runs one process per core); more run the kernels in a pool of Python threads
for the call (they release the GIL); ``threads=None`` uses numba's default count
(``NUMBA_NUM_THREADS``, all cores).
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import os
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor, wait
from typing import TypeVar

import numba
import numpy as np
from llvmlite import binding

from surfgen.generator.errors import FormulaError
from surfgen.generator.eval import grid_driver as kernels
from surfgen.generator.eval import interpreter
from surfgen.generator.eval import point_driver as points
from surfgen.generator.eval.compiler import Program, compile_tree
from surfgen.generator.eval.grid import Box, Field, Grid
from surfgen.generator.eval.opcodes import M_S, M_SV, M_V, M_VS, M_VV, OP
from surfgen.generator.formula.expr import Expr
from surfgen.generator.formula.parser import parse

T = TypeVar("T")

log = logging.getLogger(__name__)


def tile_max(cpu_name: str) -> int:
    """Points per W row (several z rows when nz <= half of it) on the CPU LLVM calls
    ``cpu_name``. Any length gives the same bits (every operation is elementwise); the best
    one is the CPU's: ``benchmarks/tile_length.py`` (the 50 stored formulas at 128^3, one
    thread) put 512 at 1.017x the time of 1024 on an AMD Zen 5 (the n_vector rows stay in its
    L2 and a dispatch costs less per point), and 1024 at 1.07x the time of 512 on an Intel Xeon
    (Sapphire Rapids), where 384 and 512 were the fastest. AMD's Zen cores get 1024 (also the
    AVX2 Zen 3's, where 1024 meets the speed targets), every other CPU 512."""
    return 1024 if cpu_name.startswith("znver") else 512


def _host_cpu_name() -> str:
    return str(binding.get_host_cpu_name())


TILE_MAX = tile_max(_host_cpu_name())
CHUNKS_PER_THREAD = 4  # slabs per thread, for load balance when threads are shared
COMPILED_CACHE = 64  # programs kept by evaluate_fast, keyed by (tree, params)

compile_program = compile_tree
_NO_PROFILE = np.empty(0)


def evaluate_fast(
    tree: Expr,
    grid: Grid,
    params: Mapping[str, float] | None = None,
    threads: int | None = None,
) -> Field:
    """Sample ``tree`` on ``grid`` with the compiled interpreter; same values as the reference.

    Raises :class:`FormulaError` as :func:`surfgen.generator.eval.reference.evaluate_reference`
    does, and for a ``threads`` that is not a whole number >= 1.
    """
    return evaluate_program(_compiled(tree, tuple(sorted((params or {}).items()))), grid, threads)


def compile_cached(tree: Expr, params: Mapping[str, float] | None = None) -> Program:
    """:func:`compile_tree` through the evaluator's cache of recent programs (the sampler's
    resolution check evaluates the tree it has just evaluated on the coarse grid)."""
    return _compiled(tree, tuple(sorted((params or {}).items())))


@functools.lru_cache(maxsize=COMPILED_CACHE)
def _compiled(tree: Expr, params: tuple[tuple[str, float], ...]) -> Program:
    """Programs of recent trees: the sampler evaluates one tree on a coarse, then a fine grid."""
    return compile_tree(tree, dict(params))


def evaluate_program(program: Program, grid: Grid, threads: int | None = None) -> Field:
    """Run a compiled ``program`` on ``grid``; returns a read-only :class:`Field`."""
    if not isinstance(program, Program):
        raise TypeError(f"expected a Program, got {type(program).__name__}")
    if not isinstance(grid, Grid):
        raise TypeError(f"expected a Grid, got {type(grid).__name__}")
    return Field(grid, _run(program, grid, _resolve_threads(threads), _NO_PROFILE))


def _run(program: Program, grid: Grid, n_threads: int, prof: np.ndarray) -> np.ndarray:
    """The values of ``program`` on ``grid`` (``prof``: see :func:`.grid_driver.run_grid`)."""
    interpreter.load_interpreter()  # here, where an error can be raised (the kernels call it)
    ax, ay, az = grid.axes()
    out = np.empty(grid.shape, np.float64)
    tile = _tile(grid.shape[2])  # rows along z; x and y runs are cut to the same length
    prog = _prog(program, tile >= 2 * grid.shape[2])
    stores = kernels.grid_stores(prog[5], ax, ay, az)
    if n_threads == 1:
        kernels.run_grid(prog, tile, *stores, out, prof, kernels.GRID_ALL, 0, 0)
    else:
        _run_threads(prog, tile, stores, out, n_threads)
    return out


def _run_threads(prog: tuple, tile: int, stores: tuple, out: np.ndarray, n_threads: int) -> None:
    """:func:`.grid_driver.run_grid` on ``n_threads`` threads: the x, y, z blocks, then the yz
    plane's rows and the slabs of x indices in ``CHUNKS_PER_THREAD`` chunks per thread, on a
    pool of Python threads (the kernels release the GIL: ``nogil``)."""
    run = functools.partial(kernels.run_grid, prog, tile, *stores, out, _NO_PROFILE)
    run(kernels.GRID_XYZ_AXES, 0, 0)
    ny, nx = stores[1].shape[1], stores[0].shape[1]
    for part, size in (
        (kernels.GRID_YZ_ROWS, ny if prog[5][6] > 0 else 0),
        (kernels.GRID_SLAB, nx),
    ):
        chunks = min(n_threads * CHUNKS_PER_THREAD, size)
        # n_threads workers take the chunks in turn from one iterator (atomic under the GIL)
        todo = iter([(c * size // chunks, (c + 1) * size // chunks) for c in range(chunks)])

        def work(part=part, todo=todo) -> None:
            for lo, hi in todo:
                run(part, lo, hi)

        run_at_once([work] * min(n_threads, chunks))


def run_at_once(tasks: Sequence[Callable[[], T]]) -> list[T]:
    """Run ``tasks`` at once, the first in this thread, the others on the kept pool of threads
    (for kernels that release the GIL); returns their results in order. Raises the first
    failure once every task has stopped: none is left writing into shared arrays."""
    # the calling thread works too: it starts at once, while a pool thread may take a
    # millisecond to wake (an idle vCPU of a virtual machine)
    if not tasks:
        return []
    helpers = [_pool(len(tasks)).submit(task) for task in tasks[1:]]
    try:
        first = tasks[0]()
    finally:
        wait(helpers)
    return [first, *(future.result() for future in helpers)]


_POOL: dict[int, ThreadPoolExecutor] = {}  # {helper threads: pool}, at most one, made on first use
_POOL_LOCK = threading.Lock()


def _pool(n_threads: int) -> ThreadPoolExecutor:
    """A pool of at least ``n_threads - 1`` threads (the caller works too), kept between calls
    (a pool made per call costs a millisecond or two, a third of a 128^3 evaluation on two
    threads)."""
    helpers = max(1, n_threads - 1)
    with _POOL_LOCK:
        if not _POOL or max(_POOL) < helpers:
            # a smaller pool still in use by another call keeps running; its threads end when
            # the last reference to it goes (ThreadPoolExecutor's workers watch it by weakref)
            _POOL.clear()
            _POOL[helpers] = ThreadPoolExecutor(helpers, thread_name_prefix="surfgen-eval")
        return next(iter(_POOL.values()))


def _forget_pool() -> None:
    """In a forked child the pool's threads do not exist: make a new pool when asked."""
    global _POOL_LOCK
    _POOL.clear()
    _POOL_LOCK = threading.Lock()


os.register_at_fork(after_in_child=_forget_pool)


def warm_up(parallel: bool = True) -> float:
    """Load (or compile, the first time) the interpreter; returns the seconds it took.
    ``parallel``: also run it once on two threads (the same compiled kernel: this only makes
    the pool of threads)."""
    t0 = time.perf_counter()
    grid = Grid(Box.cube(1.0), (4, 4, 4))
    program = compile_tree(_WARM_TREE)
    evaluate_program(program, grid, threads=1)
    if parallel and numba.config.NUMBA_NUM_THREADS > 1:
        evaluate_program(program, grid, threads=2)
    seconds = time.perf_counter() - t0
    log.debug("fast evaluator ready in %.2f s (threads too: %s)", seconds, parallel)
    return seconds


@contextlib.contextmanager
def compiled_not_run(*others: tuple[object, str]) -> Iterator[None]:
    """Within the block the interpreter is not loaded, and the grid kernels (the grid's and the
    bricks', :func:`.grid_driver.run_columns`) and each ``(module, name)`` numba dispatcher of
    ``others`` (kernels of other layers that call the interpreter: the walls') are compiled (or
    loaded from numba's cache) for the types of the arguments they are called with, not run: a
    call returns 0 and writes nothing. A kernel's compile needs only the interpreter's calling
    convention (:func:`surfgen.generator.eval.interpreter.run_code_far`), not its code."""

    sites = ((kernels, "run_grid"), (kernels, "run_columns"), *others)
    originals = {(module, name): getattr(module, name) for module, name in sites}

    def put(stand_ins: bool) -> None:
        for (module, name), dispatcher in originals.items():
            setattr(module, name, compiling(dispatcher) if stand_ins else dispatcher)

    def compiling(dispatcher):
        def compile_for(*args):
            put(False)  # a kernel that calls another (run_columns: run_grid) compiles the real one
            try:
                dispatcher.compile(tuple(numba.typeof(a) for a in args))
            finally:
                put(True)
            return 0

        return compile_for

    load = interpreter.load_interpreter
    try:
        put(True)
        interpreter.load_interpreter = lambda: None
        yield
    finally:
        interpreter.load_interpreter = load
        put(False)


def warm_interpreter() -> float:
    """Load (or compile) the tape interpreter itself (:func:`interpreter.load_interpreter`, with
    every elementary function), without a kernel around it; returns the seconds it took. The
    first time on a machine that is most of the compiling a shape needs, and nothing else needs
    it compiled first: the sampler's warm-up runs this while another process compiles the
    kernels that call it."""
    t0 = time.perf_counter()
    interpreter.load_interpreter()
    return time.perf_counter() - t0


def _resolve_threads(threads: int | None) -> int:
    limit = numba.config.NUMBA_NUM_THREADS  # read, never numba.get_num_threads(): that call
    if threads is None:  # starts numba's own thread pool (TBB first, too old beside pymeshlab)
        return limit
    if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
        raise FormulaError(f"threads must be a whole number >= 1, got {threads!r}")
    return min(int(threads), limit)


def _tile(n: int) -> int:
    """Tile length for runs of up to n points along z: at most TILE_MAX, equal chunks; for
    short runs (n <= TILE_MAX/2) as many whole runs as fit, which the yz and xyz blocks fill
    with several rows j at once (fewer dispatches per point; see kernels._block)."""
    if 0 < n <= TILE_MAX // 2:
        return (TILE_MAX // n) * n
    pieces = math.ceil(n / TILE_MAX)
    return max(1, math.ceil(n / pieces))


def scratch_bytes(program: Program, grid: Grid, threads: int = 1) -> int:
    """Bytes the interpreter allocates besides the output field (Nx*Ny*Nz*8 bytes): the x, y,
    z and yz stores, and per thread the register file and the xy and xz rows."""
    nx, ny, nz = grid.shape
    r = program.rows
    tile = _tile(nz)
    shared = r[1] * nx + r[2] * ny + r[4] * nz + r[6] * ny * nz
    per_thread = (
        (_prog(program, tile >= 2 * nz)[6] + 2) * tile + program.n_scalar + r[3] * ny + r[5] * nz
    )
    return int(8 * (shared + max(1, threads) * per_thread))


def _prog(program: Program, rows: bool = False) -> tuple:
    """The tuple the kernels take; ``rows``: the program rewritten for tiles of several rows j
    (:func:`rows_program`)."""
    if rows:
        return rows_program(program)
    return (
        program.code,
        program.blocks,
        program.loads,
        program.stores,
        program.consts,
        program.rows,
        program.n_vector,
        program.n_scalar,
    )


@functools.lru_cache(maxsize=COMPILED_CACHE)
def rows_program(program: Program) -> tuple:
    """The kernels' tuple of ``program`` for tiles of several rows j (kernels._block_rows).

    In the yz and xyz blocks a y or xy value is one scalar per row j, loaded into an S slot; a
    tile of several rows needs it as a vector instead. Each such load becomes a W row filled
    per row j (load kinds 2 and 3 with vector = 1), and the instructions that read the slot read
    that row: ``op(W, S)`` -> ``op(W, W)`` and ``op(S, W)`` -> ``op(W, W)`` with the operands in
    the same order, ``W = S`` -> a copy. Every operation computes the same function of the same
    values elementwise (the row functions and scalar ones share their code), so the bits are
    those of the original program. A block that is a single copy (a broadcast root) is kept.
    """
    code = program.code.copy()
    loads = program.loads.copy()
    nv = program.n_vector
    for lv in (6, 7):
        c0, c1, l0, l1 = (int(v) for v in program.blocks[lv, :4])
        if c1 - c0 == 1 and code[c0, 0] == OP["copy"]:
            continue
        slot_row: dict[int, int] = {}
        for q in range(l0, l1):
            kind, row, slot, vec = (int(v) for v in loads[q])
            if vec == 0 and kind in (2, 3):
                slot_row[slot] = nv
                loads[q] = (kind, row, nv, 1)
                nv += 1
        for pc in range(c0, c1):
            mode, a, b = int(code[pc, 1]), int(code[pc, 3]), int(code[pc, 4])
            if mode == M_VS and b in slot_row:
                code[pc, 1], code[pc, 4] = M_VV, slot_row[b]
            elif mode == M_SV and a in slot_row:
                code[pc, 1], code[pc, 3] = M_VV, slot_row[a]
            elif mode == M_S and a in slot_row:
                code[pc] = (OP["copy"], M_V, code[pc, 2], slot_row[a], 0, 0)
    for a in (code, loads):
        a.flags.writeable = False
    return (
        code,
        program.blocks,
        loads,
        program.stores,
        program.consts,
        program.rows,
        nv,
        program.n_scalar,
    )


def evaluate_columns(
    program: Program,
    axes: tuple[np.ndarray, np.ndarray, np.ndarray],
    members: np.ndarray,
    corner: np.ndarray,
    extent: np.ndarray,
    values: np.ndarray,
    threads: int = 1,
    then: Callable[[int, int], T] | None = None,
) -> list[T]:
    """Fill the bricks ``members`` of ``values`` (``values[b, :nx, :ny, :nz]``: ``extent[b]``
    points from grid index ``corner[b]``; ``members`` ordered by corner, x then y then z)
    a group of columns at a time: a column is a run of members with the same x and y corner,
    and neighbouring columns along y are grouped where one grid for them costs less than a
    grid each (:func:`.grid_driver.column_groups`: a grid's fixed cost is that of
    :data:`~.grid_driver.COLUMN_COST_POINTS` points; sculpture-1's 2187 columns at 512^3 in
    343 groups, 48 -> 15 ms on 2 threads). A group is run as a grid of its own
    (:func:`.grid_driver.run_columns`) on its x points, its y points and the union of its
    bricks' z points: each point's value is the one a grid with the same coordinates gives,
    bit for bit (every operation is elementwise). ``threads`` take contiguous runs of groups
    of about equal points. ``then(m0, m1)``: called by each thread on the members ``m0:m1`` it
    filled, once they are (while they are in its cache); returns its results in the runs'
    order (none without ``then``)."""
    interpreter.load_interpreter()
    if len(members) == 0:
        return []
    members = np.ascontiguousarray(members, dtype=np.int64)
    groups = kernels.column_groups(
        members, corner, extent, kernels.COLUMN_COST_POINTS, kernels.GROUP_POINTS
    )
    ax, ay, az = (np.ascontiguousarray(a, dtype=np.float64).reshape(-1) for a in axes)
    plain, rows = _prog(program, False), _prog(program, True)

    def run(c0: int, c1: int) -> list[T]:
        kernels.run_columns(
            plain, rows, TILE_MAX, ax, ay, az, groups[c0:c1], members, corner, extent, values
        )
        return [] if then is None else [then(int(groups[c0, 0]), int(groups[c1 - 1, 1]))]

    n = max(1, min(int(threads), len(groups)))
    if n == 1:
        return run(0, len(groups))
    points = np.cumsum(np.add.reduceat(np.prod(extent[members], axis=1), groups[:, 0]))
    bounds = [0, *np.searchsorted(points, points[-1] * np.arange(1, n) / n).tolist(), len(groups)]
    runs = [(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True) if b > a]
    return [
        r for part in run_at_once([functools.partial(run, a, b) for a, b in runs]) for r in part
    ]


def profile_program(program: Program, grid: Grid) -> tuple[Field, np.ndarray]:
    """Run ``program`` on one thread counting CPU cycles per code row.

    Returns the field and a float64 array with the cycles of each row of ``program.code``
    (for benchmarks and for finding where the time goes; slower than a plain run).
    """
    prof = np.zeros(len(program.code))
    return Field(grid, _run(program, grid, 1, prof)), prof


POINTS_TILE = 256  # points per W row of the points kernel


def points_program(program: Program) -> tuple:
    """``program`` rewritten for :func:`.point_driver.run_points`: every block runs along a list of
    points instead of a grid axis.

    On a grid, a value that does not vary along a block's run axis is a row scalar (an S slot,
    operand modes ``vs``, ``sv`` and ``s``); along points every value varies, so S slot ``s``
    becomes W row ``n_vector + s`` and those operations their ``vv`` and ``v`` forms (the same
    scalar operation per element: the rows of :mod:`~surfgen.generator.elementary` are one
    scalar function in a loop, and the ``x^c`` convention is applied per element in both).
    """
    nv = int(program.n_vector)
    code = np.array(program.code, dtype=np.int64)
    mode = code[:, 1].copy()
    vs, sv, s = mode == M_VS, mode == M_SV, mode == M_S
    code[vs, 1] = M_VV
    code[vs, 4] += nv
    code[sv, 1] = M_VV
    code[sv, 3] += nv
    code[s, 1] = M_V  # the only M_S operation is copy
    code[s, 3] += nv
    loads = np.array(program.loads, dtype=np.int64)
    scalar = loads[:, 3] == 0
    loads[scalar, 2] += nv
    # read-only, as on a grid: the points kernels then call the interpreter with the grid
    # kernel's argument types, and numba compiles (and caches) one interpreter for both
    for a in (code, loads):
        a.flags.writeable = False
    return (
        code,
        np.ascontiguousarray(program.blocks),
        loads,
        np.ascontiguousarray(program.stores),
        np.ascontiguousarray(program.consts),
        np.ascontiguousarray(program.rows),
        nv + max(1, int(program.n_scalar)),
    )


class PointsEvaluator:
    """A compiled formula evaluated at arbitrary points (numba, one thread).

    ``PointsEvaluator(program)(x, y, z)`` returns F at ``(x[i], y[i], z[i])``: the values
    :func:`evaluate_program` gives at grid points, and the reference's
    (:func:`surfgen.generator.eval.reference.evaluate_points`), bit for bit.  Each level of the
    program is evaluated once per distinct value it needs (:meth:`_lattice`); :meth:`plain`
    evaluates every level at every point.
    """

    def __init__(self, program: Program) -> None:
        if not isinstance(program, Program):
            raise TypeError(f"expected a Program, got {type(program).__name__}")
        if np.any(program.code[:, 1] == M_S) and not np.all(
            program.code[program.code[:, 1] == M_S, 0] == OP["copy"]
        ):
            raise AssertionError("a scalar-mode operation other than copy")  # pragma: no cover
        self.program = program
        self._prog = points_program(program)
        self._active = np.ascontiguousarray(program.blocks[:, 1] > program.blocks[:, 0])
        self._rows = np.ascontiguousarray(program.rows, dtype=np.int64)

    def __call__(self, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
        """F at the points ``(x[i], y[i], z[i])`` (1-D arrays of one length), float64."""
        px = np.ascontiguousarray(x, dtype=np.float64).reshape(-1)
        py = np.ascontiguousarray(y, dtype=np.float64).reshape(-1)
        pz = np.ascontiguousarray(z, dtype=np.float64).reshape(-1)
        if not (px.size == py.size == pz.size):
            raise ValueError(f"x, y, z differ in length: {px.size}, {py.size}, {pz.size}")
        out = np.empty(px.size, dtype=np.float64)
        if px.size:
            interpreter.load_interpreter()
            self._lattice(px, py, pz, out)
        return out

    def plain(self, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
        """The same values, every level computed at every point (:func:`.point_driver.run_points`,
        no sharing): the check of :meth:`__call__`'s sharing."""
        px, py, pz = (np.ascontiguousarray(a, dtype=np.float64).reshape(-1) for a in (x, y, z))
        out = np.empty(px.size, dtype=np.float64)
        if px.size:
            interpreter.load_interpreter()
            points.run_points(self._prog, POINTS_TILE, px, py, pz, out)
        return out

    def kernel_args(self) -> tuple:
        """``(prog, tile, active, rows)``: what :func:`.point_driver.eval_points` takes before the
        points, for numba code that evaluates the formula itself (the walls' classification).
        Loads the interpreter that code calls."""
        interpreter.load_interpreter()
        return self._prog, POINTS_TILE, self._active, self._rows

    def _lattice(self, px: np.ndarray, py: np.ndarray, pz: np.ndarray, out: np.ndarray) -> None:
        """Evaluate each level once per distinct value it needs (:func:`.point_driver.eval_points`
        plans the lattice and runs :func:`.point_driver.run_lattice`).

        Points on grid lines (the walls' refinement) share most coordinates: a level of x and y
        alone is computed once per distinct (x, y) pair, not once per point.  Coordinates are
        told apart by their bits (-0.0 and +0.0 are distinct), so every entry is computed from
        exactly the bits of its points.
        """
        points.eval_points(self._prog, POINTS_TILE, self._active, self._rows, px, py, pz, out)


def points_evaluator(tree: Expr, params: Mapping[str, float] | None = None) -> PointsEvaluator:
    """A :class:`PointsEvaluator` of ``tree`` (compiled programs are shared with
    :func:`evaluate_fast`; evaluators of recent trees are kept, as the walls' classification
    asks for one per mesh). Raises :class:`FormulaError` as :func:`compile_tree` does."""
    return _points_evaluator(tree, tuple(sorted((params or {}).items())))


def evaluate_points(
    tree: Expr,
    x: np.ndarray | float,
    y: np.ndarray | float,
    z: np.ndarray | float,
    params: Mapping[str, float] | None = None,
) -> np.ndarray:
    """``tree`` at the points ``(x, y, z)`` (broadcast together), float64: the values of
    :func:`surfgen.generator.eval.reference.evaluate_points`, bit for bit (a
    :class:`PointsEvaluator`)."""
    bx, by, bz = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (x, y, z)))
    out = points_evaluator(tree, params)(bx.reshape(-1), by.reshape(-1), bz.reshape(-1))
    return out.reshape(bx.shape)


@functools.lru_cache(maxsize=COMPILED_CACHE)
def _points_evaluator(tree: Expr, params: tuple[tuple[str, float], ...]) -> PointsEvaluator:
    return PointsEvaluator(_compiled(tree, params))


_WARM_TREE = parse("x*y+z^2")
