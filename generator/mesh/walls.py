"""Walls: the parts of a marching-cubes mesh that are not the zero set F = level.

Marching cubes puts a vertex on every grid edge whose samples lie on opposite sides of the
level.  F may cross the level there (a *root*: the surface), pass through infinity (a *pole*:
tan, cot, sec, csc, 1/u) or jump over the level without taking it (a *jump*: the resets of
``atan(tan u)``, ``acot(cot u)``, the staircase and pulse functions, the edge of a domain where F
becomes NaN).  Poles and jumps give *walls*: they bound the solid {F < level}, but they are not
the zero set.

:func:`classify_edges` tells them apart in four steps, cheapest first:

1. *Samples.*  A crossing looks like a smooth root, and is taken as one, when the secants of
   its grid line around it (``dm``, ``d``, ``dp``: the edge's and its two neighbours') are
   finite and either have one sign with ``|d|`` at most ``SMOOTH_RATIO`` times the larger
   neighbour, or change so little that the third difference ``|dp - 2 d + dm|`` is at most
   ``SMOOTH_THIRD`` times ``|dm| + |dp|`` (F bends smoothly through an extremum: a pole or a
   jump on the edge makes it about twice the pole's or the jump's size).  Everything else
   (poles and resets against the neighbours' slopes, steep steps, non-finite neighbours, edges
   at the grid's border) is *suspect*.
2. *Midpoint.*  F at the edge's middle (at an edge on the grid's border, which has no grid line
   to judge its profile, at the secant estimate rounded to a sixteenth of the edge): a root
   when ``|F| < NEAR_ROOT * |F(s)|``, ``s`` the sample on the same side of the level as the
   midpoint (a pole or a jump keeps |F| at least as large as that sample's between it and the
   wall: |F| does not fall away from a wall; a sample exactly at the level never certifies).
   ``NEAR_ROOT`` is 1/2: F linear through a root anywhere on the edge has
   ``|F(1/2)| <= |F(s)| / 2``, so the midpoint settles every near-linear root, halfway between
   a root's profile and a wall's.  Else the half edge where the side changes is the bracket.
3. *Secant step.*  Where |F| at the midpoint is below that sample's (not a wall's profile), F
   at the secant estimate inside the half edge (rounded to a sixteenth of the edge): a root by
   the same test against the bracket's end on its side; else it narrows the bracket.
4. *Bisection.*  The bracket is bisected until it is a quarter of the first one (at most
   twice); where it still ends at a sample and reads as a jump (below), twice more (a steep
   root next to a sample shows only closer to it: until then its ``M`` stays, as a jump's; it
   does not grow as a pole's, so a bracket that reads as a pole is not held); where it reads as a jump whose ``M``
   shrank, but to more than ``ROOT_SHRINK`` and less than ``UNSURE`` of ``M1``, twice more (a
   root on the flank of a spike, or a curved one, keeps shrinking; a jump's ``M`` stays).
   ``M`` is the largest ``|F - level|`` at a bracket's ends, leaving out an end that is still a
   sample; ``M1`` before and ``M2`` after the last narrowing (a bracket at least 4x narrower):

   - root: ``M2 <= ROOT_SHRINK * M1`` (|F| keeps shrinking towards 0: 4x for a simple root)
     or ``M2`` below ``ROOT_FLOOR`` of the samples' ``|fa| + |fb|`` (rounding noise at a
     root); a sample kept as an end must itself be within ``ROOT_KEPT`` of that scale;
   - pole: F is infinite at the bracket, ``M2 >= POLE_GROWTH * M1`` (|F| grows: 4x for 1/u),
     or an end ``POLE_SCALE`` times the samples' scale (a pole a bisection hit early, or one
     next to a sample);
   - jump: otherwise (|F| stays bounded away from 0 on both sides, or F becomes NaN: the edge
     of a domain).

   A suspect costs one point when the midpoint shows a root, two when the secant step does,
   else three (five for a jump next to a sample or where M shrank a little), plus the secant step where
   |F| dipped.

Every point lies on a grid edge at a dyadic fraction of it (1/2, 1/4, 1/8, ...), so the formula
is evaluated axis by axis (:func:`points.eval_edges`): the parts of the formula that do not
involve the edge's axis once per edge, the parts in that axis alone or with one other once per
distinct value or pair (the midpoints of all edges of one grid slab share one x), only the part
in all three variables once per point.

Jumps smaller than about the change of F across one cell look like roots at this resolution and
are counted as roots. Where F oscillates faster than the grid resolves (a bracket with several
side changes), bisection follows one of them, so kinds there are a guess.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numba import njit

from surfgen.generator.errors import EmptySurface, SpecError
from surfgen.generator.eval.evaluate import points_evaluator
from surfgen.generator.eval.grid import Field
from surfgen.generator.eval.row_operations import unsigned
from surfgen.generator.eval.sparse import SparseField
from surfgen.generator.formula.expr import Expr
from surfgen.generator.jit.options import KERNEL
from surfgen.generator.mesh.mesh import (
    CAP,
    JUMP,
    POLE,
    ROOT,
    WALL_KINDS,
    Mesh,
    compact_mesh,
    extract_with_edges,
    face_area,
)
from surfgen.generator.mesh.refine import refine_suspects

log = logging.getLogger(__name__)

WALL_MODES = ("keep", "remove", "mark")

SMOOTH_RATIO = 2.0
SMOOTH_THIRD = 1.0
UNKNOWN = 255  # a vertex on no crossing grid edge (cap vertices, cell-interior vertices)
_NO_AREAS = np.empty(0)  # _label_faces makes each face's area itself


@dataclass(frozen=True)
class WallReport:
    """How the crossings of one mesh were classified.

    ``edges``: crossing edges under vertices; ``refined``: how many of them were looked at
    with the formula (a secant step, then the bisections if needed); ``points``: how many
    points the formula was evaluated at; ``roots``, ``poles``, ``jumps``: the result;
    ``wall_fraction``: share of the mesh's area on wall faces.
    """

    edges: int
    refined: int
    points: int
    roots: int
    poles: int
    jumps: int
    wall_fraction: float

    def to_dict(self) -> dict[str, float | int]:
        return {
            "edges": self.edges,
            "refined": self.refined,
            "points": self.points,
            "roots": self.roots,
            "poles": self.poles,
            "jumps": self.jumps,
            "wall_fraction": self.wall_fraction,
        }


def check_walls_mode(walls: str) -> str:
    """``walls`` if it is one of :data:`WALL_MODES`; else :class:`ValueError`-free one-line
    :class:`~surfgen.generator.errors.SpecError`."""
    if walls not in WALL_MODES:
        raise SpecError(f"unknown --walls mode '{walls}' (allowed: {', '.join(WALL_MODES)})")
    return walls


def extract_labelled(
    field: Field,
    tree: Expr,
    params: Mapping[str, float] | None = None,
    level: float = 0.0,
    cap: bool = False,
    walls: str = "mark",
    threads: int = 1,
) -> tuple[Mesh, WallReport]:
    """Mesh ``F = level`` and classify its faces (see the module's docstring).

    ``walls``: ``keep`` and ``mark`` return the whole mesh (with ``face_kinds`` for ``mark``);
    ``remove`` returns only the faces on roots, without caps (the zero set is open where the box
    cuts it).  ``tree``/``params`` must be the formula ``field`` was sampled from.
    The report's ``wall_fraction`` is measured on the mesh extracted (with its caps, except
    for ``remove``, which extracts without them).  ``threads``: the suspect crossings are
    refined on that many (:func:`classify_edges`; the same result on any number).
    Raises :class:`EmptySurface` when there is no crossing, or with ``remove`` when no
    crossing is a root.
    """
    check_walls_mode(walls)
    mesh, edges = extract_with_edges(field, level, cap and walls != "remove")
    return label_walls(mesh, edges, field, tree, params, level, cap, walls, threads=threads)


def label_walls(
    mesh: Mesh,
    edges: np.ndarray,
    field: Field | SparseField,
    tree: Expr,
    params: Mapping[str, float] | None = None,
    level: float = 0.0,
    cap: bool = False,
    walls: str = "mark",
    areas: np.ndarray | None = None,
    lines: np.ndarray | None = None,
    threads: int = 1,
) -> tuple[Mesh, WallReport]:
    """The second half of :func:`extract_labelled`, for a mesh and edges that
    :func:`~surfgen.generator.mesh.mesh.extract_with_edges` made (with ``cap`` off for ``remove``):
    lets a caller look at the mesh before paying for the classification.  ``areas``: the
    mesh's face areas (:func:`~surfgen.generator.mesh.mesh.face_areas`) where the caller has them
    (the sampler's filters need them too: computed once); else computed here.  ``lines``: F
    at the four samples of each edge's grid line (a sparse field's,
    :func:`~surfgen.generator.mesh.sparse_marching.sparse_edge_lines`); ``field`` is then only
    read for its grid.  ``threads``: as :func:`extract_labelled`'s."""
    check_walls_mode(walls)
    if areas is not None and len(areas) != mesh.n_faces:
        raise ValueError(f"{len(areas)} face areas for {mesh.n_faces} faces")
    kinds, refined, points = _classify(field, tree, params, level, edges, lines, threads)
    roots, poles, jumps = _count_kinds(kinds)
    any_wall = bool(poles + jumps)
    if walls == "keep" and not any_wall:  # no face can be a wall: no faces to label
        face_kinds, wall, total = None, 0.0, 0.0
    else:  # one pass labels the faces and, with walls, sums the areas (wall_share's sums)
        face_kinds, wall, total = _label_faces(
            mesh.vertices,
            mesh.faces,
            kinds,
            cap and walls != "remove",
            np.asarray(field.grid.box.lo, dtype=np.float64),
            np.asarray(field.grid.box.hi, dtype=np.float64),
            any_wall,
            np.ascontiguousarray(
                areas if any_wall and areas is not None else _NO_AREAS, dtype=np.float64
            ),
        )
    report = WallReport(
        edges=int(roots + poles + jumps),
        refined=refined,
        points=points,
        roots=int(roots),
        poles=int(poles),
        jumps=int(jumps),
        wall_fraction=float(wall / total) if wall > 0.0 and total > 0.0 else 0.0,
    )
    log.debug("walls: %s", report)
    if walls == "keep":
        return mesh, report
    if walls == "mark":
        return Mesh(mesh.vertices, mesh.faces, face_kinds), report
    keep = ~np.isin(face_kinds, WALL_KINDS)
    if not keep.any():
        raise EmptySurface(
            f"no root: all {report.edges} crossings of F = {level:g} are poles or jumps "
            "(walls), so --walls remove leaves nothing; use --walls keep or mark"
        )
    out = compact_mesh(mesh.vertices, mesh.faces[keep])
    return Mesh(out.vertices, out.faces, face_kinds[keep]), report


