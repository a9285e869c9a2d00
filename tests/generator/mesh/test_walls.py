"""Walls: crossings classified as roots, poles and jumps; --walls keep/remove/mark.

The analytic cases of issue 11: tan(x) (a root at x = 0, poles at +-pi/2), 1/x (only a pole),
atan(tan(2x)) + 0.5 (roots and saw-tooth resets), a staircase (risers are jumps), and smooth
closed shapes (no walls at all).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from surfgen.generator.errors import EmptySurface, SpecError
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.reference import evaluate_points, evaluate_reference
from surfgen.generator.eval.tape import points_evaluator
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.exchange import load_mesh, save_mesh
from surfgen.generator.mesh.mesh import CAP, JUMP, POLE, ROOT, wall_fraction
from surfgen.generator.mesh.walls import extract_labelled


def labelled(formula: str, half: float, n: int, walls: str = "mark", cap: bool = False):
    tree = parse(formula)
    field = evaluate_reference(tree, Grid(Box.cube(half), (n, n, n)))
    return extract_labelled(field, tree, None, 0.0, cap=cap, walls=walls)


def sheet_positions(mesh, kinds) -> np.ndarray:
    """x of the planes x = const the faces of the given kinds lie on (rounded to 0.05)."""
    faces = mesh.faces[np.isin(mesh.face_kinds, kinds)]
    x = mesh.vertices[faces][:, :, 0].mean(axis=1)
    return np.unique(np.round(x / 0.05) * 0.05)


@pytest.mark.parametrize("n", [32, 33])  # x = 0 between samples, and on a grid plane
def test_tan_keep_has_three_sheets_remove_keeps_the_root(n):
    keep, report = labelled("tan(x)", 3.0, n, walls="keep")
    assert keep.face_kinds is None
    xs = np.round(keep.vertices[:, 0] / 0.05) * 0.05
    assert set(np.unique(xs)) == {-1.55, 0.0, 1.55} or set(np.unique(xs)) == {-1.6, 0.0, 1.6}
    marked, _ = labelled("tan(x)", 3.0, n)
    assert set(sheet_positions(marked, [POLE])) <= {-1.6, -1.55, 1.55, 1.6}
    assert len(sheet_positions(marked, [POLE])) == 2
    assert sheet_positions(marked, [ROOT]) == pytest.approx([0.0])
    assert report.poles == 2 * report.roots and report.jumps == 0
    assert report.wall_fraction == pytest.approx(2 / 3)
    removed, _ = labelled("tan(x)", 3.0, n, walls="remove")
    assert np.abs(removed.vertices[:, 0]).max() < 0.02 * 6 / (n - 1)  # only the plane x = 0
    assert removed.n_faces == marked.face_kinds.tolist().count(ROOT)


def test_the_pole_of_one_over_x_is_not_a_surface():
    marked, report = labelled("1/x", 3.0, 32)
    assert report.roots == 0 and report.poles == report.edges > 0
    # a wall costs three points of the formula, five next to a sample (the secant, bisections)
    assert 3 * report.refined <= report.points <= 5 * report.refined
    assert wall_fraction(marked) == 1.0
    with pytest.raises(EmptySurface, match="no root") as err:
        labelled("1/x", 3.0, 32, walls="remove")
    assert "\n" not in str(err.value)


def test_sawtooth_resets_are_jumps_and_remove_keeps_the_roots():
    # atan(tan(2x)) + 0.5 = 0 at 2x = -0.5 + k pi; it jumps by -pi at 2x = pi/2 + k pi.
    marked, report = labelled("atan(tan(2*x))+0.5", 3.0, 32)
    roots = [(-0.5 + k * math.pi) / 2 for k in range(-2, 3) if abs(-0.5 + k * math.pi) < 6]
    resets = [(math.pi / 2 + k * math.pi) / 2 for k in range(-3, 3)]
    resets = [r for r in resets if abs(r) < 3]
    h = 6 / 31
    for x in sheet_positions(marked, [ROOT]):
        assert min(abs(x - r) for r in roots) < h
    for x in sheet_positions(marked, [JUMP]):
        assert min(abs(x - r) for r in resets) < h
    assert report.poles == 0 and report.jumps > 0 and report.roots > 0
    removed, _ = labelled("atan(tan(2*x))+0.5", 3.0, 32, walls="remove")
    for x in np.unique(np.round(removed.vertices[:, 0], 6)):
        assert min(abs(x - r) for r in roots) < h  # every vertex left is on a root sheet


@pytest.mark.parametrize("name", ["sphere", "torus"])
def test_smooth_shapes_have_no_walls(name, shapes, shape_field):
    shape = shapes[name]
    tree = parse(shape.formula)
    mesh, report = extract_labelled(shape_field(name), tree, None, 0.0, cap=True, walls="mark")
    assert report.wall_fraction == 0.0 and report.poles == report.jumps == 0
    removed, _ = extract_labelled(shape_field(name), tree, None, 0.0, walls="remove")
    assert removed.n_faces == mesh.n_faces  # nothing removed


@pytest.mark.parametrize(
    "formula",
    ["stair1(x,0.5,1,4)-0.5", "floor(2*x)+floor(2*y)", "floor(3*z)"],  # plateaus at the level
)
def test_staircase_risers_are_jumps(formula):
    mesh, report = labelled(formula, 1.5, 25, cap=True)
    assert report.roots == 0 and report.poles == 0 and report.jumps == report.edges > 0
    kinds = set(mesh.face_kinds.tolist())
    assert kinds <= {JUMP, CAP} and JUMP in kinds


def test_domain_edges_are_jumps_and_their_roots_stay():
    # sqrt(1 - x^2) - 0.5: roots at |x| = sqrt(3)/2; F is -0.5 at |x| = 1, then NaN.
    mesh, report = labelled("sqrt(1-x^2)-0.5", 1.5, 32)
    assert sheet_positions(mesh, [ROOT]) == pytest.approx([-0.85, 0.85])
    assert report.poles == 0 and report.jumps == report.roots


@pytest.mark.parametrize("c", [0.302, 0.35, 0.398, 0.4])  # the pole near a sample, or on it
def test_poles_next_to_a_sample_are_poles(c):
    _mesh, report = labelled(f"1/(x-{c})+0.3*y", 1.0, 21)
    assert report.roots == 0 and report.poles == report.edges > 0


@pytest.mark.parametrize("c", [0.9985, 0.95, 0.9015])  # a root in a border edge, near a sample
def test_roots_next_to_a_sample_at_the_border_are_roots(c):
    mesh, report = labelled(f"x+{c}+0.01*y*z", 1.0, 21)
    assert report.refined > 0  # border edges are looked at with the formula
    assert report.poles == report.jumps == 0 and wall_fraction(mesh) == 0.0


def test_marked_files_keep_their_labels(tmp_path):
    mesh, report = labelled("tan(x)", 3.0, 24, cap=True)
    for suffix in (".ply", ".glb"):
        path = save_mesh(mesh, tmp_path / f"m{suffix}")
        assert path.stat().st_size > 0
    back = load_mesh(tmp_path / "m.ply")
    assert np.array_equal(back.face_kinds, mesh.face_kinds)
    assert wall_fraction(back) == pytest.approx(report.wall_fraction, rel=1e-6)
    import trimesh

    glb = trimesh.load(tmp_path / "m.glb", force="mesh")
    colours = {tuple(c) for c in np.asarray(glb.visual.vertex_colors)[:, :3]}
    assert (214, 39, 40) in colours  # poles are red


def test_bad_walls_mode_is_a_one_line_error():
    with pytest.raises(SpecError, match="allowed: keep, remove, mark"):
        labelled("x", 1.0, 8, walls="drop")


def test_points_evaluator_is_the_reference():
    tree = parse("atan(tan(2*x))*stair1(y,0.5,1,4)+abs(z)^0.3/sec(x*y)-rect2(z,1,0.4)")
    rng = np.random.default_rng(3)
    x, y, z = rng.uniform(-3, 3, size=(3, 500))
    got = points_evaluator(tree)(x, y, z)  # the walls' evaluator: the numba points kernel
    assert np.array_equal(got, evaluate_points(tree, x, y, z), equal_nan=True)


# ----------------------------------------------------------------------------- fast path
# classify_edges runs the midpoint, the secant step, the bisections and the decision in one
# numba call (the formula through points.eval_edges, the levels that do not vary along an
# edge computed once per edge).  The reference below takes the same steps on arrays from
# Python, the formula evaluated at every point without sharing (PointsEvaluator.plain,
# points.run_points): the kinds must be the same.


def reference_kinds(field, tree, level, edges):
    from surfgen.generator.mesh import refine as r
    from surfgen.generator.mesh import walls as w

    values = np.ascontiguousarray(field.values, dtype=np.float64).reshape(-1)
    shape = np.asarray(field.values.shape, dtype=np.int64)
    kinds, idx, fa, fb, ina = w._crossings(values, shape, edges, level, w.SMOOTH_RATIO)
    if idx.size == 0:
        return kinds, 0
    plain = points_evaluator(tree).plain
    axes = field.grid.axes()
    ijk, axis = edges[idx, 1:], edges[idx, 0]
    grid_point = np.stack([axes[k][ijk[:, k]] for k in range(3)], axis=1)
    u0 = grid_point[np.arange(idx.size), axis]
    h = np.asarray(field.grid.spacing)[axis]

    def f_at(t, rows):  # on the edge: its grid values, and u0 + t h along it
        p = grid_point[rows].copy()
        p[np.arange(rows.size), axis[rows]] = u0[rows] + t * h[rows]
        return plain(p[:, 0], p[:, 1], p[:, 2]) - level

    def split(now, rows, s, f):  # keep the part where the side changes
        inside = np.isfinite(f) & (f < 0)
        lower = (now[rows, 4] != 0) != inside
        now[rows[lower], 1], now[rows[lower], 3] = s[lower], f[lower]
        up = rows[~lower]
        now[up, 0], now[up, 2], now[up, 4] = s[~lower], f[~lower], inside[~lower]

    everyone = np.arange(idx.size)
    with np.errstate(all="ignore"):
        finite = ~np.isnan(fa) & ~np.isnan(fb) & ~np.isnan(fa / (fa - fb))
        pos = ijk[everyone, axis]
        border = (pos < 1) | (pos + 2 >= np.asarray(field.values.shape)[axis])
        q = r.SECANT_GRID
        u = np.where(np.isnan(fa / (fa - fb)), 0.5, fa / (fa - fb))
        t1 = np.where(border, np.minimum(np.maximum(np.round(u * q), 1.0), q - 1) / q, 0.5)
        f1 = f_at(t1, everyone)
        in1 = np.isfinite(f1) & (f1 < 0)
        far = np.where(in1 == ina, np.abs(fa), np.abs(fb))
        root = finite & (np.abs(f1) < r.NEAR_ROOT * far)
        upper = in1 == ina  # the side changes between the midpoint and sample b
        now = np.stack(
            [np.where(upper, t1, 0.0), np.where(upper, 1.0, t1), np.where(upper, f1, fa),
             np.where(upper, fb, f1), np.where(upper, in1, ina).astype(float)], axis=1
        )  # fmt: skip
        before = now.copy()
        room = (now[:, 1] - now[:, 0]) * r.SECANT_GRID >= 2
        dips = np.flatnonzero(~root & finite & (np.abs(f1) < far) & room)
        if dips.size:
            lo, hi, flo, fhi = now[dips, 0], now[dips, 1], now[dips, 2], now[dips, 3]
            u = flo / (flo - fhi)
            u = np.where(np.isnan(u), 0.5, u)
            q = r.SECANT_GRID
            s = np.minimum(np.maximum(np.round((lo + u * (hi - lo)) * q), lo * q + 1), hi * q - 1)
            s = s / q
            f2 = f_at(s, dips)
            in2 = np.isfinite(f2) & (f2 < 0)
            end = np.where(in2 == (now[dips, 4] != 0), np.abs(flo), np.abs(fhi))
            near = np.abs(f2) < r.NEAR_ROOT * end
            root[dips[near]] = True
            split(now, dips[~near], s[~near], f2[~near])
    rest = np.flatnonzero(~root)

    def bisect(rows):
        s = 0.5 * (now[rows, 0] + now[rows, 1])
        with np.errstate(all="ignore"):
            split(now, rows, s, f_at(s, rows))

    for _ in range(r.BISECTIONS):
        wide = now[rest, 1] - now[rest, 0] > 0.25 * (before[rest, 1] - before[rest, 0])
        bisect(rest[wide])
    first = r._decide(before[rest], now[rest], fa[rest], fb[rest])
    held = rest[((now[rest, 0] == 0.0) | (now[rest, 1] == 1.0)) & (first == JUMP)]
    before[held] = now[held]
    for _ in range(r.BISECTIONS):
        bisect(held)
    kinds_rest = r._decide(before[rest], now[rest], fa[rest], fb[rest])
    with np.errstate(all="ignore"):  # M2 / M1 as _decide measures them
        kept_lo, kept_hi = now[rest, 0] == 0.0, now[rest, 1] == 1.0
        m1 = np.where(kept_lo, 0.0, np.abs(before[rest, 2]))
        m1 = np.maximum(m1, np.where(kept_hi, 0.0, np.abs(before[rest, 3])))
        m2 = np.maximum(np.where(kept_lo, 0.0, np.abs(now[rest, 2])),
                        np.where(kept_hi, 0.0, np.abs(now[rest, 3])))  # fmt: skip
        ratio = np.where((m1 > 0) & ~np.isnan(m2), m2 / m1, 1.0)
    unsure = rest[(kinds_rest == JUMP) & (ratio < r.UNSURE)]
    before[unsure] = now[unsure]
    for _ in range(r.BISECTIONS):
        bisect(unsure)
    sub = np.full(idx.size, ROOT, dtype=np.uint8)
    sub[rest] = r._decide(before[rest], now[rest], fa[rest], fb[rest])
    kinds[idx] = sub
    return kinds, int(idx.size)


@pytest.mark.parametrize(
    ("formula", "half"),
    [
        ("tan(x)*tan(y)-z", 3.0),
        ("1/x+y+z", 2.0),
        ("atan(tan(2*x))+0.5-0.3*y*z", 3.0),
        ("stair1(x,0.5,1,4)+stair1(y,0.5,1,4)-z", 2.0),
        ("saw1(x+y,0.6,4)-0.3*z^2", 2.0),
        ("sqrt(1-x^2-y^2)-abs(z)-0.2+0.1/(x-0.3)", 1.2),  # NaN domain edges and a pole
        ("sin(3*x)*cos(3*y)+sin(3*y)*cos(3*z)+sin(3*z)*cos(3*x)", 2.0),
    ],
)
@pytest.mark.parametrize("cap", [False, True])
def test_fused_classification_is_the_stepwise_reference(formula, half, cap):
    from surfgen.generator.mesh.mesh import extract_with_edges
    from surfgen.generator.mesh.walls import classify_edges

    tree = parse(formula)
    field = evaluate_reference(tree, Grid(Box.cube(half), (27, 30, 25)))
    _mesh, edges = extract_with_edges(field, 0.0, cap)
    kinds, refined = classify_edges(field, tree, None, 0.0, edges)
    want, want_refined = reference_kinds(field, tree, 0.0, np.ascontiguousarray(edges))
    assert refined == want_refined
    assert np.array_equal(kinds, want)


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_suspects_refined_in_runs_on_threads_give_the_same_kinds(monkeypatch, threads):
    # refine_suspects calls the kernel on runs of SUSPECTS_A_CALL suspects, each thread taking
    # the next run: with runs of 5 (hundreds of them, ending mid-axis) the kinds are still the
    # stepwise reference's and the points evaluated those of one call over all the suspects
    from surfgen.generator.mesh import refine
    from surfgen.generator.mesh.mesh import extract_with_edges
    from surfgen.generator.mesh.walls import _classify

    tree = parse("sqrt(1-x^2-y^2)-abs(z)-0.2+0.1/(x-0.3)+0.05*tan(4*y)")
    field = evaluate_reference(tree, Grid(Box.cube(1.2), (27, 30, 25)))
    _mesh, edges = extract_with_edges(field, 0.0, True)
    edges = np.ascontiguousarray(edges)
    _kinds, refined, whole_points = _classify(field, tree, None, 0.0, edges)
    assert refined > 100 * 5  # a hundred runs and more
    monkeypatch.setattr(refine, "SUSPECTS_A_CALL", 5)
    kinds, refined_runs, points = _classify(field, tree, None, 0.0, edges, threads=threads)
    want, want_refined = reference_kinds(field, tree, 0.0, edges)
    assert refined_runs == refined == want_refined
    assert np.array_equal(kinds, want)
    assert points == whole_points


@pytest.mark.parametrize("walls", ["keep", "mark"])
def test_label_walls_takes_the_face_areas_a_caller_has(walls):
    # the sampler's filters need the faces' areas too: it computes them once and passes them
    from surfgen.generator.mesh.mesh import extract_with_edges, face_areas
    from surfgen.generator.mesh.walls import label_walls

    tree = parse("tan(x)+0.3*y")
    field = evaluate_reference(tree, Grid(Box.cube(3.0), (30, 30, 30)))
    mesh, edges = extract_with_edges(field, 0.0, True)
    areas = face_areas(mesh)
    got, report = label_walls(mesh, edges, field, tree, None, 0.0, True, walls, areas)
    want, want_report = label_walls(mesh, edges, field, tree, None, 0.0, True, walls)
    assert report == want_report and report.wall_fraction > 0.1  # the same bits
    assert (got.face_kinds is None) == (want.face_kinds is None)
    if walls == "mark":
        assert np.array_equal(got.face_kinds, want.face_kinds)
        assert report.wall_fraction == wall_fraction(got)
    # they are used, not measured again: twice the walls' areas, a larger share
    marked = label_walls(mesh, edges, field, tree, None, 0.0, True, "mark")[0]
    double = np.where(np.isin(marked.face_kinds, (POLE, JUMP)), 2.0, 1.0) * areas
    _, doubled = label_walls(mesh, edges, field, tree, None, 0.0, True, walls, double)
    assert doubled.wall_fraction > report.wall_fraction
    with pytest.raises(ValueError, match="face areas"):
        label_walls(mesh, edges, field, tree, None, 0.0, True, walls, areas[:-1])


# ----------------------------------------------------------------------------- step 1
def step_one_reference(values, edges, level):
    """Step 1 of walls' docstring on arrays: kinds (ROOT at a crossing, else UNKNOWN) and the
    suspects' rows, fa, fb, whether sample a is inside, grid indices and axes."""
    from surfgen.generator.mesh import walls as w

    shape = np.asarray(values.shape)
    axis, ijk = edges[:, 0], edges[:, 1:]
    on_grid = axis >= 0
    a = np.where(on_grid, axis, 0)
    pos = ijk[np.arange(len(edges)), a]
    inner = on_grid & (pos + 1 < shape[a])
    step = np.eye(3, dtype=np.int64)[a]

    def f_at(shift):  # F - level at ijk + shift * step, clipped into the grid
        p = np.clip(ijk + shift[:, None] * step, 0, shape - 1)
        return values[p[:, 0], p[:, 1], p[:, 2]] - level

    zero = np.zeros(len(edges), dtype=np.int64)
    fa, fb = f_at(zero), f_at(zero + 1)
    inside_a = np.isfinite(fa) & (fa < 0)
    crossing = inner & (inside_a != (np.isfinite(fb) & (fb < 0)))
    with np.errstate(all="ignore"):
        fm, fp = f_at(zero - 1), f_at(zero + 2)
        d, dm, dp = fb - fa, fa - fm, fp - fb
        one_sign = (np.sign(dm) == np.sign(d)) & (np.sign(dp) == np.sign(d))
        smooth = (
            (pos >= 1)
            & (pos + 2 < shape[a])
            & np.isfinite(dm + d + dp)
            & (
                (one_sign & (np.abs(d) <= w.SMOOTH_RATIO * np.maximum(np.abs(dm), np.abs(dp))))
                | (np.abs(dp - 2 * d + dm) <= w.SMOOTH_THIRD * (np.abs(dm) + np.abs(dp)))
            )
        )
    rows = np.flatnonzero(crossing & ~smooth)
    kinds = np.where(crossing, ROOT, w.UNKNOWN).astype(np.uint8)
    return kinds, rows, fa[rows], fb[rows], inside_a[rows], ijk[rows], axis[rows]


