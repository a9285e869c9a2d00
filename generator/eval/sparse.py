"""Sparse evaluation: sample a formula only in the blocks of the grid the surface may cross.

The grid's cells are split into cubic *leaf blocks* of :data:`BLOCK` cells a side.  Coarse to
fine (:func:`~surfgen.generator.eval.leaf_states.classify_blocks`), blocks of ``BLOCK * 2**l``
cells are bounded with interval arithmetic over the block's grid points
(:func:`~surfgen.generator.eval.intervals.grid_point_bounds`: a value of one axis, such as
``tan(m x)``, by its values at the block's coordinates on that axis, so a pole between two
samples does not make the block's bounds infinite): a block whose bounds lie above the
level is *outside* (every sample is above the level or non-finite, which meshing counts as
outside), one whose bounds are finite and below the level is *inside*; the others are split
in eight and bounded again, down to the leaves.  Only the leaves left uncertain are *sampled*:
their ``(BLOCK + 1)**3`` grid points (the points of the neighbouring blocks' shared faces
included, so a leaf's cells have all their corners) are evaluated with the fast evaluator's grid kernel on those coordinates
(:func:`~surfgen.generator.eval.tape.evaluate_columns`), bit for bit the dense grid's values.
A sampled leaf whose samples then all lie on one side is decided as the bounds would have
decided it, and its brick dropped (:func:`_sample_and_decide`): the bricks kept are the leaves
the surface crosses (and, for caps, the inside ones on the box's faces).

A cell lies in exactly one leaf, and its corners in that leaf's closed box: a cell whose corners
are not all on one side lies in a sampled leaf.  So the sampled leaves hold every crossing, and
the signs of every other sample are known from its leaf's state.  :class:`SparseField` holds the
states, the sampled bricks and a lookup of any sampled grid point
(:func:`~.brick_lookup.sample_at`); the sparse meshing
(:mod:`surfgen.generator.mesh.sparse_marching`) works on it, and where its caller keeps only
the mesh, frees the bricks' samples as soon as it has read them
(:meth:`SparseField.release_samples`).  ``faces=True`` also samples the inside leaves on the
box's faces: a capped mesh closes the surface there with caps, whose vertices need those
samples.
"""

from __future__ import annotations

import functools
import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numba
import numpy as np
from numba import njit

from surfgen.generator.allocator import scratch_kept
from surfgen.generator.eval.brick_lookup import locate, sampled_at, values_at
from surfgen.generator.eval.compiler import Program, compile_tree
from surfgen.generator.eval.grid import Field, Grid
from surfgen.generator.eval.interval_poly import polynomial_bounds, polynomial_structure
from surfgen.generator.eval.interval_regroup import regroup, regrouped_bounds
from surfgen.generator.eval.intervals import grid_point_bounds
from surfgen.generator.eval.leaf_states import (
    INSIDE,
    OUTSIDE,
    SAMPLED,
    Bounds,
    classify_blocks,
    sampled_blocks,
)
from surfgen.generator.eval.tape import evaluate_columns, evaluate_points, run_at_once
from surfgen.generator.formula.expr import Expr
from surfgen.generator.formula.limits import MemoryBudget, check_step
from surfgen.generator.jit.options import INLINE, KERNEL

log = logging.getLogger(__name__)

#: Cells per side of a leaf block.  8 measured best at 256-1024 (benchmarks/bench_sparse.py):
#: 4 bounds four times as many boxes and evaluates 125/64 points per cell; 16 samples
#: ~2x more cells around the surface.
BLOCK = 8
#: The largest leaf: the meshing reads a brick's rows of ``block + 1`` samples as the bits
#: of an int64 (:func:`surfgen.generator.mesh.sparse_bricks._row_mask`).
MAX_BLOCK = 62
#: Bricks sampled at a time (23 MiB of samples at ``BLOCK`` 8) before the one-sided ones are
#: dropped: a bound that leaves many leaves to sample costs their time, not their memory.
CHUNK_BRICKS = 4096

# A brick's samples (:func:`_sides`): all outside, all inside, or both sides.
_ALL_OUTSIDE, _ALL_INSIDE, _MIXED = 0, 1, 2

__all__ = [
    "SparseField",
    "evaluate_points",
    "evaluate_sparse",
    "evaluate_sparse_program",
]