def classify_edges(
    field: Field,
    tree: Expr,
    params: Mapping[str, float] | None,
    level: float,
    edges: np.ndarray,
    threads: int = 1,
) -> tuple[np.ndarray, int]:
    """Kind (ROOT, POLE, JUMP, or UNKNOWN) of each ``(axis, i, j, k)`` edge of ``edges`` (V, 4).

    Rows with axis -1, or whose samples are on the same side, are UNKNOWN.  Returns uint8
    ``(V,)`` kinds and the number of edges looked at with the formula (the suspects).
    The suspects are refined with the formula
    (:func:`~surfgen.generator.mesh.refine.refine_suspects`: the midpoint, the secant step, the
    bisections and the decision, the formula through :func:`points.eval_edges`), on
    ``threads`` threads (the same kinds on any number).
    """
    kinds, refined, _points = _classify(field, tree, params, level, edges, threads=threads)
    return kinds, refined


def _classify(
    field: Field | SparseField,
    tree: Expr,
    params: Mapping[str, float] | None,
    level: float,
    edges: np.ndarray,
    lines: np.ndarray | None = None,
    threads: int = 1,
) -> tuple[np.ndarray, int, int]:
    """:func:`classify_edges`, and how many points the formula was evaluated at.  ``lines``: F
    at the four samples of each row's grid line, ``(4, V)``, instead of reading them in
    ``field.values`` (a sparse field's, :func:`~.sparse_marching.sparse_edge_lines`);
    ``threads``: the suspects' refinement's."""
    shape = np.asarray(field.grid.shape, dtype=np.int64)
    edges = np.ascontiguousarray(edges, dtype=np.int64)
    if lines is None:
        values = np.ascontiguousarray(field.values, dtype=np.float64).reshape(-1)
        kinds, idx, fa, fb, ina, ijk, axis = _crossings_core(
            values, shape, edges, float(level), SMOOTH_RATIO
        )
    else:
        inner, both = _line_flags(shape, edges)
        kinds, idx, fa, fb, ina, ijk, axis = _crossings_of_lines(
            np.ascontiguousarray(lines, dtype=np.float64),
            inner,
            both,
            edges,
            float(level),
            SMOOTH_RATIO,
        )
    if idx.size == 0:
        return kinds, 0, 0
    prog, tile, active, rows = points_evaluator(tree, params).kernel_args()
    ax, ay, az = (np.ascontiguousarray(a, dtype=np.float64) for a in field.grid.axes())
    points = refine_suspects(
        prog,
        tile,
        active,
        rows,
        float(level),
        (ax, ay, az),
        np.asarray(field.grid.spacing, dtype=np.float64),
        ijk,
        axis,
        idx,
        ina,
        fa,
        fb,
        kinds,
        threads,
    )
    return kinds, int(idx.size), int(points)