@pytest.mark.parametrize(
    "formula, half",
    [
        ("tan(x)+0.3*y", 3.0),  # poles
        ("stair1(x,0.5,1,4)+stair1(y,0.5,1,4)-z", 2.0),  # plateaus and risers
        ("sqrt(1-x^2-y^2)-abs(z)-0.2+0.1/(x-0.3)", 1.2),  # NaN and +-inf samples
        ("1/x+y+z", 2.0),  # +inf samples at x = 0
        ("log(abs(x))+0.3*y", 2.0),  # -inf samples at x = 0: outside
        ("x^2+y^2+z^2-1", 1.05),  # smooth: suspects only next to the border
    ],
)
@pytest.mark.parametrize("cap", [False, True])  # cap: vertices on no grid edge (axis -1)
def test_step_one_is_its_docstring(formula, half, cap):
    from surfgen.generator.mesh import walls as w
    from surfgen.generator.mesh.mesh import extract_with_edges

    tree = parse(formula)
    field = evaluate_reference(tree, Grid(Box.cube(half), (21, 24, 19)))
    _mesh, edges = extract_with_edges(field, 0.0, cap)
    # rows on no grid edge and at the grid's end, which marching cubes does not make
    extra = np.array([[-1, 3, 4, 5], [0, 20, 2, 2], [1, 2, 23, 2], [2, 2, 2, 18]])
    edges = np.ascontiguousarray(np.concatenate([edges, extra]), dtype=np.int64)
    assert (edges[:, 0] == -1).any()
    values = np.ascontiguousarray(field.values, dtype=np.float64)
    got = w._crossings_core(values.reshape(-1), np.asarray(values.shape), edges, 0.0,
                            w.SMOOTH_RATIO)  # fmt: skip
    want = step_one_reference(values, edges, 0.0)
    assert got[1].size > 0
    if "log" in formula:
        assert np.isneginf(values).any()
    for g, e in zip(got, want, strict=True):
        assert g.dtype.kind == e.dtype.kind
        assert np.array_equal(g, e, equal_nan=g.dtype.kind == "f")
