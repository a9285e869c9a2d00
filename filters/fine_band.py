"""The resolution check's fine field as a :class:`~surfgen.generator.eval.sparse.SparseField`:
only the leaves around the band are built, evaluated and meshed.

:func:`surfgen.filters.resolution.fine_field` (``method="band"``) fills the whole nested grid
of ``2N - 1`` points per axis: the band's new points evaluated, every other point the coarse
field's trilinear mean kept on its cell's side, then the singular samples patched. Its mesh is
all in the band: a fine cell outside it has its corners on one side. :func:`fine_band` builds
the same values where a mesh reads them, and no others:

- a *leaf* of the fine grid (``BLOCK`` fine cells a side: ``BLOCK / 2`` coarse cells) is built
  when a band cell touches its closed box of points (the coarse cells one beyond it on each
  side, :func:`_leaf_candidates`), and, for a capped mesh, when it lies on the box's faces on
  the inside; its brick holds the dense fine field's values, bit for bit (:func:`_fill_bricks`:
  the coarse samples, the band's new points — evaluated brick by brick with the grid kernel,
  :func:`~surfgen.generator.eval.tape.evaluate_columns`, the values the points and grid
  evaluators give — and the means, patched as :func:`~surfgen.filters.resolution.fine_field`
  patches them);
- every other leaf lies in coarse cells that are not crossed and touch no crossed cell: their
  corners are all on one side (neighbouring cells share corners), and so are the means; the
  leaf is *inside* or *outside* as its cells' corners.

The sparse marching of the result
(:func:`~surfgen.generator.mesh.sparse_marching.extract_sparse`) is the dense marching of the
dense fine field, bit for bit (``tests/filters/test_fine_band.py``), at the cost of the band:
the dense path scanned the whole ``127^3`` fine grid three times (the means, the evaluation of
every point, marching cubes), about 50 ms of the main job's 73 ms a check (51 ms now).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from numba import njit

from surfgen.generator.errors import SpecError
from surfgen.generator.eval.brick_lookup import locate
from surfgen.generator.eval.grid import Field, Grid
from surfgen.generator.eval.sparse import (
    BLOCK,
    INSIDE,
    OUTSIDE,
    SAMPLED,
    SparseField,
    brick_layout,
    leaf_counts,
    sample_face_leaves,
)
from surfgen.generator.eval.tape import compile_cached, evaluate_columns
from surfgen.generator.formula.expr import Expr
from surfgen.generator.jit.options import INLINE, KERNEL


def fine_band(
    tree: Expr,
    coarse: Field,
    cells: np.ndarray,
    level: float,
    params: Mapping[str, float] | None = None,
    *,
    faces: bool = False,
    threads: int = 1,
) -> tuple[SparseField, int, int]:
    """The fine field of :func:`~surfgen.filters.resolution.fine_field` (``method="band"``)
    around the band ``cells`` (coarse cells, ``(N-1,)*3`` bool), as a sparse field on the
    nested grid (``faces``: the inside leaves on the box's faces sampled too, for a capped
    mesh). Returns it, the number of fine points evaluated (the band's new points) and the
    number patched (non-finite between finite coarse samples), both as ``fine_field``
    counts them. Raises what compiling ``tree`` raises."""
    grid = fine_grid(coarse.grid)
    values = np.ascontiguousarray(coarse.values, dtype=np.float64)
    counts = np.asarray(leaf_counts(grid, BLOCK), dtype=np.int64)
    state = _leaf_candidates(cells, counts, BLOCK // 2)
    _side_of_leaves(values, level, state, BLOCK // 2)
    if faces:
        sample_face_leaves(state)
    leaves, slot, corner, extent = brick_layout(state, grid, BLOCK)
    raw = np.full((len(corner), BLOCK + 1, BLOCK + 1, BLOCK + 1), np.nan)
    todo, evaluated = band_points(cells, tuple(grid.shape))
    members = np.flatnonzero(_bricks_in_band(todo, corner, extent))  # in C order, as leaves
    if len(members):
        program = compile_cached(tree, params)
        evaluate_columns(program, grid.axes(), members, corner, extent, raw, threads)
    # filled in place (past the grid's end the bricks hold NaN: never read, but defined); a
    # brick whose samples all lie on one side holds no crossing: its leaf is decided and the
    # brick dropped, as the sparse evaluator drops them (the inside ones on the box's faces
    # kept for a cap), so the marching passes over the bricks the surface crosses only
    shape = np.asarray(grid.shape, dtype=np.int64)
    sides = np.empty(len(corner), dtype=np.int8)
    singular, kept = _fill_bricks(
        values, todo, level, corner, extent, slot, raw, raw, BLOCK, shape, faces, sides
    )
    if kept < len(corner):
        state[tuple(leaves.T)] = sides
        _, slot, corner, extent = brick_layout(state, grid, BLOCK)
        raw = raw[:kept]
    sf = SparseField(grid, float(level), BLOCK, state, slot, corner, extent, raw)
    return sf, int(evaluated), int(singular)


def fine_grid(grid: Grid) -> Grid:
    """The nested grid of ``2N - 1`` points per axis over the same box: its even points are
    ``grid``'s, bit for bit (``lo + 2i * (h / 2) == lo + i * h`` exactly in floating point)."""
    return Grid(grid.box, tuple(2 * n - 1 for n in grid.shape))


def band_cells(coarse: Field, level: float, band: int = 1) -> np.ndarray:
    """The band, ``(N-1,)*3`` bool: the coarse cells the surface ``F = level`` crosses,
    widened by ``band`` cells (diagonals included). Raises :class:`SpecError` for a negative
    band."""
    if band < 0:
        raise SpecError(f"the resolution band must be >= 0 cells, got {band}")
    cells = _crossed_cells(np.ascontiguousarray(coarse.values, dtype=np.float64), level)
    return _dilate(cells, band) if band else cells


@njit(**KERNEL)
def _crossed_cells(values, level):
    """``(N-1, N-1, N-1)`` bool: the cells with corners on both sides of the level (inside is
    ``F < level`` and finite, as marching cubes has it)."""
    n0, n1, n2 = values.shape
    inside = np.empty(values.shape, dtype=np.bool_)
    for i in range(n0):
        for j in range(n1):
            for k in range(n2):
                v = values[i, j, k]
                inside[i, j, k] = math.isfinite(v) and v < level
    out = np.empty((max(n0 - 1, 0), max(n1 - 1, 0), max(n2 - 1, 0)), dtype=np.bool_)
    for i in range(n0 - 1):
        for j in range(n1 - 1):
            for k in range(n2 - 1):
                count = 0
                for dx in range(2):
                    for dy in range(2):
                        for dz in range(2):
                            count += inside[i + dx, j + dy, k + dz]
                out[i, j, k] = 0 < count < 8
    return out


@njit(**KERNEL)
def _dilate(cells, band):
    """The cells within ``band`` cells of a marked one, diagonals included (a cube of side
    ``2 band + 1`` about each, clipped to the array): scipy's ``binary_dilation`` by the 3x3x3
    cube ``band`` times over, as three passes of a window, one per axis (the cube is their
    product; ten times faster on the sampler's 63^3 cells)."""
    n0, n1, n2 = cells.shape
    a = np.zeros_like(cells)
    for i in range(n0):
        for q in range(max(i - band, 0), min(i + band, n0 - 1) + 1):
            for j in range(n1):
                for k in range(n2):
                    a[i, j, k] |= cells[q, j, k]
    b = np.zeros_like(cells)
    for i in range(n0):
        for j in range(n1):
            for q in range(max(j - band, 0), min(j + band, n1 - 1) + 1):
                for k in range(n2):
                    b[i, j, k] |= a[i, q, k]
    out = np.zeros_like(cells)
    for i in range(n0):
        for j in range(n1):
            for k in range(n2):
                hit = False
                for q in range(max(k - band, 0), min(k + band, n2 - 1) + 1):
                    hit |= b[i, j, q]
                out[i, j, k] = hit
    return out


@njit(**KERNEL)
def band_points(cells, shape):
    """The fine points ``shape`` of the band ``cells`` (each coarse cell's 27), less the coarse
    samples (even indices on every axis): the points to evaluate, and how many."""
    todo = np.zeros(shape, dtype=np.bool_)
    c0, c1, c2 = cells.shape
    for i in range(c0):
        for j in range(c1):
            for k in range(c2):
                if cells[i, j, k]:
                    for a in range(2 * i, 2 * i + 3):
                        for b in range(2 * j, 2 * j + 3):
                            for c in range(2 * k, 2 * k + 3):
                                todo[a, b, c] = True
    n = 0
    for a in range(shape[0]):
        for b in range(shape[1]):
            for c in range(shape[2]):
                if todo[a, b, c]:
                    if (a & 1) == 0 and (b & 1) == 0 and (c & 1) == 0:
                        todo[a, b, c] = False
                    else:
                        n += 1
    return todo, n


@njit(**KERNEL)
def _leaf_candidates(cells, counts, half):
    """:data:`SAMPLED` for each fine leaf (``half`` coarse cells a side) that a band cell
    touches — one whose fine points meet the leaf's closed box: the coarse cells from one
    before the leaf to one after it — else :data:`OUTSIDE` (decided later)."""
    state = np.full((counts[0], counts[1], counts[2]), OUTSIDE, dtype=np.int8)
    c0, c1, c2 = cells.shape
    for i in range(c0):
        for j in range(c1):
            for k in range(c2):
                if not cells[i, j, k]:
                    continue
                # the leaves a with a*half - 1 <= i <= a*half + half
                for a in range(max((i - 1) // half, 0), min((i + 1) // half, counts[0] - 1) + 1):
                    for b in range(
                        max((j - 1) // half, 0), min((j + 1) // half, counts[1] - 1) + 1
                    ):
                        for c in range(
                            max((k - 1) // half, 0), min((k + 1) // half, counts[2] - 1) + 1
                        ):
                            state[a, b, c] = SAMPLED
    return state


@njit(**KERNEL)
def _side_of_leaves(values, level, state, half):
    """Each leaf that no band cell touches takes the side of its first coarse sample (all of
    its cells' corners are on that side): :data:`INSIDE` (finite, below the level) or
    :data:`OUTSIDE`."""
    n0, n1, n2 = state.shape
    for a in range(n0):
        for b in range(n1):
            for c in range(n2):
                if state[a, b, c] == SAMPLED:
                    continue
                v = values[a * half, b * half, c * half]
                state[a, b, c] = INSIDE if (math.isfinite(v) and v < level) else OUTSIDE


@njit(**KERNEL)
def _bricks_in_band(todo, corner, extent):
    """Whether each brick holds a point of the band (else it is an inside leaf on the box's
    faces, all means: nothing to evaluate)."""
    out = np.zeros(corner.shape[0], dtype=np.bool_)
    for s in range(corner.shape[0]):
        c0, c1, c2 = corner[s, 0], corner[s, 1], corner[s, 2]
        for i in range(extent[s, 0]):
            for j in range(extent[s, 1]):
                for k in range(extent[s, 2]):
                    out[s] |= todo[c0 + i, c1 + j, c2 + k]
    return out


@njit(**INLINE)
def corner_sum(values, a, b, c):
    """The sum of the coarse samples around fine point ``(a, b, c)`` (its coarse cell's 8
    corners, or a face's 4, an edge's 2, counted 8 / n times each in that order: the mean is
    the same) and how many were summed."""
    i0, j0, k0 = a // 2, b // 2, c // 2
    s = 0.0
    n = 0
    for i in (i0, i0 + (a & 1)):
        for j in (j0, j0 + (b & 1)):
            for k in (k0, k0 + (c & 1)):
                s += values[i, j, k]
                n += 1
    return s, n


@njit(**INLINE)
def mean_on_side(values, a, b, c, s, n, level, below):
    """The mean ``s / n`` of the coarse samples around a fine point of a cell that is not
    crossed, kept on the side of those samples (``below``: the float below ``level``);
    non-finite means count as outside, as in marching cubes."""
    v = s / n
    corner = values[a // 2, b // 2, c // 2]
    if math.isfinite(corner) and corner < level:
        return min(v, below)
    if math.isfinite(v) and v < level:  # cannot happen in exact arithmetic
        return level
    return v


@njit(**KERNEL)
def _fill_bricks(
    values, todo, level, corner, extent, slot, raw, bricks, block, shape, faces, sides
):
    """Each brick's points as :func:`surfgen.filters.resolution.fine_field` gives them: a
    coarse sample (even indices), an evaluated band point (``todo``: ``raw``), or the mean of
    the coarse samples around it kept on their side (:func:`mean_on_side`); a non-finite new
    point between finite coarse samples takes their mean (as
    :func:`surfgen.filters.resolution._patch_singular`). Returns how many points were patched,
    each counted once (in the first brick :func:`locate` finds for it).

    Each brick's leaf state into ``sides``: :data:`OUTSIDE` (every point above the level or
    non-finite), :data:`INSIDE` (every point finite and below it) or :data:`SAMPLED` (both;
    and, with ``faces``, an inside leaf on the faces of the grid ``shape``). The bricks kept
    (sampled) are written to ``bricks[0], bricks[1], ...`` in order; returns the points
    patched and the bricks kept. ``bricks`` may be ``raw`` itself: a brick is written to a
    place at or before its own, and a point of ``raw`` read just before its place is
    written."""
    below = np.nextafter(level, -np.inf)
    patched = 0
    q = 0  # where the brick goes
    for s in range(corner.shape[0]):
        n_inside = 0
        for i in range(extent[s, 0]):
            a = corner[s, 0] + i
            for j in range(extent[s, 1]):
                b = corner[s, 1] + j
                for k in range(extent[s, 2]):
                    c = corner[s, 2] + k
                    if (a & 1) == 0 and (b & 1) == 0 and (c & 1) == 0:
                        v = values[a // 2, b // 2, c // 2]
                        bricks[q, i, j, k] = v
                        n_inside += math.isfinite(v) and v < level
                        continue
                    if todo[a, b, c]:
                        v = raw[s, i, j, k]
                        if math.isfinite(v):
                            bricks[q, i, j, k] = v
                            n_inside += v < level
                            continue
                    total, n = corner_sum(values, a, b, c)
                    if not todo[a, b, c]:
                        v = mean_on_side(values, a, b, c, total, n, level, below)
                    if not math.isfinite(v) and math.isfinite(total):
                        v = total / n
                        patched += locate(slot, block, a, b, c)[0] == s
                    bricks[q, i, j, k] = v
                    n_inside += math.isfinite(v) and v < level
        points = extent[s, 0] * extent[s, 1] * extent[s, 2]
        side = INSIDE if n_inside == points else (OUTSIDE if n_inside == 0 else SAMPLED)
        if faces and side == INSIDE:
            for a in range(3):
                if corner[s, a] == 0 or corner[s, a] + extent[s, a] == shape[a]:
                    side = SAMPLED  # a cap's vertices need it
        sides[s] = side
        if side == SAMPLED:
            e0, e1, e2 = extent[s, 0], extent[s, 1], extent[s, 2]
            if q < s and min(e0, e1, e2) <= block:  # past the grid's end: never read, but
                _tail_nan(bricks, q, e0, e1, e2)  # defined (NaN), as in the raw brick
            q += 1
    return patched, q


@njit(**INLINE)
def _tail_nan(bricks, q, e0, e1, e2):
    """NaN in brick ``q`` past extents ``(e0, e1, e2)``."""
    m = bricks.shape[1]
    for i in range(m):
        for j in range(m):
            for k in range(m):
                if i >= e0 or j >= e1 or k >= e2:
                    bricks[q, i, j, k] = np.nan
