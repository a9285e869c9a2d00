"""The tape interpreter (:mod:`surfgen.generator.eval.interpreter`) run at arbitrary points: a list
of points (:func:`run_points`), the lattice of the distinct coordinates and pairs they need
(:func:`run_lattice`, planned by :func:`eval_points`), and points on grid edges
(:func:`edge_lattice`, :func:`eval_edges`, for the walls). Each gives the grid driver's values
(and the reference's) bit for bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.eval.interpreter import run_code_far
from surfgen.generator.eval.row_operations import unsigned
from surfgen.generator.jit.options import INLINE, KERNEL


@njit(**KERNEL)
def run_points(prog, tile, px, py, pz, out):
    """Evaluate a program at the points ``(px[p], py[p], pz[p])`` into ``out[p]``.

    ``prog`` is ``(code, blocks, loads, stores, consts, rows, n_rows)`` of a program rewritten
    by :func:`surfgen.generator.eval.tape.points_program`: every block runs along the points, so
    each level's store holds one value per point of the current tile and the row scalars of
    the grid's blocks (S slots) are W rows ``n_vector + slot`` read by ``vv`` operations.
    Each element goes through the same scalar operations as on a grid, so the values are the
    grid interpreter's (and the reference's) bit for bit.
    """
    code, blocks, loads, stores, consts, rows = prog[0], prog[1], prog[2], prog[3], prog[4], prog[5]
    n_rows = prog[6]
    depth = 1
    for lv in range(8):
        depth = max(depth, rows[lv])
    st = np.empty((8, depth, tile))  # st[level, row, point]
    W = np.empty((n_rows, tile))
    S = np.empty(1)
    T = np.empty((2, tile))
    prof = np.empty(0)
    total = px.size
    for p0 in range(0, total, tile):
        n = min(tile, total - p0)
        for k in range(n):
            st[1, 0, k] = px[p0 + k]
            st[2, 0, k] = py[p0 + k]
            st[4, 0, k] = pz[p0 + k]
        for lv in (1, 2, 4, 6, 3, 5, 7):
            c0 = blocks[lv, 0]
            c1 = blocks[lv, 1]
            if c0 == c1:
                continue
            for q in range(blocks[lv, 2], blocks[lv, 3]):
                kind = loads[q, 0]
                row = loads[q, 1]
                slot = loads[q, 2]
                if kind == 0:
                    v = consts[row]
                    for k in range(n):
                        W[slot, k] = v
                else:
                    for k in range(n):
                        W[slot, k] = st[kind, row, k]
            run_code_far(code, c0, c1, consts, W, S, T, n, prof)
            for q in range(blocks[lv, 4], blocks[lv, 5]):
                slot = stores[q, 0]
                kind = stores[q, 1]
                row = stores[q, 2]
                if kind == 7:
                    for k in range(n):
                        out[p0 + k] = W[slot, k]
                else:
                    for k in range(n):
                        st[kind, row, k] = W[slot, k]


@njit(**KERNEL)
def dedupe(keys):
    """Distinct int64 keys in order of first appearance (open addressing, O(n)).

    Returns ``ids`` (``keys[p]`` is the ``ids[p]``-th distinct key) and ``first`` (the position
    of each distinct key's first appearance)."""
    ids = np.empty(keys.size, dtype=np.int64)
    return ids, _dedupe_into(keys, ids)


@njit(**KERNEL)
def _dedupe_into(keys, ids):
    """:func:`dedupe` writing ``ids`` into the given array (a row of the maps, no copy);
    returns ``first``."""
    n = keys.size
    cap = 16
    while cap < 2 * n:
        cap *= 2
    mask = np.uint64(cap - 1)
    table = np.full(cap, -1, dtype=np.int64)
    held = np.empty(cap, dtype=np.int64)  # the key in each used slot: no lookup through first
    first = np.empty(n, dtype=np.int64)
    m = 0
    for p in range(n):
        k = keys[p]
        u = np.uint64(k)
        h = ((u ^ (u >> np.uint64(31))) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(17)
        h = h & mask
        while True:
            t = table[h]
            if t == -1:
                table[h] = m
                held[h] = k
                first[m] = p
                ids[p] = m
                m += 1
                break
            if held[h] == k:
                ids[p] = t
                break
            h = (h + np.uint64(1)) & mask
    return first[:m]


@njit(**KERNEL)
def dedupe_in(keys, size):
    """:func:`dedupe` of keys known to lie in ``[0, size)`` (pairs of dense ids): the same
    ``ids`` and ``first``, through a table indexed by the key where it is small enough (no
    hashing, no probing), else :func:`dedupe`."""
    ids = np.empty(keys.size, dtype=np.int64)
    return ids, _dedupe_in_into(keys, size, ids)


@njit(**KERNEL)
def _dedupe_in_into(keys, size, ids):
    """:func:`dedupe_in` writing ``ids`` into the given array; returns ``first``."""
    n = keys.size
    if size > 8 * n + 4096:
        return _dedupe_into(keys, ids)
    table = np.full(size, -1, dtype=np.int32)
    first = np.empty(n, dtype=np.int64)
    m = 0
    for p in range(n):
        k = keys[p]
        t = table[unsigned(k)]
        if t == -1:
            table[unsigned(k)] = m
            first[m] = p
            ids[p] = m
            m += 1
        else:
            ids[p] = t
    return first[:m]


@njit(**KERNEL)
def run_lattice(prog, tile, sizes, offsets, maps, map_at, store, out, skip=None):
    """Evaluate a points program (see :func:`run_points`) level by level over the distinct
    values each level needs: level ``lv`` runs over ``sizes[lv]`` entries (distinct x values,
    distinct (x, y) pairs, ..., every point for xyz); a load of level ``K`` in level ``lv``'s
    block reads entry ``maps[map_at[lv, K] + c]`` of K's store for entry ``c`` (K == lv: the
    level's own variable, entry ``c``).  Stores live in ``store``: level K, row r, entry e at
    ``offsets[K] + r * sizes[K] + e``; rows 0 of levels x, y, z hold the coordinates (filled
    by the caller).  Every entry is computed from the same bits as at its points, so values
    equal :func:`run_points`' bit for bit.  ``skip[lv]``: level ``lv``'s store is already
    filled (the edges' levels that do not vary along them, :func:`eval_edges`)."""
    code, blocks, loads, stores, consts = prog[0], prog[1], prog[2], prog[3], prog[4]
    n_rows = prog[6]
    W = np.empty((n_rows, tile))
    S = np.empty(1)
    T = np.empty((2, tile))
    prof = np.empty(0)
    for lv in (1, 2, 4, 6, 3, 5, 7):
        c0 = blocks[lv, 0]
        c1 = blocks[lv, 1]
        if c0 == c1 or (skip is not None and skip[lv]):
            continue
        total = sizes[lv]
        for e0 in range(0, total, tile):
            n = min(tile, total - e0)
            for q in range(blocks[lv, 2], blocks[lv, 3]):
                kind = loads[q, 0]
                row = loads[q, 1]
                slot = loads[q, 2]
                if kind == 0:
                    v = consts[row]
                    for k in range(n):
                        W[slot, k] = v
                elif kind == lv:
                    base = offsets[kind] + row * sizes[kind] + e0
                    for k in range(n):
                        W[slot, k] = store[unsigned(base + k)]
                else:
                    base = offsets[kind] + row * sizes[kind]
                    at = map_at[lv, kind] + e0
                    for k in range(n):
                        W[slot, k] = store[unsigned(base + maps[at + k])]
            run_code_far(code, c0, c1, consts, W, S, T, n, prof)
            for q in range(blocks[lv, 4], blocks[lv, 5]):
                slot = stores[q, 0]
                kind = stores[q, 1]
                row = stores[q, 2]
                if kind == 7:
                    for k in range(n):
                        out[unsigned(e0 + k)] = W[slot, k]
                else:
                    base = offsets[kind] + row * sizes[kind] + e0
                    for k in range(n):
                        store[unsigned(base + k)] = W[slot, k]


@njit(**KERNEL)
def _gather(values, at):
    out = np.empty(at.size, dtype=values.dtype)
    for i in range(at.size):
        out[i] = values[unsigned(at[i])]
    return out


@njit(**KERNEL)
def _pair_level(ids, sizes, has, lv, a, b):
    """Pair level ``lv`` of variables' levels ``a`` and ``b`` (dense ids ``ids[a]``,
    ``ids[b]`` of the points): its entries are their distinct pairs (sets ``ids[lv]``,
    ``sizes[lv]``, ``has[lv]``).  Returns the entries of ``a`` and of ``b`` each one reads (the
    caller appends them to the parts :func:`_place_parts` copies: numba types the list there)."""
    first = _dedupe_in_into(ids[a] * sizes[b] + ids[b], sizes[a] * sizes[b], ids[lv])
    sizes[lv] = first.size
    has[lv] = True
    return _gather(ids[a], first), _gather(ids[b], first)


@njit(**KERNEL)
def _maps_with_ids(n, pair_levels):
    """The ``maps`` of :func:`run_lattice`, laid out so that the points' entries need no copy:
    first the xyz level's section, whose row ``k`` (``ids[k]``, a view, filled by the caller)
    is the entry of every point in level ``k``'s store, then room for the two parts of each of
    ``pair_levels`` pair levels (at most ``n`` entries each: :func:`_place_parts`)."""
    maps = np.empty(8 * n + 2 * n * pair_levels + 1, dtype=np.int64)
    return maps, maps[: 8 * n].reshape((8, n))


@njit(**KERNEL)
def _place_parts(maps, n, pair_parts, pair_keys, has, map_at):
    """Copy each pair level's two parts (the entries of its variables' stores, ``pair_keys[q]``
    = (pair level, variable level)) behind the xyz section of ``maps``
    (:func:`_maps_with_ids`), and record in ``map_at`` where every section starts."""
    for k in (1, 2, 4, 3, 5, 6):
        if has[k]:
            map_at[7, k] = k * n
    at = 8 * n
    for q in range(len(pair_parts)):
        lv, k = pair_keys[q]
        map_at[lv, k] = at
        part = pair_parts[q]
        for e in range(part.size):  # not a slice copy: numba would compile its shape error
            maps[at + e] = part[e]
        at += part.size


@njit(**KERNEL)
def eval_points(prog, tile, active, rows, px, py, pz, out):
    """Evaluate a points program at ``(px[p], py[p], pz[p])`` into ``out[p]``, each level once
    per distinct value it needs (:func:`run_lattice`): its plan made here, in one call.

    Level x runs over the distinct x values (told apart by their bits, so -0.0 and +0.0 are
    distinct and every entry is computed from exactly the bits of its points), xy over the
    distinct (x, y) pairs of the points (if ``active[3]``), likewise xz, yz; xyz over every
    point.  ``rows[lv]``: the store rows of level ``lv`` (``Program.rows``)."""
    n = px.size
    # the rows of the levels it has, all set below, in place in the maps
    maps, ids = _maps_with_ids(n, active[3] + active[5] + active[6])
    sizes = np.zeros(8, dtype=np.int64)
    has = np.zeros(8, dtype=np.bool_)
    first_x = _dedupe_into(px.view(np.int64), ids[1])
    first_y = _dedupe_into(py.view(np.int64), ids[2])
    first_z = _dedupe_into(pz.view(np.int64), ids[4])
    sizes[1], sizes[2], sizes[4] = first_x.size, first_y.size, first_z.size
    has[1] = has[2] = has[4] = True
    sizes[7] = n
    # parts: (level, variable level) -> the entries of the variable's store it reads, in maps
    map_at = np.zeros((8, 8), dtype=np.int64)
    pair_parts = []
    pair_keys = []
    for lv, a, b in ((3, 1, 2), (5, 1, 4), (6, 2, 4)):
        if not active[lv]:
            continue
        part_a, part_b = _pair_level(ids, sizes, has, lv, a, b)
        pair_parts.append(part_a)
        pair_keys.append((lv, a))
        pair_parts.append(part_b)
        pair_keys.append((lv, b))
    _place_parts(maps, n, pair_parts, pair_keys, has, map_at)
    offsets = np.zeros(8, dtype=np.int64)
    total = 0
    for k in (1, 2, 3, 4, 5, 6):
        offsets[k] = total
        total += rows[k] * sizes[k]
    store = np.empty(max(total, 1))
    store[offsets[1] : offsets[1] + sizes[1]] = _gather(px, first_x)
    store[offsets[2] : offsets[2] + sizes[2]] = _gather(py, first_y)
    store[offsets[4] : offsets[4] + sizes[4]] = _gather(pz, first_z)
    # skip given (nothing skipped): the signature of the edges' calls, one compile for all
    run_lattice(prog, tile, sizes, offsets, maps, map_at, store, out, np.zeros(8, dtype=np.bool_))


# ----------------------------------------------------------------------------- points on grid edges


@njit(**INLINE)
def edge_lattice(prog, tile, active, rows, axis, ijk, axes):
    """The part of a points program that does not vary along grid edges parallel to ``axis``
    (0, 1, 2): for edges starting at grid indices ``ijk`` (n, 3), the two single-variable
    levels of the other axes over their whole grid axis and their pair level over the edges'
    distinct pairs, computed once (:func:`run_lattice`); :func:`eval_edges` then evaluates
    points on these edges running only the levels that involve ``axis``.

    ``axes``: the grid's three coordinate arrays.  Returns the context :func:`eval_edges` takes:
    ``(axis, ijk, sizes, offsets, pair_ids, store, fixed_end, pair_first)``."""
    va = 1 << axis
    b = (axis + 1) % 3
    c = (axis + 2) % 3
    if b > c:
        b, c = c, b
    vb, vc = 1 << b, 1 << c
    n = ijk.shape[0]
    nb, nc = axes[b].size, axes[c].size
    sizes = np.zeros(8, dtype=np.int64)
    sizes[vb], sizes[vc] = nb, nc
    pair_ids = np.zeros(n, dtype=np.int64)
    pair_first = np.zeros(0, dtype=np.int64)
    if active[vb | vc]:
        keys = np.empty(n, dtype=np.int64)
        for e in range(n):
            keys[e] = ijk[e, b] * nc + ijk[e, c]
        pair_ids, pair_first = dedupe_in(keys, nb * nc)
        sizes[vb | vc] = pair_first.size
    offsets = np.zeros(8, dtype=np.int64)
    total = 0
    for k in (vb, vc, vb | vc):
        offsets[k] = total
        total += rows[k] * sizes[k]
    fixed_end = np.int64(total)  # never a literal: one type of ctx, one compile of eval_edges
    # room for the varying levels of a round of up to n points (one entry per point at most)
    for k in (va, va | vb, va | vc):
        total += rows[k] * n
    store = np.empty(max(total, 1))
    for q in range(nb):  # not slice copies: numba would compile their shape error (1.5 s)
        store[offsets[vb] + q] = axes[b][q]
    for q in range(nc):
        store[offsets[vc] + q] = axes[c][q]
    m = pair_first.size
    maps = np.empty(max(2 * m, 1), dtype=np.int64)
    for q in range(m):
        e = pair_first[q]
        maps[q] = ijk[e, b]
        maps[m + q] = ijk[e, c]
    map_at = np.zeros((8, 8), dtype=np.int64)
    map_at[vb | vc, vb] = 0
    map_at[vb | vc, vc] = m
    skip = np.ones(8, dtype=np.bool_)
    skip[vb] = skip[vc] = skip[vb | vc] = False
    run_lattice(prog, tile, sizes, offsets, maps, map_at, store, np.empty(0), skip)
    return axis, ijk, sizes, offsets, pair_ids, store, fixed_end, pair_first


@njit(**KERNEL)
def eval_edges(prog, tile, active, rows, ctx, sel, u, out):
    """Evaluate a points program at points on the edges of ``ctx`` (:func:`edge_lattice`):
    point ``p`` on edge ``sel[p]`` with coordinate ``u[p]`` along the edges' axis, the others the
    edge's grid values.  Levels that do not involve the axis come from ``ctx`` (computed once per
    edge); the axis' level runs over the distinct values of ``u`` (by their bits), its pair levels
    over the distinct (value, grid index) pairs, the xyz level over every point.  The values are
    :func:`eval_points`' (and the reference's) bit for bit: every entry is computed from the bits
    of the coordinates of its points."""
    axis, ijk, sizes_fixed, offsets_fixed, pair_ids, store, fixed_end, _first = ctx
    n = sel.size
    if n == 0:
        return
    va = 1 << axis
    b = (axis + 1) % 3
    c = (axis + 2) % 3
    if b > c:
        b, c = c, b
    vb, vc = 1 << b, 1 << c
    sizes = sizes_fixed.copy()
    offsets = offsets_fixed.copy()
    # the rows of the levels it has, all set below, in place in the maps
    maps, ids = _maps_with_ids(n, active[va | vb] + active[va | vc])
    ufirst = _dedupe_into(u.view(np.int64), ids[va])
    sizes[va] = ufirst.size
    sizes[7] = n
    has = np.zeros(8, dtype=np.bool_)
    has[va] = has[vb] = has[vc] = True
    has[vb | vc] = active[vb | vc]
    map_at = np.zeros((8, 8), dtype=np.int64)
    for p in range(n):
        e = sel[p]
        ids[vb, p] = ijk[unsigned(e), b]
        ids[vc, p] = ijk[unsigned(e), c]
        ids[vb | vc, p] = pair_ids[unsigned(e)]
    # the pair levels with the axis: (value id, grid index) pairs
    pair_parts = []
    pair_keys = []
    for other in (vb, vc):
        lv = va | other
        if not active[lv]:
            continue
        part_a, part_b = _pair_level(ids, sizes, has, lv, va, other)
        pair_parts.append(part_a)
        pair_keys.append((lv, va))
        pair_parts.append(part_b)
        pair_keys.append((lv, other))
    _place_parts(maps, n, pair_parts, pair_keys, has, map_at)
    total = fixed_end
    for k in (va, va | vb, va | vc):
        offsets[k] = total
        total += rows[k] * sizes[k]
    if total > store.size:  # more points than edges: a larger store with the fixed levels
        grown = np.empty(total)
        for e in range(fixed_end):
            grown[e] = store[e]
        store = grown
    for q in range(ufirst.size):
        store[unsigned(offsets[va] + q)] = u[unsigned(ufirst[q])]
    skip = np.zeros(8, dtype=np.bool_)
    skip[vb] = skip[vc] = skip[vb | vc] = True
    run_lattice(prog, tile, sizes, offsets, maps, map_at, store, out, skip)