@dataclass(frozen=True, eq=False)
class SparseField:
    """A formula sampled where its level set may pass (see the module's docstring).

    ``state``: int8 per leaf block (:data:`OUTSIDE`, :data:`INSIDE`, :data:`SAMPLED`);
    ``slot``: the brick of each sampled leaf (-1 otherwise); ``corner``: ``(K, 3)`` first grid
    index of each brick; ``values``: ``(K, B+1, B+1, B+1)`` samples of each brick (entries past
    the grid's last point are NaN and never read); ``extent``: ``(K, 3)`` points of each brick
    per axis.  ``level`` is the level the states refer to.  ``stats``: boxes bounded, points
    evaluated, non-finite samples, seconds.  ``values`` is None once the samples are released
    (:meth:`release_samples`): what was counted stays, what reads samples raises.
    """

    grid: Grid
    level: float
    block: int
    state: np.ndarray
    slot: np.ndarray
    corner: np.ndarray
    extent: np.ndarray
    values: np.ndarray | None
    stats: dict[str, float] = field(default_factory=dict)

    @property
    def released(self) -> bool:
        """Whether the samples were released (:meth:`release_samples`)."""
        return self.values is None

    def release_samples(self) -> None:
        """Free the bricks' samples, most of a fine field's memory, once nothing will read
        them (the sparse meshing does, where its caller keeps only the mesh:
        ``realise(..., keep_samples=False)``).  The states, the bricks' layout and ``stats``
        stay; reading samples afterwards raises ``RuntimeError``."""
        if "nonfinite" not in self.stats:  # counted now: nothing can count it later
            self.stats["nonfinite"] = self.nonfinite
        object.__setattr__(self, "values", None)  # frozen: the one field that may go

    def samples(self) -> np.ndarray:
        """The bricks' samples, ``(K, B+1, B+1, B+1)``; raises ``RuntimeError`` once released."""
        if self.values is None:
            raise RuntimeError(
                "this sparse field's samples were released after meshing "
                "(realise(..., keep_samples=True) keeps them)"
            )
        return self.values

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.grid.shape

    @property
    def n_bricks(self) -> int:
        return int(self.corner.shape[0])

    @property
    def points_evaluated(self) -> int:
        """Grid points evaluated (shared faces of neighbouring bricks once per brick): those of
        the bricks dropped after sampling too (:func:`_sample_and_decide`)."""
        if "points" in self.stats:
            return int(self.stats["points"])
        return int(np.prod(self.extent, axis=1).sum()) if self.n_bricks else 0

    @property
    def share(self) -> float:
        """Points evaluated per grid point (1.0 = as many as the dense grid)."""
        return self.points_evaluated / self.grid.size

    @property
    def nbytes(self) -> int:
        held = 0 if self.values is None else self.values.nbytes
        return int(held + self.state.nbytes + self.slot.nbytes)

    @property
    def nonfinite(self) -> int:
        """How many of the sampled points are NaN or infinite (each grid point once; the
        skipped blocks' samples are not known; those of bricks dropped after sampling are
        counted, :func:`_sample_and_decide`)."""
        if "nonfinite" in self.stats:
            return int(self.stats["nonfinite"])
        sides = np.empty(self.n_bricks, dtype=np.int8)  # what _sides also tells; unused here
        args = (self.samples(), self.extent, self.corner, self.slot, self.block, 0, self.level)
        return int(_sides(*args, sides, 0, self.n_bricks))

    def sign_proxy(self) -> Field:
        """A dense :class:`Field` with F where sampled, and in the skipped leaves a value of
        the leaf's side: +inf (outside) or ``level - max(1, |level| / 2)`` (inside: finite,
        and far enough below the level that an interpolation keeps the sign).  Every
        grid cell lies in one leaf, so whatever reads a cell's corners for their sides, or
        interpolates within a cell and compares with the level, reads it as from the dense
        field (the sweep's inside-sample comparisons)."""
        values = np.empty(self.grid.shape)
        below = self.level - max(1.0, abs(self.level) / 2)
        _fill_proxy(values, self.state, self.block, below, self.samples(), self.corner,
                    self.extent)  # fmt: skip
        return Field(self.grid, values)

    def any_inside(self) -> bool:
        """Whether some sample is inside (``F < level``, finite)."""
        if np.any(self.state == INSIDE):
            return True
        return bool(_bricks_count_inside(self.samples(), self.extent, self.level) > 0)

    def all_inside(self) -> bool:
        """Whether every sample is inside: no leaf outside, and every sample of the bricks kept
        (not :attr:`points_evaluated`, which counts the one-sided bricks dropped after
        sampling too: their leaves' states tell their side)."""
        if np.any(self.state == OUTSIDE):
            return False
        kept = int(np.prod(self.extent, axis=1).sum()) if self.n_bricks else 0
        return bool(_bricks_count_inside(self.samples(), self.extent, self.level) == kept)

    def lookup(self) -> tuple:
        """What :func:`sample_at` takes after the index: ``(slot, corner, values, block)``."""
        return self.slot, self.corner, self.samples(), self.block

    def values_at(self, i: np.ndarray, j: np.ndarray, k: np.ndarray) -> np.ndarray:
        """F at grid indices ``(i, j, k)`` where sampled; NaN where not
        (:func:`~.brick_lookup.sample_at`)."""
        ii, jj, kk = (np.ascontiguousarray(a, dtype=np.int64).reshape(-1) for a in (i, j, k))
        out = np.empty(ii.size)
        values_at(ii, jj, kk, *self.lookup(), out)
        return out

    def sampled_at(self, i: np.ndarray, j: np.ndarray, k: np.ndarray) -> np.ndarray:
        """Whether the grid points ``(i, j, k)`` lie in a sampled brick."""
        ii, jj, kk = (np.ascontiguousarray(a, dtype=np.int64).reshape(-1) for a in (i, j, k))
        out = np.empty(ii.size, dtype=np.bool_)
        sampled_at(ii, jj, kk, self.slot, self.block, out)
        return out


