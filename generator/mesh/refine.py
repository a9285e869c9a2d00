"""Refining suspect crossings with the formula: steps 2-4 of :mod:`surfgen.generator.mesh.walls`.

A numba call (:func:`_bisect_kernel`) takes suspect edges through the midpoint, the secant step,
the bisections and the decision (root, pole or jump), evaluating the formula axis by axis
(:func:`~surfgen.generator.eval.point_driver.eval_edges`); :func:`refine_suspects` makes one
such call per run of :data:`SUSPECTS_A_CALL` suspects, the runs shared among threads.  The
thresholds are explained in the walls module's docstring.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.allocator import scratch_kept
from surfgen.generator.eval.point_driver import edge_lattice, eval_edges
from surfgen.generator.eval.row_operations import unsigned
from surfgen.generator.eval.tape import run_at_once
from surfgen.generator.jit.options import INLINE, KERNEL
from surfgen.generator.mesh.mesh import JUMP, POLE, ROOT

ROOT_SHRINK = 0.6
ROOT_FLOOR = 1e-9
ROOT_KEPT = 0.25
POLE_GROWTH = 2.5
POLE_SCALE = 4.0
NEAR_ROOT = 0.5  # see step 2 of the docstring
UNSURE = 0.9  # a jump whose M shrank below this share is bisected twice more
BISECTIONS = 2  # at most, after the midpoint; as many again where the bracket ends at a sample
SECANT_GRID = 16.0  # the secant step's point: a multiple of 1/16 of the edge
#: Suspect edges a call of :func:`_bisect_kernel` refines at most: its stores (the formula's
#: levels for a round of points, about 2 KB a suspect for equation C) are then a run's, reused
#: from one run to the next, not the whole mesh's made afresh (equation C at 512^3: 1.36
#: million suspects, 185,000 page faults and 0.52-0.58 s in one call; in runs, 0.09 s on one
#: thread, 0.05 s on two).
SUSPECTS_A_CALL = 8192


def refine_suspects(prog, tile, active, rows, level, axes, spacing, edge_ijk, edge_axis, idx,
                    a_inside, fa, fb, kinds, threads: int = 1) -> int:  # fmt: skip
    """:func:`_bisect_kernel` over the suspects (its arguments, ``axes`` a tuple of three
    contiguous arrays), in runs of :data:`SUSPECTS_A_CALL`, on ``threads`` threads, each taking
    the next run as it is free (a suspect's kind depends on its edge alone, so the kinds are
    the same whatever the runs and the threads).  Returns the number of points evaluated."""
    n = idx.size
    starts = iter(range(0, n, SUSPECTS_A_CALL))  # shared: next() on it is atomic under the GIL

    def work() -> int:
        points = 0
        for r0 in starts:
            r1 = min(n, r0 + SUSPECTS_A_CALL)
            points += _bisect_kernel(prog, tile, active, rows, level, axes, spacing,
                                     edge_ijk[r0:r1], edge_axis[r0:r1], idx[r0:r1],
                                     a_inside[r0:r1], fa[r0:r1], fb[r0:r1], kinds)  # fmt: skip
        return points

    workers = max(1, min(int(threads), -(-n // SUSPECTS_A_CALL)))
    with scratch_kept():  # the runs' stores reused from one run to the next
        return sum(run_at_once([work] * workers))


@njit(**INLINE)
def _nanmax(a, b):
    """np.maximum: NaN propagates (a select, not a branch)."""
    bigger = a if a > b else b
    return np.nan if (a != a) | (b != b) else bigger


@njit(**KERNEL)
def _decide(mid, end, fa, fb):
    """The kind of each refined edge from its brackets ``(n, 5)`` after the first and the last
    round (:func:`_decide_all` for brackets in rows, the layout of the references in tests)."""
    out = np.empty(fa.size, dtype=np.uint8)
    _decide_all(np.ascontiguousarray(mid.T), np.ascontiguousarray(end.T), fa, fb, out)
    return out


@njit(**KERNEL)
def _decide_all(mid, end, fa, fb, out):
    """Into ``out[e]``: the kind of edge ``e`` from its brackets ``mid[:, e]`` after the first
    and ``end[:, e]`` after the last round (columns: lo, hi, f_lo, f_hi, lo_inside), every
    edge: one pass over contiguous columns without a branch, which vectorises (10x faster a
    row than deciding the refined rows through their indices)."""
    for e in range(fa.size):
        f_lo2, f_hi2 = mid[2, e], mid[3, e]
        lo4, hi4, f_lo4, f_hi4 = end[0, e], end[1, e], end[2, e], end[3, e]
        kept_lo = lo4 == 0.0  # the bracket still starts at sample a
        kept_hi = hi4 == 1.0  # ... or still ends at sample b
        outside_end = f_hi4 if end[4, e] != 0.0 else f_lo4
        a, b = abs(fa[e]), abs(fb[e])
        scale = (a if np.isfinite(fa[e]) else 0.0) + (b if np.isfinite(fb[e]) else 0.0)
        m2 = _nanmax(0.0 if kept_lo else abs(f_lo2), 0.0 if kept_hi else abs(f_hi2))
        m4 = _nanmax(0.0 if kept_lo else abs(f_lo4), 0.0 if kept_hi else abs(f_hi4))
        kept_value = a if kept_lo else (b if kept_hi else 0.0)
        # & and | rather than and/or: no short-circuit branches
        kept_small = (not (kept_lo | kept_hi)) | (kept_value <= ROOT_KEPT * scale)
        root = kept_small & ((m4 <= ROOT_SHRINK * m2) | (m4 <= ROOT_FLOOR * scale))
        ends = _nanmax(abs(f_lo4), abs(f_hi4) if np.isfinite(f_hi4) else 0.0)
        pole = (
            np.isinf(outside_end)
            | ((m4 >= POLE_GROWTH * m2) & (m4 > 0.0))
            | (ends >= POLE_SCALE * scale)
        )
        # F becoming NaN is a domain's edge: a jump
        is_pole = pole & (not np.isnan(outside_end))
        is_root = root & np.isfinite(outside_end)
        out[e] = np.uint8(ROOT) if is_root else (np.uint8(POLE) if is_pole else np.uint8(JUMP))


@njit(**INLINE)
def _split(now, e, s, f):
    """Keep the part of bracket ``now[:, e]`` (lo, hi, f_lo, f_hi, lo_inside) where the side
    changes, given ``f = F(s) - level`` at a point ``s`` inside it."""
    inside = np.isfinite(f) and f < 0.0
    lower = (now[4, e] != 0.0) != inside  # the side changes between lo and s
    # selects, not branches: which half keeps the change is unpredictable
    now[1, e] = s if lower else now[1, e]
    now[3, e] = f if lower else now[3, e]
    now[0, e] = now[0, e] if lower else s
    now[2, e] = now[2, e] if lower else f
    now[4, e] = now[4, e] if lower else (1.0 if inside else 0.0)


@njit(**KERNEL)
def _bisect(prog, tile, active, rows, ctx, level, u0, h, now, sel):
    """One bisection of the brackets ``now[:, sel]`` in place (one batch of points)."""
    m = sel.size
    u = np.empty(m)
    fm = np.empty(m)
    for r in range(m):
        e = unsigned(sel[r])
        u[r] = u0[e] + 0.5 * (now[0, e] + now[1, e]) * h
    eval_edges(prog, tile, active, rows, ctx, sel, u, fm)
    for r in range(m):
        e = unsigned(sel[r])
        _split(now, e, 0.5 * (now[0, e] + now[1, e]), fm[r] - level)
    return m


@njit(**KERNEL)
def _wider(now, first, sel):
    """The rows of ``sel`` whose bracket is wider than a quarter of the ``first`` one."""
    out = np.empty(sel.size, dtype=np.int64)
    m = 0
    for r in range(sel.size):
        e = unsigned(sel[r])
        if now[1, e] - now[0, e] > 0.25 * (first[1, e] - first[0, e]):
            out[m] = e
            m += 1
    return out[:m]


@njit(**KERNEL)
def _first_point(fa, fb):
    """The first point on an edge at the grid's border (no neighbours tell its profile): the
    secant estimate ``fa / (fa - fb)`` rounded to a multiple of ``1 / SECANT_GRID`` strictly
    inside the edge (the middle where it is NaN)."""
    u = fa / (fa - fb)
    if u != u:
        u = 0.5
    return min(max(np.round(u * SECANT_GRID), 1.0), SECANT_GRID - 1.0) / SECANT_GRID


@njit(**KERNEL)
def _secant_in(now, e):
    """The secant estimate of the crossing in bracket ``now[:, e]``, rounded to a multiple of
    ``1 / SECANT_GRID`` strictly inside it (its middle where the estimate is NaN)."""
    lo, hi = now[0, e], now[1, e]
    u = now[2, e] / (now[2, e] - now[3, e])
    if u != u:
        u = 0.5
    k = np.round((lo + u * (hi - lo)) * SECANT_GRID)
    k = min(max(k, lo * SECANT_GRID + 1.0), hi * SECANT_GRID - 1.0)
    return k / SECANT_GRID


@njit(**KERNEL)
def _classify_axis(prog, tile, active, rows, ctx, level, u0, h, a_inside, fa, fb, t):
    """Kinds of the suspect edges along one axis (steps 2 to 4 of the module's docstring),
    ``u0``: their first samples' coordinate along it, ``h`` the spacing, ``t`` where the first
    point goes on each; returns the kinds and the number of points evaluated."""
    n = fa.size
    u = np.empty(n)
    for e in range(n):
        u[e] = u0[e] + t[e] * h
    fs = np.empty(n)
    eval_edges(prog, tile, active, rows, ctx, np.arange(n), u, fs)
    out = np.full(n, ROOT, dtype=np.uint8)
    points = n
    # the brackets, one column an edge: lo, hi, f_lo, f_hi, lo_inside (1.0/0.0); the first
    # point splits the edge
    now = np.empty((5, n))
    rest = np.empty(n, dtype=np.int64)
    dips = np.empty(n, dtype=np.int64)
    m = 0
    n_dips = 0
    for e in range(n):  # without a branch per verdict: roots and walls interleave
        f = fs[e] - level
        a, b = abs(fa[e]), abs(fb[e])
        finite = (
            fa[e] == fa[e]
            and fb[e] == fb[e]
            and (fa[e] / (fa[e] - fb[e])) == (fa[e] / (fa[e] - fb[e]))
        )
        inside = np.isfinite(f) and f < 0.0
        upper = inside == a_inside[e]  # the side changes between the point and sample b
        far = a if upper else b  # the sample on the point's side
        root = finite and abs(f) < NEAR_ROOT * far
        lo = t[e] if upper else 0.0
        hi = 1.0 if upper else t[e]
        now[0, e], now[1, e] = lo, hi
        now[2, e] = f if upper else fa[e]
        now[3, e] = fb[e] if upper else f
        now[4, e] = 1.0 if a_inside[e] else 0.0  # the side at lo is sample a's either way
        rest[m] = e
        m += not root
        room = (hi - lo) * SECANT_GRID >= 2.0  # a point strictly inside
        dips[n_dips] = e
        # |F| dips below the sample: not a wall's profile
        n_dips += (not root) and finite and abs(f) < far and room
    before = now.copy()
    # a secant step inside the half where |F| dipped: a root there shows in one more point
    if n_dips:
        sel = dips[:n_dips]
        for r in range(n_dips):
            u[r] = u0[sel[r]] + _secant_in(now, sel[r]) * h
        f2 = np.empty(n_dips)
        eval_edges(prog, tile, active, rows, ctx, sel, u[:n_dips], f2)
        points += n_dips
        for r in range(n_dips):
            e = sel[r]
            s = _secant_in(now, e)
            f = f2[r] - level
            inside = np.isfinite(f) and f < 0.0
            lo_inside = now[4, e] != 0.0
            end = abs(now[2, e]) if inside == lo_inside else abs(now[3, e])
            if abs(f) < NEAR_ROOT * end:
                now[0, e] = -1.0  # a root: dropped from rest below
            else:
                _split(now, e, s, f)
        keep = 0
        for r in range(m):
            if now[0, rest[r]] >= 0.0:
                rest[keep] = rest[r]
                keep += 1
        m = keep
    rest = rest[:m]
    # bisections until the bracket is 4x narrower than the first one
    for _ in range(BISECTIONS):
        sel = _wider(now, before, rest)
        points += _bisect(prog, tile, active, rows, ctx, level, u0, h, now, sel)
    # a bracket still ending at a sample that reads as a jump is bisected twice more (a steep
    # root next to a sample shows only closer to it); so is a jump whose M shrank, but by less
    # than a root's (a root on the flank of a spike, or curved, shrinks as the bracket closes
    # in; a jump's M stays): the held ones first, then those of them that read so after it.
    # Both sets in the same rounds (the rows are independent: the kinds are those of one set
    # after the other, in fewer calls)
    # (kinds are decided for every edge, in one vectorised pass; those of the roots not in rest
    # mean nothing and are not read)
    kinds = np.empty(n, dtype=np.uint8)
    _decide_all(before, now, fa, fb, kinds)
    held = np.empty(m, dtype=np.bool_)
    pick = np.empty(m, dtype=np.bool_)
    for r in range(m):
        e = rest[r]
        held[r] = (now[0, e] == 0.0 or now[1, e] == 1.0) and kinds[e] == JUMP
        pick[r] = held[r] or (kinds[e] == JUMP and _shrink(before, now, e) < UNSURE)
    points += _decide_again(prog, tile, active, rows, ctx, level, u0, h, now, before, fa, fb,
                            rest, kinds, pick)  # fmt: skip
    for r in range(m):
        e = rest[r]
        pick[r] = held[r] and kinds[e] == JUMP and _shrink(before, now, e) < UNSURE
    points += _decide_again(prog, tile, active, rows, ctx, level, u0, h, now, before, fa, fb,
                            rest, kinds, pick)  # fmt: skip
    for r in range(m):
        out[rest[r]] = kinds[rest[r]]
    return out, points


@njit(**KERNEL)
def _decide_again(prog, tile, active, rows, ctx, level, u0, h, now, before, fa, fb, rest, kinds,
                  pick):  # fmt: skip
    """Bisect the brackets of the edges ``rest[r]`` with ``pick[r]`` ``BISECTIONS`` more times
    and decide the ``kinds`` again from the brackets before and after (the others' brackets
    did not change, so neither do their kinds); returns the number of points evaluated."""
    sel = np.empty(rest.size, dtype=np.int64)
    count = 0
    for r in range(rest.size):
        if pick[r]:
            e = unsigned(rest[r])
            sel[count] = e
            count += 1
            for k in range(5):
                before[k, e] = now[k, e]
    if count == 0:
        return 0
    points = 0
    for _ in range(BISECTIONS):
        points += _bisect(prog, tile, active, rows, ctx, level, u0, h, now, sel[:count])
    _decide_all(before, now, fa, fb, kinds)
    return points


@njit(**KERNEL)
def _shrink(mid, end, e):
    """``M2 / M1`` of edge ``e`` as :func:`_decide_all` measures them (1 where M1 is 0 or
    NaN)."""
    kept_lo = end[0, e] == 0.0
    kept_hi = end[1, e] == 1.0
    m2 = _nanmax(0.0 if kept_lo else abs(mid[2, e]), 0.0 if kept_hi else abs(mid[3, e]))
    m4 = _nanmax(0.0 if kept_lo else abs(end[2, e]), 0.0 if kept_hi else abs(end[3, e]))
    if not (m2 > 0.0) or m4 != m4:
        return 1.0
    return m4 / m2


@njit(**KERNEL)
def _bisect_kernel(
    prog,
    tile,
    active,
    rows,
    level,
    axes,
    spacing,
    edge_ijk,
    edge_axis,
    idx,
    a_inside,
    fa,
    fb,
    kinds,
):
    """Kinds of the suspect edges (from grid indices ``edge_ijk`` along ``edge_axis``) into
    ``kinds[idx]``, axis by axis (:func:`_classify_axis`; the formula's levels that do not vary
    along an axis are computed once per edge, :func:`points.edge_lattice`).  Returns the
    number of points evaluated."""
    n = idx.size
    # the suspects grouped by axis (in their order within an axis), without numpy's fancy
    # indexing: their starts, grid indices and samples
    starts = np.zeros(4, dtype=np.int64)
    for r in range(n):
        starts[edge_axis[r] + 1] += 1
    for a in range(3):
        starts[a + 1] += starts[a]
    order = np.empty(n, dtype=np.int64)
    ijk = np.empty((n, 3), dtype=np.int64)
    s_in = np.empty(n, dtype=np.bool_)
    s_fa = np.empty(n)
    s_fb = np.empty(n)
    fill = starts[:3].copy()
    for r in range(n):  # one pass: reads in order, writes three streams
        a = edge_axis[r]
        q = fill[a]
        fill[a] += 1
        order[q] = r
        for k in range(3):
            ijk[q, k] = edge_ijk[r, k]
        s_in[q], s_fa[q], s_fb[q] = a_inside[r], fa[r], fb[r]
    points = 0
    for a in range(3):
        s0, s1 = starts[a], starts[a + 1]
        m = s1 - s0
        if m == 0:
            continue
        sub = ijk[s0:s1]
        ctx = edge_lattice(prog, tile, active, rows, a, sub, axes)
        u0 = np.empty(m)
        t = np.empty(m)
        for r in range(m):
            pos = sub[r, a]
            u0[r] = axes[a][pos]
            border = pos < 1 or pos + 2 >= axes[a].size  # no grid line to judge the profile
            t[r] = _first_point(s_fa[s0 + r], s_fb[s0 + r]) if border else 0.5
        got, pts = _classify_axis(
            prog,
            tile,
            active,
            rows,
            ctx,
            level,
            u0,
            spacing[a],
            s_in[s0:s1],
            s_fa[s0:s1],
            s_fb[s0:s1],
            t,
        )
        for r in range(m):
            kinds[idx[order[s0 + r]]] = got[r]
        points += pts
    return points
