"""The grid driver: the tape interpreter (:mod:`surfgen.generator.eval.interpreter`) run over a
whole grid, level by level, with hoisting (tape format: compiler.py).

Layout of a run (:func:`run_grid`): the caller allocates the output and the stores
(:func:`grid_stores`); the x, y, z and yz stores are computed once (:func:`_prologue`,
:func:`_yz_rows`), then each slab of x indices (:func:`_slab`, one per thread chunk) computes
its xy and xz rows per i and the xyz block per (i, j) row of z values, in tiles of W rows,
writing straight into the output. Scratch is O(tile * n_vector) per thread plus the yz store.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.eval.interpreter import run_code_far
from surfgen.generator.eval.opcodes import M_S, OP_COPY
from surfgen.generator.eval.row_operations import unsigned
from surfgen.generator.jit.options import INLINE, KERNEL

# ----------------------------------------------------------------------------- blocks and drivers


@njit(**KERNEL)
def _block(
    lv,
    i,
    j0,
    j1,
    nrun,
    code,
    blocks,
    loads,
    stores,
    consts,
    sx,
    sy,
    sz,
    sxy,
    sxz,
    syz,
    out,
    W,
    S,
    T,
    prof,
):
    """Run the block of level ``lv`` for rows j0 <= j < j1 (at x index i), ``nrun`` points
    along its axis each, tile by tile: scalar loads per row, vector loads, code, stores."""
    c0 = blocks[lv, 0]
    c1 = blocks[lv, 1]
    l0 = blocks[lv, 2]
    l1 = blocks[lv, 3]
    s0 = blocks[lv, 4]
    s1 = blocks[lv, 5]
    if c0 == c1:
        return
    # A root of a lower level (a formula of one or two variables): the output is a broadcast,
    # written straight from its source instead of through the register file.
    if lv == 7 and c1 - c0 == 1 and code[c0, 0] == OP_COPY:
        _broadcast(
            code[c0, 1],
            code[c0, 3],
            loads,
            l0,
            l1,
            consts,
            sx,
            sy,
            sxy,
            sz,
            sxz,
            syz,
            out,
            i,
            j0,
            j1,
        )
        return
    tile = W.shape[1]
    # Rows of several j per tile when a run is short (nrun <= tile/2) and no scalar load varies
    # with j (y or xy values): the code then runs on m*nrun points per dispatch, and the per-op
    # cost of the interpreter is paid once per m rows. Every operation is elementwise, so the
    # values (and bits) are those of a row at a time.
    m = tile // nrun if (lv == 6 or lv == 7) and nrun > 0 else 1
    if m > 1:
        for q in range(l0, l1):
            if loads[q, 3] == 0 and (loads[q, 0] == 2 or loads[q, 0] == 3):
                m = 1
    if m > 1:
        _block_rows(
            m,
            i,
            j0,
            j1,
            nrun,
            code,
            c0,
            c1,
            l0,
            l1,
            s0,
            s1,
            loads,
            stores,
            consts,
            sx,
            sy,
            sz,
            sxy,
            sxz,
            syz,
            out,
            W,
            S,
            T,
            prof,
        )
        return
    for j in range(j0, j1):
        for q in range(l0, l1):
            if loads[q, 3] == 0:
                kind = loads[q, 0]
                row = loads[q, 1]
                if kind == 0:
                    S[loads[q, 2]] = consts[row]
                elif kind == 1:
                    S[loads[q, 2]] = sx[row, i]
                elif kind == 2:
                    S[loads[q, 2]] = sy[row, j]
                else:
                    S[loads[q, 2]] = sxy[row, j]
        r0 = 0
        while r0 < nrun:
            n = min(tile, nrun - r0)
            for q in range(l0, l1):
                vec = loads[q, 3]
                if vec == 1 or (vec == 2 and (j == j0 or nrun > tile)):
                    kind = loads[q, 0]
                    row = loads[q, 1]
                    slot = loads[q, 2]
                    if kind == 4:
                        for k in range(n):
                            W[slot, k] = sz[row, r0 + k]
                    elif kind == 6:
                        for k in range(n):
                            W[slot, k] = syz[row, j, r0 + k]
                    elif kind == 5:
                        for k in range(n):
                            W[slot, k] = sxz[row, r0 + k]
                    elif kind == 2:
                        for k in range(n):
                            W[slot, k] = sy[row, r0 + k]
                    else:
                        for k in range(n):
                            W[slot, k] = sx[row, r0 + k]
            run_code_far(code, c0, c1, consts, W, S, T, n, prof)
            for q in range(s0, s1):
                slot = stores[q, 0]
                kind = stores[q, 1]
                row = stores[q, 2]
                if kind == 7:
                    for k in range(n):
                        out[i, j, r0 + k] = W[slot, k]
                elif kind == 6:
                    for k in range(n):
                        syz[row, j, r0 + k] = W[slot, k]
                elif kind == 5:
                    for k in range(n):
                        sxz[row, r0 + k] = W[slot, k]
                elif kind == 3:
                    for k in range(n):
                        sxy[row, r0 + k] = W[slot, k]
                elif kind == 4:
                    for k in range(n):
                        sz[row, r0 + k] = W[slot, k]
                elif kind == 2:
                    for k in range(n):
                        sy[row, r0 + k] = W[slot, k]
                else:
                    for k in range(n):
                        sx[row, r0 + k] = W[slot, k]
            r0 += n


@njit(**INLINE)
def _block_rows(
    m,
    i,
    j0,
    j1,
    nrun,
    code,
    c0,
    c1,
    l0,
    l1,
    s0,
    s1,
    loads,
    stores,
    consts,
    sx,
    sy,
    sz,
    sxy,
    sxz,
    syz,
    out,
    W,
    S,
    T,
    prof,
):
    """A block along z (yz or xyz) in tiles of up to m whole rows j (see :func:`_block`): its
    scalar loads are constants or x values, the same for every j; y and xy values enter as
    vector loads (kinds 2 and 3, one value per row j: fast.rows_program rewrites a program so).

    A run is the whole z axis (``nrun == Nz``), so the tile's rows of the output and of the yz
    plane are one contiguous stretch: they are copied as such, through flat views."""
    ny = syz.shape[1]
    out_flat = out.reshape(out.size)
    syz_flat = syz.reshape(syz.size)
    for q in range(l0, l1):
        if loads[q, 3] == 0:
            if loads[q, 0] == 0:
                S[loads[q, 2]] = consts[loads[q, 1]]
            else:
                S[loads[q, 2]] = sx[loads[q, 1], i]
    j = j0
    while j < j1:
        rows = min(m, j1 - j)
        n = rows * nrun
        for q in range(l0, l1):
            vec = loads[q, 3]
            if vec == 1 or (vec == 2 and j == j0):
                kind = loads[q, 0]
                row = loads[q, 1]
                slot = loads[q, 2]
                if kind == 6:  # rows j..j+rows-1 of the plane: contiguous
                    base = unsigned((row * ny + j) * nrun)
                    for k in range(n):
                        W[slot, k] = syz_flat[base + unsigned(k)]
                elif kind == 2:
                    for r in range(rows):
                        v = sy[row, j + r]
                        for k in range(nrun):
                            W[slot, r * nrun + k] = v
                elif kind == 3:
                    for r in range(rows):
                        v = sxy[row, j + r]
                        for k in range(nrun):
                            W[slot, r * nrun + k] = v
                elif kind == 5:
                    for r in range(rows):
                        for k in range(nrun):
                            W[slot, r * nrun + k] = sxz[row, k]
                else:  # z (the only other vector load of a block along z)
                    for r in range(rows):
                        for k in range(nrun):
                            W[slot, r * nrun + k] = sz[row, k]
        run_code_far(code, c0, c1, consts, W, S, T, n, prof)
        for q in range(s0, s1):
            slot = stores[q, 0]
            kind = stores[q, 1]
            row = stores[q, 2]
            if kind == 7:  # out[i, j:j+rows, :] is contiguous (nrun is the whole z axis)
                base = unsigned((i * ny + j) * nrun)
                for k in range(n):
                    out_flat[base + unsigned(k)] = W[slot, k]
            else:  # the yz store
                base = unsigned((row * ny + j) * nrun)
                for k in range(n):
                    syz_flat[base + unsigned(k)] = W[slot, k]
        j += rows


@njit(**KERNEL)
def _broadcast(mode, a, loads, l0, l1, consts, sx, sy, sxy, sz, sxz, syz, out, i, j0, j1):
    """out[i, j, :] for j0 <= j < j1 = the root of a formula of one or two variables: a scalar
    per row (mode S: a constant, x, y or xy value) or a z, xz or yz row (mode V), copied
    straight from its store, in one call for all rows j (a call per row cost more than the
    copy of its Nz values). Indexed flat, without a view per row (numba counts references to
    every view it makes)."""
    ny = out.shape[1]
    nz = out.shape[2]
    out_flat = out.reshape(out.size)
    for q in range(l0, l1):
        if loads[q, 2] != a or (loads[q, 3] == 0) != (mode == M_S):
            continue
        kind = loads[q, 0]
        row = loads[q, 1]
        for j in range(j0, j1):
            base = unsigned((i * ny + j) * nz)
            if mode == M_S:
                if kind == 0:
                    s = consts[row]
                elif kind == 1:
                    s = sx[row, i]
                elif kind == 2:
                    s = sy[row, j]
                else:
                    s = sxy[row, j]
                for k in range(nz):
                    out_flat[base + unsigned(k)] = s
            elif kind == 4:
                for k in range(nz):
                    out_flat[base + unsigned(k)] = sz[row, k]
            elif kind == 5:
                for k in range(nz):
                    out_flat[base + unsigned(k)] = sxz[row, k]
            else:
                for k in range(nz):
                    out_flat[base + unsigned(k)] = syz[row, j, k]


@njit(**KERNEL)
def _scratch(prog, tile):
    nv, ns = prog[6], prog[7]
    return np.empty((nv, tile)), np.empty(ns), np.empty((2, tile))


@njit(**KERNEL)
def grid_stores(rows, ax, ay, az):
    """The x, y, z and yz stores of a grid run (``rows``: the program's), the axes in row 0."""
    sx = np.empty((rows[1], ax.size))
    sy = np.empty((rows[2], ay.size))
    sz = np.empty((rows[4], az.size))
    # element by element: a row copy would compile numba's shape-mismatch error (1.5 s)
    for i in range(ax.size):
        sx[0, i] = ax[i]
    for j in range(ay.size):
        sy[0, j] = ay[j]
    for k in range(az.size):
        sz[0, k] = az[k]
    syz = np.empty((rows[6], ay.size, az.size))
    return sx, sy, sz, syz


@njit(**INLINE)
def _prologue(prog, tile, sx, sy, sz, syz, out, prof):
    """The x, y and z blocks (1-D, once per grid)."""
    code, blocks, loads, stores, consts = prog[0], prog[1], prog[2], prog[3], prog[4]
    W, S, T = _scratch(prog, tile)
    e = np.empty((0, 1))
    args = (code, blocks, loads, stores, consts, sx, sy, sz, e, e, syz, out, W, S, T, prof)
    _block(1, 0, 0, 1, sx.shape[1], *args)
    _block(2, 0, 0, 1, sy.shape[1], *args)
    _block(4, 0, 0, 1, sz.shape[1], *args)


@njit(**INLINE)
def _yz_rows(j0, j1, prog, tile, sx, sy, sz, syz, out, prof):
    """The yz block for rows j0 <= j < j1 (once per grid)."""
    code, blocks, loads, stores, consts = prog[0], prog[1], prog[2], prog[3], prog[4]
    W, S, T = _scratch(prog, tile)
    e = np.empty((0, 1))
    args = (code, blocks, loads, stores, consts, sx, sy, sz, e, e, syz, out, W, S, T, prof)
    _block(6, 0, j0, j1, sz.shape[1], *args)


@njit(**INLINE)
def _slab(i0, i1, prog, tile, sx, sy, sz, syz, out, prof):
    """x indices i0 <= i < i1: per i the xy and xz rows, then the xyz block row by row."""
    code, blocks, loads, stores, consts, rows = prog[0], prog[1], prog[2], prog[3], prog[4], prog[5]
    W, S, T = _scratch(prog, tile)
    ny = sy.shape[1]
    nz = sz.shape[1]
    sxy = np.empty((rows[3], ny))
    sxz = np.empty((rows[5], nz))
    args = (code, blocks, loads, stores, consts, sx, sy, sz, sxy, sxz, syz, out, W, S, T, prof)
    for i in range(i0, i1):
        _block(3, i, 0, 1, ny, *args)
        _block(5, i, 0, 1, nz, *args)
        _block(7, i, 0, ny, nz, *args)


# What run_grid does: all of a grid on one thread, or one part of it (the threads' way).
GRID_ALL, GRID_XYZ_AXES, GRID_YZ_ROWS, GRID_SLAB = 0, 1, 2, 3


@njit(**KERNEL)
def run_grid(prog, tile, sx, sy, sz, syz, out, prof, part, lo, hi):
    """Evaluate a program into ``out`` (Nx, Ny, Nz), with the stores of :func:`grid_stores`.

    ``prog`` is ``(code, blocks, loads, stores, consts, rows, n_vector, n_scalar)`` of a
    :class:`~surfgen.generator.eval.compiler.Program`; ``prof`` is empty, or float64 of one entry
    per code row to receive cycle counts. ``part`` is :data:`GRID_ALL` (the whole grid), or
    one step of it, for threads: :data:`GRID_XYZ_AXES` (the x, y and z blocks, first),
    :data:`GRID_YZ_ROWS` (the yz plane's rows lo <= j < hi, next), :data:`GRID_SLAB` (x
    indices lo <= i < hi, last). Every part computes the same values wherever it runs.

    One entry point for both: numba compiles (and caches) every jitted function an entry point
    calls into that entry point, and LLVM optimises it again there (the interpreter itself is
    called through a pointer, :func:`interpreter.run_code_far`, and compiled once).
    """
    whole = part == GRID_ALL
    j0, j1 = (0, sy.shape[1]) if whole else (lo, hi)
    i0, i1 = (0, sx.shape[1]) if whole else (lo, hi)
    # one call site each (LLVM may inline a callee into every site: twice the code to compile)
    if whole or part == GRID_XYZ_AXES:
        _prologue(prog, tile, sx, sy, sz, syz, out, prof)
    if whole or part == GRID_YZ_ROWS:
        _yz_rows(j0, j1, prog, tile, sx, sy, sz, syz, out, prof)
    if whole or part == GRID_SLAB:
        _slab(i0, i1, prog, tile, sx, sy, sz, syz, out, prof)


@njit(**INLINE)
def tile_for(n, tile_max):
    """:func:`surfgen.generator.eval.tape._tile` (the tile for runs of ``n`` points along z)."""
    if 0 < n <= tile_max // 2:
        return (tile_max // n) * n
    pieces = -(-n // tile_max)
    return max(1, -(-n // pieces))


#: What a column's grid costs beside its points, in points: its x, y, z and yz blocks and, per x
#: index, the xy and xz rows and a dispatch of the xyz block's code (about 14 us against 2.3 ns
#: a point for sculpture-1's program on a Zen 5). 4096 measured best or near it at 512^3 over
#: the presets and draws of every family (against 0, 1024, 2048 and 8192: the performance log,
#: 2026-12-06 (20)).
COLUMN_COST_POINTS = 4096
#: The most points a group's grid takes (its values: 512 KiB a thread, beside its yz store):
#: as fast as groups without a bound at 512^3 (larger ones only where every leaf is sampled,
#: where a column's cost is small beside its points anyway).
GROUP_POINTS = 1 << 16


@njit(**KERNEL)
def column_groups(members, corner, extent, cost_points, max_points):
    """The runs of ``members`` (ordered by corner, x then y then z) that :func:`run_columns`
    evaluates as one grid each, ``(G, 2)`` member ranges: a run of columns (members with the
    same x and y corner) with the same x points, each starting at most one point past the y
    points of the ones before, merged while the grid of their union (their x points, the y
    points from the first to the last, the union of their z points) costs less than the grids
    apart, each ``cost_points`` beside its points."""
    n = members.size
    groups = np.empty((n, 2), dtype=np.int64)
    top = 0
    for q in range(n):
        top = max(top, corner[members[q], 2] + extent[members[q], 2])
    in_group = np.zeros(top, dtype=np.int64)  # the group (+1) a z point was taken by
    in_column = np.zeros(top, dtype=np.int64)  # the column (its first member, +1)
    g = 0
    q = 0
    while q < n:
        b = members[q]
        x0, y0, nx = corner[b, 0], corner[b, 1], extent[b, 0]
        y1 = y0 + extent[b, 1]
        start = q
        q, nz, _ = _column_points(members, corner, extent, q, in_group, g + 1, in_group, g + 1)
        cost = cost_points + nx * (y1 - y0) * nz  # of the group's columns, each apart
        while q < n:  # the next column, merged where that costs less
            c = members[q]
            if corner[c, 0] != x0 or extent[c, 0] != nx or corner[c, 1] > y1:
                break
            cy, cy1 = corner[c, 1], corner[c, 1] + extent[c, 1]
            # its z points, and those the group does not have yet
            r, own, new = _column_points(members, corner, extent, q, in_column, q + 1, in_group,
                                         g + 1)  # fmt: skip
            apart = cost + cost_points + nx * (cy1 - cy) * own
            merged = cost_points + nx * (max(y1, cy1) - y0) * (nz + new)
            if merged > apart or merged - cost_points > max_points:
                break
            _column_points(members, corner, extent, q, in_group, g + 1, in_group, g + 1)
            cost, y1, nz, q = merged, max(y1, cy1), nz + new, r
        groups[g, 0] = start
        groups[g, 1] = q
        g += 1
    return groups[:g].copy()


@njit(**INLINE)
def _column_points(members, corner, extent, q, mark, stamp, group, g):
    """The column of members from ``q`` (those with its x and y corner): one past its last
    member, its z points (each counted once: marked ``stamp`` in ``mark``), and how many of
    them ``group`` does not mark ``g``."""
    n = members.size
    x0, y0 = corner[members[q], 0], corner[members[q], 1]
    own = new = 0
    r = q
    while r < n and corner[members[r], 0] == x0 and corner[members[r], 1] == y0:
        m = members[r]
        for k in range(corner[m, 2], corner[m, 2] + extent[m, 2]):
            if mark[k] != stamp:
                mark[k] = stamp
                own += 1
                new += group[k] != g
        r += 1
    return r, own, new


@njit(**KERNEL)
def run_columns(prog, prog_rows, tile_max, ax, ay, az, cols, members, corner, extent, values):
    """Evaluate bricks group by group, each group as a grid of its own: the bricks
    ``members[cols[c, 0]:cols[c, 1]]`` (:func:`column_groups`) share their x points and are
    ordered by y then z corner; the grid runs once on their x points, the y points from the
    first brick's to the last one's, and the union of their z points (with ``prog_rows``, the
    program for tiles of several rows, where the tile holds two runs), and each brick's points
    are copied to ``values[brick]``. One call for many groups: no Python between them (the
    sparse evaluator's bricks)."""
    zs = np.empty(az.size, dtype=np.int64)
    at = np.full(az.size, -1, dtype=np.int64)  # a z index's place in zs, or -1
    no_profile = np.empty(0)
    # int64 values, not literal constants: run_grid is then the grid evaluator's own compile
    # (literal arguments would make numba compile it a second time for them)
    whole, unused = np.int64(GRID_ALL), np.int64(0)
    for c in range(cols.shape[0]):
        m0, m1 = cols[c, 0], cols[c, 1]
        first = members[m0]
        i0, j0 = corner[first, 0], corner[first, 1]
        ni = extent[first, 0]
        j1, lo, hi = j0, az.size, 0
        for q in range(m0, m1):  # the union of the members' z points (marked), their y span
            b = members[q]
            j1 = max(j1, corner[b, 1] + extent[b, 1])
            lo, hi = min(lo, corner[b, 2]), max(hi, corner[b, 2] + extent[b, 2])
            for k in range(corner[b, 2], corner[b, 2] + extent[b, 2]):
                at[k] = 0
        nz = 0
        for k in range(lo, hi):  # in order, each with its place
            if at[k] == 0:
                zs[nz] = k
                at[k] = nz
                nz += 1
        nj = j1 - j0
        cz = np.empty(nz)
        for q in range(nz):
            cz[q] = az[zs[q]]
        tile = tile_for(nz, tile_max)
        prog_c = prog_rows if tile >= 2 * nz else prog
        sx, sy, sz, syz = grid_stores(prog_c[5], ax[i0 : i0 + ni], ay[j0:j1], cz)
        out = np.empty((ni, nj, nz))
        run_grid(prog_c, tile, sx, sy, sz, syz, out, no_profile, whole, unused, unused)
        for q in range(m0, m1):
            b = members[q]
            w = at[corner[b, 2]]
            jo = corner[b, 1] - j0
            for i in range(ni):
                for j in range(extent[b, 1]):
                    for k in range(extent[b, 2]):
                        values[b, i, j, k] = out[i, jo + j, w + k]
        for q in range(nz):
            at[zs[q]] = -1