def leaf_counts(grid: Grid, block: int = BLOCK) -> tuple[int, int, int]:
    """Leaf blocks per axis: ``ceil((N - 1) / block)``."""
    return tuple(-(-(n - 1) // block) for n in grid.shape)  # type: ignore[return-value]


def evaluate_sparse(
    tree: Expr,
    grid: Grid,
    params: Mapping[str, float] | None = None,
    threads: int | None = None,
    level: float = 0.0,
    faces: bool = False,
    block: int = BLOCK,
    bounds: Bounds | None = None,
    budget: MemoryBudget | None = None,
    progress: Callable[[float], None] | None = None,
) -> SparseField:
    """Sample ``tree`` on ``grid`` where ``F = level`` may pass (the module's docstring).

    ``faces``: also sample the inside leaves on the box's faces (for capped meshes);
    ``threads``: threads evaluating bricks (None: numba's count); ``bounds``: the interval
    bounds (None: over the grid's points,
    :func:`~surfgen.generator.eval.intervals.grid_point_bounds`, tightened where the formula
    holds a power of a sum multiplied out or a maximum written through ``|·|``,
    :mod:`~.interval_regroup`, or else expanded polynomials, :mod:`~.interval_poly`;
    :func:`~surfgen.generator.eval.intervals.program_bounds` bounds whole boxes); ``budget``: refuse (a
    ``LimitError``) a run of leaves whose samples would take the command past its memory limit,
    before it is sampled; ``progress``: called with the share of the leaves sampled after each
    run of them.
    Raises ``FormulaError`` as compiling the formula does.
    """
    program = compile_tree(tree, dict(params or {}))
    if bounds is None:
        bounds = grid_point_bounds(grid.axes(), thread_count(threads))
        if (regrouped := regroup(tree)) is not None:
            bounds = regrouped_bounds(
                bounds, program, regrouped, params, float(level), thread_count(threads)
            )
        elif (structure := polynomial_structure(tree)) is not None:
            bounds = polynomial_bounds(
                bounds, program, structure, float(level), params, thread_count(threads)
            )
    return evaluate_sparse_program(
        program, grid, threads, level, faces, block, bounds, budget, progress
    )


def evaluate_sparse_program(
    program: Program,
    grid: Grid,
    threads: int | None = None,
    level: float = 0.0,
    faces: bool = False,
    block: int = BLOCK,
    bounds: Bounds | None = None,
    budget: MemoryBudget | None = None,
    progress: Callable[[float], None] | None = None,
) -> SparseField:
    """:func:`evaluate_sparse` of a compiled program."""
    if int(block) != block or not 1 <= block <= MAX_BLOCK:
        raise ValueError(f"block must be a whole number from 1 to {MAX_BLOCK}, got {block!r}")
    t0 = time.perf_counter()
    axes = grid.axes()
    if bounds is None:
        bounds = grid_point_bounds(axes, thread_count(threads))
    with scratch_kept():
        state, boxes = classify_blocks(program, grid, axes, float(level), block, bounds)
    if faces:
        sample_face_leaves(state)
    t1 = time.perf_counter()
    leaves, slot, corner, extent = brick_layout(state, grid, block)
    sampled, points = len(leaves), int(np.prod(extent, axis=1).sum())
    values, sides, keep, nonfinite = _sample_and_decide(
        program, axes, state.shape, leaves, slot, corner, extent, block, float(level), faces,
        threads, budget, progress,
    )  # fmt: skip
    t2 = time.perf_counter()
    if not keep.all():  # the one-sided leaves decided, the layout of the bricks kept
        decided = np.where(sides == _ALL_INSIDE, INSIDE, OUTSIDE).astype(np.int8)
        state[tuple(leaves.T)] = np.where(keep, SAMPLED, decided)
        leaves, slot, corner, extent = brick_layout(state, grid, block)
    sf = SparseField(grid, float(level), int(block), state, slot, corner, extent, values)
    sf.stats.update(
        boxes=boxes,
        points=points,
        share=points / grid.size,
        nonfinite=nonfinite,
        sampled_leaves=sampled,
        bound_seconds=t1 - t0,
        sample_seconds=t2 - t1,
    )
    log.debug(
        "sparse: %d boxes bounded, %d of %d leaves sampled (%d kept), %.3g of the grid's points",
        boxes,
        sampled,
        state.size,
        sf.n_bricks,
        sf.share,
    )
    return sf


def _shrunk(held: list[np.ndarray], n: int) -> np.ndarray:
    """The first ``n`` bricks of the array in ``held`` (taken out of it): the array itself,
    resized in place where nothing else holds it (the allocator gives the rest back), else a
    copy."""
    values = held.pop()
    try:
        values.resize((n,) + values.shape[1:])
        return values
    except (ValueError, SystemError):  # referenced elsewhere or not its own memory
        return values[:n].copy()


def thread_count(threads: int | None) -> int:
    """Threads for ``threads`` (None: numba's count, which the evaluator uses too)."""
    if threads is None:
        return int(numba.config.NUMBA_NUM_THREADS)
    return max(1, int(threads))


# ----------------------------------------------------------------------------- the leaves


def brick_layout(
    state: np.ndarray, grid: Grid, block: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Where the sampled leaves' bricks go: the leaves in C order ``(K, 3)``, each leaf's
    brick number (``slot``, -1 where not sampled), the bricks' first grid indices
    (``corner``) and their points per axis (``extent``), as :class:`SparseField` holds them.
    All C-contiguous whatever the count (:func:`~.leaf_states.sampled_blocks`; ``np.argwhere``
    gives a transposed array for two leaves or more), so the kernels that read them are
    compiled for one layout."""
    leaves, slot = sampled_blocks(state)
    corner = leaves * block
    extent = np.minimum(block + 1, np.asarray(grid.shape, dtype=np.int64)[None, :] - corner)
    return leaves, slot, corner, extent


def sample_face_leaves(state: np.ndarray) -> None:
    """Sample the inside leaves on the box's faces (in place): a capped mesh closes the
    surface there, with caps whose vertices need those samples."""
    for axis in range(3):
        for end in (0, state.shape[axis] - 1):
            face = state[(slice(None),) * axis + (end,)]  # a view of the face
            face[face == INSIDE] = SAMPLED


# ----------------------------------------------------------------------------- the bricks


def _sample_and_decide(
    program: Program,
    axes: tuple[np.ndarray, np.ndarray, np.ndarray],
    leaf_shape: tuple[int, ...],
    leaves: np.ndarray,
    slot: np.ndarray,
    corner: np.ndarray,
    extent: np.ndarray,
    block: int,
    level: float,
    faces: bool,
    threads: int | None,
    budget: MemoryBudget | None = None,
    progress: Callable[[float], None] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """F at the sampled leaves' bricks, :data:`CHUNK_BRICKS` at a time, each run's one-sided
    bricks dropped before the next is sampled (:func:`evaluate_sparse_program`): returns the
    samples of the bricks kept (in order), each brick's side (:func:`_sides`), which were kept
    and the non-finite samples of them all, each grid point once (``leaves``, ``slot``: the
    layout before any is dropped). A run is evaluated in place after the bricks kept so far, so the array's
    pages are touched only as far as they hold the bricks kept and one run; it is then shrunk.

    Per column of leaves (one x and y block) the grid kernel runs once on the union of the
    column's z points, and the values are scattered to the bricks, all of a run's columns in
    one kernel call per thread (:func:`~surfgen.generator.eval.tape.evaluate_columns`; a call
    per column from Python, on a pool of threads, spent more time in Python than in the
    kernel: 4-6x slower), each thread then deciding the sides of the bricks it filled
    (:func:`_sides`). ``budget``: each run's samples are checked against it before they are
    written (the array is reserved, not touched, whole); ``progress``: called with the share
    of the bricks sampled after each run."""
    n = len(corner)
    values = np.empty((n, block + 1, block + 1, block + 1))
    brick_bytes = values.itemsize * (block + 1) ** 3
    sides = np.empty(n, dtype=np.int8)
    keep = np.empty(n, dtype=np.bool_)
    top = np.asarray(leaf_shape, dtype=np.int64) - 1
    on_face = np.any((leaves == 0) | (leaves == top[None, :]), axis=1)
    workers = thread_count(threads)
    rows = nonfinite = 0
    run = decide = None
    with scratch_kept():  # the columns' temporaries reused, not mapped afresh for each
        for c0 in range(0, n, CHUNK_BRICKS):
            c1 = min(n, c0 + CHUNK_BRICKS)
            check_step(budget, (c1 - c0) * brick_bytes,
                       f"sampling the {n:,} leaves the surface may cross")  # fmt: skip
            run, ext, at = values[rows : rows + c1 - c0], extent[c0:c1], corner[c0:c1]
            run[np.flatnonzero(np.any(ext <= block, axis=1))] = np.nan  # past the grid: defined
            decide = functools.partial(_sides, run, ext, at, slot, block, c0, level, sides[c0:c1])
            bad = evaluate_columns(program, axes, np.arange(c1 - c0), at, ext, run, workers, decide)
            nonfinite += sum(bad)
            kept = sides[c0:c1] == _MIXED
            if faces:  # a cap's vertices need the inside samples on the box's faces
                kept |= (sides[c0:c1] == _ALL_INSIDE) & on_face[c0:c1]
            keep[c0:c1] = kept
            rows += moved_down(run, np.flatnonzero(kept), workers)
            if progress is not None:
                progress(c1 / n)
    held = [values]
    del run, decide, values  # no other reference: the array can then be resized in place
    return _shrunk(held, rows), sides, keep, int(nonfinite)


@njit(**KERNEL)
def _sides(values, extent, corner, slot, block, first, level, out, b0, b1):
    """Bricks ``b0:b1``'s sides into ``out``: all its samples outside the level (above it or
    non-finite), all inside (finite, below it) or both; returns their non-finite samples, each
    counted in the brick :func:`locate` finds for it (``first``: the number of brick 0).
    Counted without a branch, a whole brick as one run of samples (which the compiler
    vectorises); a brick with a non-finite sample is gone over again to find whose it is."""
    n_bad = 0
    for b in range(b0, b1):
        inside, bad = _brick_counts(values, extent, b, level)
        if inside == extent[b, 0] * extent[b, 1] * extent[b, 2]:
            out[b] = _ALL_INSIDE
        else:
            out[b] = _MIXED if inside else _ALL_OUTSIDE
        if bad:
            n_bad += _bad_here(values, extent, corner, slot, block, first, b)
    return n_bad


@njit(**INLINE)
def _brick_counts(values, extent, b, level):
    """Brick ``b``'s samples inside (finite, below ``level``) and non-finite, within its
    extent: a whole brick as one run of samples (:func:`_counts`), a brick the grid's end cuts
    row by row."""
    _, m0, m1, m2 = values.shape
    e0, e1, e2 = extent[b, 0], extent[b, 1], extent[b, 2]
    if e0 == m0 and e1 == m1 and e2 == m2:
        return _counts(values[b].reshape(m0 * m1 * m2), level)
    inside = bad = 0
    for i in range(e0):
        for j in range(e1):
            got = _counts(values[b, i, j, :e2], level)
            inside, bad = inside + got[0], bad + got[1]
    return inside, bad


@njit(**INLINE)
def _counts(run, level):
    """The samples of ``run`` inside (finite, below ``level``) and the non-finite ones."""
    inside = bad = 0
    for q in range(run.size):
        x = run[q]
        inside += np.int64((x < level) & (x > -np.inf))  # NaN fails both
        bad += np.int64(not abs(x) < np.inf)
    return inside, bad


@njit(**KERNEL)
def _bad_here(values, extent, corner, slot, block, first, b):
    """Brick ``b``'s non-finite samples that :func:`locate` finds in it."""
    n_bad = 0
    for i in range(extent[b, 0]):
        for j in range(extent[b, 1]):
            for k in range(extent[b, 2]):
                if not np.isfinite(values[b, i, j, k]):
                    gi, gj, gk = corner[b, 0] + i, corner[b, 1] + j, corner[b, 2] + k
                    n_bad += locate(slot, block, gi, gj, gk)[0] == first + b
    return n_bad


@njit(**KERNEL)
def _fill_proxy(values, state, block, below, samples, corner, extent):
    """:meth:`SparseField.sign_proxy`'s values: each skipped leaf's box (faces included) +inf
    where outside, then ``below`` where inside (an inside and an outside leaf share no point:
    the bounds hold every grid point), then the bricks' samples over both (a point two bricks
    share has the same sample in both). The leaves' loop in Python took 3 s at 512^3."""
    n0, n1, n2 = values.shape
    for side in (OUTSIDE, INSIDE):
        fill = np.inf if side == OUTSIDE else below
        for a in range(state.shape[0]):
            for b in range(state.shape[1]):
                for c in range(state.shape[2]):
                    if state[a, b, c] != side:
                        continue
                    for i in range(a * block, min(a * block + block + 1, n0)):
                        for j in range(b * block, min(b * block + block + 1, n1)):
                            for k in range(c * block, min(c * block + block + 1, n2)):
                                values[i, j, k] = fill
    for r in range(corner.shape[0]):
        for i in range(extent[r, 0]):
            for j in range(extent[r, 1]):
                for k in range(extent[r, 2]):
                    values[corner[r, 0] + i, corner[r, 1] + j, corner[r, 2] + k] = samples[
                        r, i, j, k
                    ]


#: Bricks to move in a run at least for :func:`moved_down` to move them on two threads.
MOVE_APART = 256


def moved_down(values: np.ndarray, kept: np.ndarray, threads: int = 1) -> int:
    """Bricks ``kept`` (ascending) to rows ``0, 1, ...`` of ``values``, in place; returns how
    many. Only the rows from the first dropped brick on move; with ``threads`` > 1, the first
    half of those rows and the second at once: the second half writes rows at or past ``h``,
    its own sources lie past them, and the first half's sources below ``h`` are rows it never
    writes; the first half's bricks read from ``h`` on (as many as the bricks dropped before
    them: few) are kept aside first and written last. A memory-bound copy of most of the run
    (a run drops a few bricks, and every brick after the first dropped moves): sculpture-1 at
    512^3, 3 ms a run of 4096 bricks on one thread, with the other idle."""
    k = kept.size
    # kept[r] - r counts the bricks dropped before row r's: rows before the first drop stay
    d = int(np.searchsorted(kept - np.arange(k), 0, side="right"))
    if d == k:
        return k
    if threads < 2 or k - d < MOVE_APART:
        return _move_down(values, kept, d, k)
    h = (d + k) // 2
    r0 = int(np.searchsorted(kept[:h], h))  # the first row below h whose brick is past it
    aside = values[kept[r0:h]]  # a copy (fancy indexing)
    run_at_once([lambda: _move_down(values, kept, d, r0), lambda: _move_down(values, kept, h, k)])
    values[r0:h] = aside
    return k


@njit(**KERNEL)
def _move_down(values, kept, r0, r1):
    """Bricks ``kept[r0:r1]`` (ascending, ``kept[r] >= r``) to rows ``r0:r1`` of ``values``,
    in place, in order; returns how many there are in all."""
    for r in range(r0, r1):
        b = kept[r]
        if b != r:
            values[r] = values[b]
    return kept.size


@njit(**KERNEL)
def _bricks_count_inside(values, extent, level):
    """Inside samples of the bricks (a point shared by bricks once per brick)."""
    n = 0
    for b in range(values.shape[0]):
        n += _brick_counts(values, extent, b, level)[0]
    return n