@njit(**KERNEL)
def _crossings(values, shape, edges, level, ratio):
    """Kinds of the vertices' edges from the samples alone, and the suspects.

    Rows with axis -1, at the grid's end, or whose samples are on the same side (inside is
    ``F < level``, finite) are UNKNOWN, the others ROOT.  A crossing is *suspect* unless both
    neighbours along its grid line exist and the secants look smooth (step 1 of the module's
    docstring): returns
    the kinds, and for the suspects their rows, ``fa``, ``fb`` (``F - level`` at the edge's
    samples) and whether sample a is inside.
    """
    kinds, rows, fa, fb, ina, _ijk, _axis = _crossings_core(values, shape, edges, level, ratio)
    return kinds, rows, fa, fb, ina


@njit(**KERNEL)
def _crossings_core(values, shape, edges, level, ratio):
    """:func:`_crossings`, and the suspects' grid indices ``(i, j, k)`` and axes.

    Three passes, so that the test runs on arrays: the samples of every row's grid line
    (scalar loads), the test itself (no loads, no branches: it vectorises), then the suspects
    gathered (:func:`_crossings_of_lines`).  Indices are unsigned
    (:func:`row_operations.unsigned`)."""
    n = edges.shape[0]
    # F at the edge's samples a, b and at its neighbours before a and after b along the grid
    # line; a neighbour that does not exist (the grid's border) is the edge's own sample, and
    # a row on no edge (axis -1, or at the grid's end) reads sample 0 four times
    line = np.empty((4, n))
    inner = np.empty(n, dtype=np.bool_)  # on a grid edge
    both = np.empty(n, dtype=np.bool_)  # ... with both neighbours
    s0 = shape[1] * shape[2]
    s1 = shape[2]
    for v in range(n):
        axis = edges[v, 0]
        i, j, k = edges[v, 1], edges[v, 2], edges[v, 3]
        pos = i if axis == 0 else (j if axis == 1 else k)
        length = shape[0] if axis == 0 else (shape[1] if axis == 1 else shape[2])
        step = s0 if axis == 0 else (s1 if axis == 1 else 1)
        on_edge = (axis >= 0) & (pos + 1 < length)
        ia = np.uint64(i * s0 + j * s1 + k if on_edge else 0)
        us = np.uint64(step if on_edge else 0)
        lo_ok = pos >= 1
        hi_ok = pos + 2 < length
        ib = ia + us
        line[0, v] = values[ia - us * np.uint64(lo_ok)]
        line[1, v] = values[ia]
        line[2, v] = values[ib]
        line[3, v] = values[ib + us * np.uint64(hi_ok)]
        inner[v] = on_edge
        both[v] = on_edge & lo_ok & hi_ok
    return _crossings_of_lines(line, inner, both, edges, level, ratio)


