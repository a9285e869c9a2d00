"""Walls: the parts of a marching-cubes mesh that are not the zero set F = level.

Marching cubes puts a vertex on every grid edge whose samples lie on opposite sides of the
level.  F may cross the level there (a *root*: the surface), pass through infinity (a *pole*:
tan, cot, sec, csc, 1/u) or jump over the level without taking it (a *jump*: the resets of
``atan(tan u)``, ``acot(cot u)``, the staircase and pulse functions, the edge of a domain where F
becomes NaN).  Poles and jumps give *walls*: they bound the solid {F < level}, but they are not
the zero set.

:func:`classify_edges` tells them apart in three steps, cheapest first:

1. *Samples.*  A crossing whose secant slope has the sign of both neighbouring secants along
   the same grid line, and is at most ``SMOOTH_RATIO`` times the larger of them, looks like a
   smooth root and is taken as one.  Everything else (opposite slopes: poles and downward
   resets; steep steps; non-finite neighbours; edges at the grid's border) is *suspect*.
2. *Secant.*  F at the secant point ``t* = fa / (fa - fb)``: a root when
   ``|F(t*)| < SECANT_ROOT * min(|fa|, |fb|)`` (a pole or a jump keeps |F| of the order of its
   samples' there; a sample exactly at the level never certifies, min being 0).
3. *Refinement.*  Two rounds of three points shrink the bracket around the side change to 1/4,
   then 1/16 of the edge.  ``M`` is the largest ``|F - level|`` at the bracket's ends, leaving
   out an end that is still an original sample; ``M4``, ``M16`` after each round:

   - root: ``M16 <= ROOT_SHRINK * M4`` (|F| keeps shrinking towards 0: 4x for a simple root)
     or ``M16`` below ``ROOT_FLOOR`` of the samples' ``|fa| + |fb|`` (rounding noise at a
     root); a sample kept as an end must itself be within ``ROOT_KEPT`` of that scale;
   - pole: F is infinite at the bracket, ``M16 >= POLE_GROWTH * M4`` (|F| grows: 4x for 1/u),
     or an end ``POLE_SCALE`` times the samples' scale (a pole a round hit early, or one next
     to a sample);
   - jump: otherwise (|F| stays bounded away from 0 on both sides, or F becomes NaN: the edge
     of a domain).

Jumps smaller than about half the change of F across one cell look like roots at this
resolution and are counted as roots.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from surfgen.generator.errors import EmptySurface
from surfgen.generator.expr import Expr, postorder
from surfgen.generator.functions import FUNCTIONS
from surfgen.generator.grid import Field
from surfgen.generator.mesh import (
    CAP,
    JUMP,
    POLE,
    ROOT,
    WALL_KINDS,
    Mesh,
    compact_mesh,
    extract_with_edges,
    wall_fraction,
)
from surfgen.generator.reference import _BINARY, evaluate_points

log = logging.getLogger(__name__)

WALL_MODES = ("keep", "remove", "mark")

ROUNDS = 2  # refinement rounds ...
POINTS = 3  # ... of this many points each: the bracket shrinks 4x per round
ROOT_SHRINK = 0.6
ROOT_FLOOR = 1e-9
ROOT_KEPT = 0.25
POLE_GROWTH = 2.5
POLE_SCALE = 4.0
SMOOTH_RATIO = 2.0
SECANT_ROOT = 0.25
SEPARATION_T = 0.01
UNKNOWN = 255  # a vertex on no crossing grid edge (cap vertices, cell-interior vertices)


@dataclass(frozen=True)
class WallReport:
    """How the crossings of one mesh were classified.

    ``edges``: crossing edges under vertices; ``refined``: how many of them were looked at
    with the formula (a secant step, then the refinement if needed); ``roots``, ``poles``, ``jumps``: the result; ``wall_fraction``: share of the
    mesh's area on wall faces.
    """

    edges: int
    refined: int
    roots: int
    poles: int
    jumps: int
    wall_fraction: float

    def to_dict(self) -> dict[str, float | int]:
        return {
            "edges": self.edges,
            "refined": self.refined,
            "roots": self.roots,
            "poles": self.poles,
            "jumps": self.jumps,
            "wall_fraction": self.wall_fraction,
        }


def check_walls_mode(walls: str) -> str:
    """``walls`` if it is one of :data:`WALL_MODES`; else :class:`ValueError`-free one-line
    :class:`~surfgen.generator.errors.SpecError`."""
    from surfgen.generator.errors import SpecError

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
) -> tuple[Mesh, WallReport]:
    """Mesh ``F = level`` and classify its faces (see the module's docstring).

    ``walls``: ``keep`` and ``mark`` return the whole mesh (with ``face_kinds`` for ``mark``);
    ``remove`` returns only the faces on roots, without caps (the zero set is open where the box
    cuts it).  ``tree``/``params`` must be the formula ``field`` was sampled from.
    The report's ``wall_fraction`` is measured on the mesh extracted (with its caps, except
    for ``remove``, which extracts without them).
    Raises :class:`EmptySurface` when there is no crossing, or with ``remove`` when no
    crossing is a root.
    """
    check_walls_mode(walls)
    mesh, edges = extract_with_edges(field, level, cap and walls != "remove")
    return label_walls(mesh, edges, field, tree, params, level, cap, walls)


def label_walls(
    mesh: Mesh,
    edges: np.ndarray,
    field: Field,
    tree: Expr,
    params: Mapping[str, float] | None = None,
    level: float = 0.0,
    cap: bool = False,
    walls: str = "mark",
) -> tuple[Mesh, WallReport]:
    """The second half of :func:`extract_labelled`, for a mesh and edges that
    :func:`~surfgen.generator.mesh.extract_with_edges` made (with ``cap`` off for ``remove``):
    lets a caller look at the mesh before paying for the classification."""
    check_walls_mode(walls)
    kinds, refined = classify_edges(field, tree, params, level, edges)
    face_kinds = face_kinds_of(mesh, edges, kinds, cap and walls != "remove", field)
    labelled = Mesh(mesh.vertices, mesh.faces, face_kinds)
    known = kinds[kinds != UNKNOWN]
    report = WallReport(
        edges=int(known.size),
        refined=refined,
        roots=int(np.count_nonzero(known == ROOT)),
        poles=int(np.count_nonzero(known == POLE)),
        jumps=int(np.count_nonzero(known == JUMP)),
        wall_fraction=float(wall_fraction(labelled)),
    )
    log.debug("walls: %s", report)
    if walls == "keep":
        return mesh, report
    if walls == "mark":
        return labelled, report
    keep = ~np.isin(face_kinds, WALL_KINDS)
    if not keep.any():
        raise EmptySurface(
            f"no root: all {report.edges} crossings of F = {level:g} are poles or jumps "
            "(walls), so --walls remove leaves nothing; use --walls keep or mark"
        )
    out = compact_mesh(mesh.vertices, mesh.faces[keep])
    return Mesh(out.vertices, out.faces, face_kinds[keep]), report


class PointsEvaluator:
    """``tree`` sampled at arbitrary points, the reference's numpy functions node by node.

    The tree is flattened once into a post-order list (shared nodes once), so a call costs one
    numpy operation per node: :func:`~surfgen.generator.reference.evaluate_points` looks every
    node up in a dict keyed by the (recursively hashed) tree, which costs more than the
    arithmetic on the few thousand points a refinement round needs.  Values are the reference's.
    """

    def __init__(self, tree: Expr, params: Mapping[str, float] | None = None) -> None:
        self._tree = tree
        self._params = dict(params or {})
        evaluate_points(tree, 0.0, 0.0, 0.0, self._params)  # raises FormulaError early
        # Children before parents, each node once, without recursion (deep flat sums).
        self._order: list[Expr] = postorder(tree)
        self._slot: dict[int, int] = {id(node): i for i, node in enumerate(self._order)}

    def __call__(self, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
        """F at the points ``(x[i], y[i], z[i])`` (1-D arrays of one length), float64."""
        env = {"x": np.asarray(x, np.float64), "y": np.asarray(y, np.float64)}
        env["z"] = np.asarray(z, np.float64)
        values: list[np.ndarray] = []
        with np.errstate(all="ignore"):
            for node in self._order:
                args = [values[self._slot[id(a)]] for a in node.args]
                values.append(np.asarray(self._apply(node, args, env), dtype=np.float64))
        return np.array(np.broadcast_to(values[-1], env["x"].shape), dtype=np.float64)

    def _apply(self, node: Expr, args: list[np.ndarray], env: dict) -> np.ndarray:
        """One node, exactly as :func:`surfgen.generator.reference._eval` computes it."""
        op = node.op
        if op == "num":
            return np.float64(node.value)
        if op == "var":
            return env[node.value]
        if op == "param":
            return np.float64(self._params[node.value])
        if op == "pi":
            return np.float64(np.pi)
        if op == "neg":
            return np.negative(args[0])
        if op in _BINARY:
            return _BINARY[op](args[0], args[1])
        fdef = FUNCTIONS[op]
        if fdef.const_from is not None:
            consts = [float(np.asarray(a).reshape(-1)[0]) for a in args[fdef.const_from :]]
            args = args[: fdef.const_from] + consts
        return fdef.reference(*args)


def classify_edges(
    field: Field,
    tree: Expr,
    params: Mapping[str, float] | None,
    level: float,
    edges: np.ndarray,
) -> tuple[np.ndarray, int]:
    """Kind (ROOT, POLE, JUMP, or UNKNOWN) of each ``(axis, i, j, k)`` edge of ``edges`` (V, 4).

    Rows with axis -1, or whose samples are on the same side, are UNKNOWN.  Returns uint8
    ``(V,)`` kinds and the number of edges refined with the formula.
    """
    values = np.asarray(field.values, dtype=np.float64).reshape(-1)
    shape = np.asarray(field.values.shape, dtype=np.int64)
    strides = np.array([shape[1] * shape[2], shape[2], 1], dtype=np.int64)
    kinds = np.full(len(edges), UNKNOWN, dtype=np.uint8)
    idx = np.flatnonzero(edges[:, 0] >= 0)
    axis = edges[idx, 0]
    ijk = edges[idx, 1:]
    pos = ijk[np.arange(idx.size), axis]  # index along the edge's axis
    length = shape[axis]
    ok = pos + 1 < length
    idx, axis, ijk, pos, length = idx[ok], axis[ok], ijk[ok], pos[ok], length[ok]
    step = strides[axis]
    ia = ijk @ strides
    ib = ia + step
    with np.errstate(invalid="ignore"):
        fa = values[ia] - level
        fb = values[ib] - level
        ina = np.isfinite(fa) & (fa < 0)
        crossing = ina != (np.isfinite(fb) & (fb < 0))
    sel = np.flatnonzero(crossing)
    idx, axis, ijk, pos, length = idx[sel], axis[sel], ijk[sel], pos[sel], length[sel]
    step, ia, ib, fa, fb, ina = step[sel], ia[sel], ib[sel], fa[sel], fb[sel], ina[sel]
    kinds[idx] = ROOT
    # Neighbours along the same grid line; a missing one (grid border) makes the edge suspect.
    has_m, has_p = pos >= 1, pos + 2 < length
    fm = values[np.where(has_m, ia - step, ia)] - level
    fp = values[np.where(has_p, ib + step, ib)] - level
    suspect = ~(has_m & has_p & _smooth(fm, fa, fb, fp))
    s = np.flatnonzero(suspect)
    if s.size == 0:
        return kinds, 0
    points = PointsEvaluator(tree, params)
    s = s[~_secant_root(points, level, field, ijk[s], axis[s], fa[s], fb[s])]
    if s.size:
        kinds[idx[s]] = _refine(points, level, field, ijk[s], axis[s], ina[s], fa[s], fb[s])
    return kinds, int(suspect.sum())


def _secant_root(
    points: PointsEvaluator,
    level: float,
    field: Field,
    ijk: np.ndarray,
    axis: np.ndarray,
    fa: np.ndarray,
    fb: np.ndarray,
) -> np.ndarray:
    """Suspects that one secant step shows to be roots: ``|F(t*)| < SECANT_ROOT * min(|fa|,
    |fb|)`` where F is linear enough over the edge (a jump or pole keeps |F| of the order of
    its samples' there; a sample exactly at the level never certifies, min being 0)."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        t = np.clip(fa / (fa - fb), SEPARATION_T, 1.0 - SEPARATION_T)
        finite = np.isfinite(t)
        t = np.where(finite, t, 0.5)
        xyz = _edge_points(field, ijk, axis, t[:, None])[:, 0, :]
        f = points(xyz[:, 0], xyz[:, 1], xyz[:, 2]) - level
        return finite & (np.abs(f) < SECANT_ROOT * np.minimum(np.abs(fa), np.abs(fb)))


def _edge_points(field: Field, ijk: np.ndarray, axis: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Points ``(n, m, 3)`` at fractions ``s`` ``(n, m)`` along each edge (sample ``ijk``,
    one step along ``axis``)."""
    axes = field.grid.axes()
    spacing = np.asarray(field.grid.spacing)
    origin = np.stack([axes[k][ijk[:, k]] for k in range(3)], axis=1)  # (n, 3)
    direction = np.eye(3)[axis] * spacing[axis][:, None]  # (n, 3)
    return origin[:, None, :] + s[..., None] * direction[:, None, :]


def _smooth(fm: np.ndarray, fa: np.ndarray, fb: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """Crossings that look like a smooth root on the samples (see the module's docstring)."""
    with np.errstate(invalid="ignore", over="ignore"):
        d = fb - fa
        dm = fa - fm
        dp = fp - fb
        return (
            np.isfinite(dm + d + dp)
            & (np.sign(dm) == np.sign(d))
            & (np.sign(dp) == np.sign(d))
            & (np.abs(d) <= SMOOTH_RATIO * np.maximum(np.abs(dm), np.abs(dp)))
        )


def _refine(
    points: PointsEvaluator,
    level: float,
    field: Field,
    a: np.ndarray,
    axis: np.ndarray,
    a_inside: np.ndarray,
    fa: np.ndarray,
    fb: np.ndarray,
) -> np.ndarray:
    """Refine each edge (sample ``a``, one step along ``axis``) and classify it."""
    n = len(a)
    lo = np.zeros(n)
    hi = np.ones(n)
    f_lo = fa.copy()
    f_hi = fb.copy()
    lo_inside = a_inside.copy()
    frac = np.arange(1, POINTS + 1) / (POINTS + 1)
    saved = None
    for rnd in range(ROUNDS):
        s = lo[:, None] + (hi - lo)[:, None] * frac[None, :]  # (n, POINTS)
        pts = _edge_points(field, a, axis, s)
        flat = pts.reshape(-1, 3)
        vals = points(flat[:, 0], flat[:, 1], flat[:, 2]).reshape(n, POINTS) - level
        # side of every point of the bracket: [lo, p1..p7, hi]
        all_s = np.concatenate([lo[:, None], s, hi[:, None]], axis=1)
        all_f = np.concatenate([f_lo[:, None], vals, f_hi[:, None]], axis=1)
        with np.errstate(invalid="ignore"):
            inside = np.isfinite(all_f) & (all_f < 0)
        change = inside[:, 1:] != inside[:, :-1]
        first = np.argmax(change, axis=1)  # there is one: the ends are on opposite sides
        rows = np.arange(n)
        lo, hi = all_s[rows, first], all_s[rows, first + 1]
        f_lo, f_hi = all_f[rows, first], all_f[rows, first + 1]
        lo_inside = inside[rows, first]
        if rnd == 0:
            saved = (lo.copy(), hi.copy(), f_lo.copy(), f_hi.copy())
    assert saved is not None
    return _decide(saved, (lo, hi, f_lo, f_hi), lo_inside, fa, fb)


def _decide(
    mid: tuple[np.ndarray, ...],
    end: tuple[np.ndarray, ...],
    lo_inside: np.ndarray,
    fa: np.ndarray,
    fb: np.ndarray,
) -> np.ndarray:
    """The kind of each refined edge from its brackets after two and after four rounds."""
    lo2, hi2, f_lo2, f_hi2 = mid
    lo4, hi4, f_lo4, f_hi4 = end
    kept_lo = lo4 == 0.0  # the bracket still starts at sample a
    kept_hi = hi4 == 1.0  # ... or still ends at sample b
    outside_end = np.where(lo_inside, f_hi4, f_lo4)
    scale = np.abs(np.where(np.isfinite(fa), fa, 0.0)) + np.abs(np.where(np.isfinite(fb), fb, 0.0))
    with np.errstate(invalid="ignore", over="ignore"):
        m2 = np.maximum(
            np.where(kept_lo, 0.0, np.abs(f_lo2)), np.where(kept_hi, 0.0, np.abs(f_hi2))
        )
        m4 = np.maximum(
            np.where(kept_lo, 0.0, np.abs(f_lo4)), np.where(kept_hi, 0.0, np.abs(f_hi4))
        )
        kept_value = np.where(kept_lo, np.abs(fa), np.where(kept_hi, np.abs(fb), 0.0))
        kept_small = ~(kept_lo | kept_hi) | (kept_value <= ROOT_KEPT * scale)
        root = kept_small & ((m4 <= ROOT_SHRINK * m2) | (m4 <= ROOT_FLOOR * scale))
        ends = np.maximum(np.abs(f_lo4), np.where(np.isfinite(f_hi4), np.abs(f_hi4), 0.0))
        pole = (
            np.isinf(outside_end)
            | ((m4 >= POLE_GROWTH * m2) & (m4 > 0))
            | (ends >= POLE_SCALE * scale)
        )
    out = np.full(len(lo4), JUMP, dtype=np.uint8)
    out[pole & ~np.isnan(outside_end)] = POLE  # F becoming NaN is the edge of a domain: a jump
    out[root & np.isfinite(outside_end)] = ROOT
    return out


def face_kinds_of(
    mesh: Mesh, edges: np.ndarray, kinds: np.ndarray, cap: bool, field: Field
) -> np.ndarray:
    """uint8 ``(F,)`` kind of each face from its vertices' edge kinds.

    With ``cap``, faces lying on a box face are CAP.  Otherwise a face is a wall when most of
    its labelled vertices are walls (a pole if any of those is a pole, else a jump), else ROOT.
    """
    out = np.full(mesh.n_faces, ROOT, dtype=np.uint8)
    wall_vertex = (kinds == POLE) | (kinds == JUMP)
    if wall_vertex.any():
        f = mesh.faces
        known = (kinds != UNKNOWN).astype(np.int8)
        wall = wall_vertex.astype(np.int8)
        n_known = known[f[:, 0]] + known[f[:, 1]] + known[f[:, 2]]
        n_wall = wall[f[:, 0]] + wall[f[:, 1]] + wall[f[:, 2]]
        is_wall = 2 * n_wall > n_known
        pole = (kinds == POLE)[f[is_wall]]
        out[is_wall] = np.where(pole[:, 0] | pole[:, 1] | pole[:, 2], POLE, JUMP)
    if cap:
        # One bit per box face for each vertex on it; a cap face has a bit all three share.
        v = mesh.vertices
        lo = np.asarray(field.grid.box.lo)
        hi = np.asarray(field.grid.box.hi)
        bits = np.zeros(mesh.n_vertices, dtype=np.uint8)
        for k in range(3):
            bits |= (v[:, k] == lo[k]).astype(np.uint8) << np.uint8(2 * k)
            bits |= (v[:, k] == hi[k]).astype(np.uint8) << np.uint8(2 * k + 1)
        f = mesh.faces
        out[(bits[f[:, 0]] & bits[f[:, 1]] & bits[f[:, 2]]) != 0] = CAP
    return out