@njit(**KERNEL)
def _line_flags(shape, edges):
    """Per row: whether it is on a grid edge, and whether that edge has both neighbours along
    its grid line (as :func:`_crossings_core` reads them)."""
    n = edges.shape[0]
    inner = np.empty(n, dtype=np.bool_)
    both = np.empty(n, dtype=np.bool_)
    for v in range(n):
        axis = edges[v, 0]
        pos = edges[v, 1 + axis] if axis >= 0 else 0
        length = shape[axis] if axis >= 0 else 0
        on_edge = (axis >= 0) & (pos + 1 < length)
        inner[v] = on_edge
        both[v] = on_edge & (pos >= 1) & (pos + 2 < length)
    return inner, both


@njit(**KERNEL)
def _crossings_of_lines(line, inner, both, edges, level, ratio):
    """The test and the suspects of :func:`_crossings_core` from F at each row's four line
    samples ``line`` (4, V) (a sparse field gives them without a dense array)."""
    n = edges.shape[0]
    kinds = np.empty(n, dtype=np.uint8)
    suspect = np.empty(n, dtype=np.bool_)
    for v in range(n):
        fm = line[0, v] - level
        fa = line[1, v] - level
        fb = line[2, v] - level
        fp = line[3, v] - level
        ina = (fa < 0.0) & (fa > -np.inf)  # inside: finite and below the level
        inb = (fb < 0.0) & (fb > -np.inf)
        crossing = inner[v] & (ina != inb)
        kinds[v] = ROOT if crossing else UNKNOWN
        # one sign: np.sign(dm) == np.sign(d) == np.sign(dp) (d is not 0 at a crossing)
        d = fb - fa
        dm = fa - fm
        dp = fp - fb
        one_sign = ((dm > 0.0) == (d > 0.0)) & (dm != 0.0) & ((dp > 0.0) == (d > 0.0)) & (dp != 0.0)
        total = dm + d + dp
        adm = abs(dm)
        adp = abs(dp)
        larger = adm if adm > adp else adp
        smooth = (
            both[v]
            & (total - total == 0.0)  # all finite
            & (
                (one_sign & (abs(d) <= ratio * larger))
                | (abs(dp - 2.0 * d + dm) <= SMOOTH_THIRD * (adm + adp))
            )
        )
        suspect[v] = crossing & (not smooth)
    rows = np.empty(n, dtype=np.int64)
    count = 0
    for v in range(n):  # without a branch: suspects and smooth roots interleave
        rows[count] = v
        count += suspect[v]
    rows = rows[:count]
    out_a = np.empty(count)
    out_b = np.empty(count)
    out_in = np.empty(count, dtype=np.bool_)
    out_ijk = np.empty((count, 3), dtype=np.int64)
    out_axis = np.empty(count, dtype=np.int64)
    for q in range(count):
        v = rows[q]
        fa = line[1, v] - level
        out_a[q] = fa
        out_b[q] = line[2, v] - level
        out_in[q] = (fa < 0.0) & (fa > -np.inf)
        for c in range(3):
            out_ijk[q, c] = edges[v, 1 + c]
        out_axis[q] = edges[v, 0]
    return kinds, rows, out_a, out_b, out_in, out_ijk, out_axis


@njit(**KERNEL)
def _count_kinds(kinds):
    """How many ROOT, POLE and JUMP kinds: three compares a kind, which vectorise (a histogram's
    increments of one counter after another wait on each other, as runs of one kind are the
    rule)."""
    roots = poles = jumps = 0
    for k in kinds:
        roots += k == ROOT
        poles += k == POLE
        jumps += k == JUMP
    return roots, poles, jumps


@njit(**KERNEL)
def _label_faces(v, f, kinds, cap, lo, hi, sums, areas):
    """uint8 ``(F,)`` kind of each face from its vertices' edge ``kinds``; with ``sums``, also
    the area on wall faces and in all from the faces' ``areas``
    (:func:`~surfgen.generator.mesh.mesh.wall_share`'s sums: the same operations in face order),
    or, where ``areas`` is empty, from each face's area made here
    (:func:`~surfgen.generator.mesh.mesh.face_area`, as ``face_areas`` makes it: the same bits,
    without an array of them: equation C's 5.8 million faces at 512^3, 47 MB faulted in and
    50 ms).

    With ``cap``, faces lying on a box face (``lo``, ``hi``) are CAP.  Otherwise a face is a wall
    when most of its labelled vertices are walls (a pole if any of those is a pole, else a
    jump), else ROOT.

    One code per vertex, so that a face needs three loads and no branch per vertex (walls and
    roots interleave): the low byte counts ``known + 4 wall + 16 pole`` (the sums of three stay
    below 64, so the fields do not carry into each other), the high byte has one bit per box
    face the vertex lies on (a cap face has a bit all three share)."""
    n_vertices = v.shape[0]
    table = np.zeros(256, dtype=np.int32)  # UNKNOWN counts for nothing
    table[ROOT] = 1
    table[POLE] = 1 + 4 + 16
    table[JUMP] = 1 + 4
    code = np.empty(n_vertices, dtype=np.int32)
    for i in range(n_vertices):
        b = np.int32(0)
        if cap:
            for k in range(3):
                b |= np.int32(v[i, k] == lo[k]) << (2 * k)
                b |= np.int32(v[i, k] == hi[k]) << (2 * k + 1)
        code[i] = table[kinds[i]] | (b << 8)
    n_faces = f.shape[0]
    own_areas = areas.shape[0] == 0  # none given (label_walls checked any given)
    out = np.empty(n_faces, dtype=np.uint8)
    wall_area = 0.0
    total = 0.0
    for n in range(n_faces):
        i0, i1, i2 = f[n, 0], f[n, 1], f[n, 2]
        c0, c1, c2 = code[unsigned(i0)], code[unsigned(i1)], code[unsigned(i2)]
        counts = (c0 + c1 + c2) & 255
        kind = ROOT
        if 2 * ((counts >> 2) & 3) > (counts & 3):  # most of its labelled vertices are walls
            kind = POLE if counts >= 16 else JUMP
        if (c0 & c1 & c2) >> 8 != 0:
            kind = CAP
        out[n] = kind
        if sums:
            a = face_area(v, i0, i1, i2) if own_areas else areas[n]
            total += a
            if kind == POLE or kind == JUMP:  # noqa: SIM109 (numba)
                wall_area += a
    return out, wall_area, total
