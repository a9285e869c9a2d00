"""The infill, assembly and twist families: pure functions of (seed, index, config), their
structure in the model JSON, formulas that print and parse back, and shapes that are what the
structure says (a lattice inside its envelope, bodies where the arrangement puts them, lobes
that turn)."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from surfgen.filters.meshlab import face_components
from surfgen.generator.eval.evaluate import evaluate, points_evaluator
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.expr import add_all, mul_all, to_string
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import extract_mesh
from surfgen.generator.model.families import twist
from surfgen.generator.model.families.assembly import APART, MIN_TUBE, _ring_gap, _rings_apart
from surfgen.generator.model.families.twist import harmonic, lobe_terms
from surfgen.generator.model.sampler import SamplerConfig, choose_d, draw_equation

NEW = ("infill", "assembly", "twist")


def family(name: str, **changes) -> SamplerConfig:
    """The family's own draws, in its own proportions (not stretched)."""
    return replace(SamplerConfig(), family=name, **({"aspect_prob": 0.0} | changes))


@pytest.mark.parametrize("name", NEW)
def test_a_draw_is_a_pure_function_of_seed_index_and_config(name: str) -> None:
    cfg = family(name)
    first = [draw_equation(3, i, cfg).model_dict() for i in (4, 0, 9)]
    assert first == [draw_equation(3, i, cfg).model_dict() for i in (4, 0, 9)]  # any order
    assert first[0] != draw_equation(4, 4, cfg).model_dict()  # another seed
    assert first[0] != draw_equation(3, 5, cfg).model_dict()  # another index
    other = cfg.with_settings(name, margin=[0.5, 0.6])
    assert first[0] != draw_equation(3, 4, other).model_dict()  # another config
    assert json.loads(json.dumps(first[0])) == first[0]  # JSON-ready


@pytest.mark.parametrize("name", NEW)
def test_the_model_records_its_family_and_structure(name: str) -> None:
    keys = {
        "infill": {"envelope", "pattern", "period", "strut_cells", "clip", "group"},
        "assembly": {"arrangement", "body", "join", "bodies", "group", "extent"},
        "twist": {"lobes", "lobe_depth", "turns", "axis", "cells_per_period", "braid"},
    }[name]
    for i in range(6):
        model = draw_equation(7, i, family(name)).model_dict()
        assert model["family"] == name
        assert keys <= set(model["structure"])


@pytest.mark.parametrize("name", NEW)
def test_formulas_print_and_parse_back_and_cross_their_box(name: str) -> None:
    """The printed formula is K3DSurf/MathMod syntax (the parser reads back the same tree) and
    the surface crosses the box, away from its faces (free-standing)."""
    cfg = family(name)
    for i in range(6):
        draw = draw_equation(11, i, cfg)
        d = choose_d(draw, cfg)
        assert d is not None and math.isfinite(d)
        tree = draw.equation.with_d(d).to_tree()
        assert parse(to_string(tree)) == tree
        # 48 points: a hollow infill's shell is a few cells of the run's 64 thick
        v = evaluate(tree, Grid(draw.box, (48,) * 3), threads=1).values
        inside = v < 0
        assert 0.001 < inside.mean() < 0.8
        faces = np.concatenate([inside[[0, -1]].ravel(), inside[:, [0, -1]].ravel()])
        assert faces.mean() < 0.02, f"{name} {i}: the shape touches the box"


def test_infill_is_its_lattice_inside_the_envelope_and_empty_outside() -> None:
    for i in range(8):
        draw = draw_equation(5, i, family("infill"))
        st = draw.structure
        clips = 2 * st["clips"]  # the last terms are c max(E, 0) (and a cut's c max(P, 0))
        lattice = draw.equation.terms[:-clips]
        grid = Grid(draw.box, (20,) * 3)
        f = evaluate(draw.equation.with_d(draw.d).to_tree(), grid, threads=1).values
        envelope_terms = draw.equation.terms[-clips:]
        clip = evaluate(type(draw.equation)(envelope_terms, 0.0).to_tree(), grid, threads=1).values
        lat = evaluate(type(draw.equation)(lattice, draw.d).to_tree(), grid, threads=1).values
        inside_env = clip == 0  # max(E, 0) = 0 exactly inside the envelope
        assert inside_env.any() and (~inside_env).any()
        assert np.allclose(f[inside_env], lat[inside_env])
        assert (f[~inside_env] > lat[~inside_env]).all()
        assert st["strut_cells"] >= 3.0 - 1e-9


def test_assembly_chains_are_linked_tori_and_blends_join_bodies() -> None:
    seen = set()
    cfg = family("assembly")
    for i in range(40):
        st = draw_equation(7, i, cfg).structure
        seen.add((st["arrangement"], st["join"]))
        assert 2 <= st["bodies"] <= 5
        if st["arrangement"] == "chain":
            assert st["body"] == "torus" and st["join"] == "product"
        if st["join"] == "boolean":
            assert st["bodies"] == 2 and st["operation"].split()[1] in (
                "union",
                "intersection",
                "difference",
            )
    joins = {j for _, j in seen}
    assert joins == {"blend", "product", "boolean"}
    assert {a for a, _ in seen} >= {"pair", "triangle", "tetra", "chain"}


def test_twist_lobes_are_a_turning_harmonic() -> None:
    """``lobe_terms(m, a, k)`` is ``a r^2 cos(m (phi - k z))`` (up to the δ on the axis)."""
    re, im = harmonic(3)
    assert re.coefficients == {(3, 0, 0): 1.0, (1, 2, 0): -3.0}
    assert im.coefficients == {(2, 1, 0): 3.0, (0, 3, 0): -1.0}
    eq = type(draw_equation(1, 0, family("twist")).equation)
    tree = eq(tuple(lobe_terms(4, 0.5, 1.3)), 0.0).to_tree()
    box = Box((0.4, -0.7, -1.0), (1.2, 0.9, 1.0))
    grid = Grid(box, (9, 9, 9))
    v = evaluate(tree, grid, threads=1).values
    x, y, z = np.meshgrid(*grid.axes(), indexing="ij")
    r2 = x**2 + y**2
    want = 0.5 * r2 * np.cos(4 * (np.arctan2(y, x) - 1.3 * z)) * (r2 / (r2 + 0.01))
    assert np.allclose(v, want, atol=1e-9)


def test_ring_gap_is_the_closest_pair_of_samples_bit_for_bit() -> None:
    """The gap from cached circles and per-axis differences is the minimum over every pair of
    the two circles' samples of the distance numpy gives (for axes of any length, and a second
    radius or not)."""
    rng = np.random.default_rng(3)

    def circle(c, a, r, samples=96):
        a = np.asarray(a, dtype=float) / np.linalg.norm(a)
        u = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        t = np.linspace(0, 2 * np.pi, samples, endpoint=False)[:, None]
        return np.asarray(c) + r * (np.cos(t) * u + np.sin(t) * np.cross(a, u))

    for _ in range(200):
        c1, c2, a1, a2 = (tuple(np.round(rng.normal(size=3), 4)) for _ in range(4))
        r1, r2 = (round(float(rng.uniform(0.2, 0.6)), 4) for _ in range(2))
        for second in (r2, None):
            p, q = circle(c1, a1, r1), circle(c2, a2, r1 if second is None else second)
            want = float(np.sqrt(((p[:, None, :] - q[None, :, :]) ** 2).sum(-1)).min())
            assert _ring_gap(c1, list(a1), c2, a2, r1, second) == want


def test_rings_joined_by_a_product_are_kept_apart() -> None:
    # two coplanar rings whose centres are 1.3 radii apart cross: no tube keeps them apart
    assert _ring_gap((0, 0, 0), (0, 1, 0), (0.65, 0, 0), (0, 1, 0), 0.5) < 0.02  # sampled
    assert _rings_apart("pair", 1.3, [0.0, 1.0, 0.0], 0.0, 0.3) is None
    # stacked on their common axis they are 1.3 radii apart: the tube fits as drawn...
    assert _rings_apart("pair", 1.3, [1.0, 0.0, 0.0], 0.0, 0.3) == 0.3
    # ...or is thinned to fit (0.65 apart: at most 0.45 * 0.65 / 0.5)
    assert _rings_apart("pair", 1.3, [1.0, 0.0, 0.0], 0.0, 0.9) == round(APART * 0.65 / 0.5, 2)
    assert MIN_TUBE < APART
    # every torus product the family draws: one mesh piece per ring (no webs, no debris)
    cfg = family("assembly")
    seen = 0
    for i in range(400):
        draw = draw_equation(5, i, cfg)
        info = draw.structure
        if info["body"] != "torus" or info["join"] != "product" or info["arrangement"] == "chain":
            continue
        seen += 1
        if seen > 4:
            break
        field = evaluate(draw.equation.with_d(draw.d).to_tree(), Grid(draw.box, (48,) * 3))
        pieces = np.bincount(face_components(extract_mesh(field, 0.0, cap=True)))
        assert len(pieces) == info["bodies"], (i, info)
    assert seen >= 3


def test_a_spire_is_wide_at_one_end_and_its_lobes_swell_towards_one() -> None:
    """``taper``: the column's radius at z = +H/2 and -H/2 differ by (1 + τ/2)/(1 - τ/2) (the
    sign of τ says which end is wide); ``swell``: the lobes' depth ε (1 + γ z/H) differs
    between the ends likewise; with the largest settings the column still stands free."""
    cfg = family("twist").with_settings(
        "twist", taper_prob=1.0, swell_prob=1.0, braid_prob=0.0, ellipse_prob=0.0
    )
    cfg = cfg.with_settings("twist", taper=[0.4, 0.45], swell=[0.8, 0.9], bulge=[0.0, 0.0])
    for i in range(4):
        draw = draw_equation(2, i, cfg)
        st = draw.structure
        tau, gamma, height = st["taper"], st["swell"], st["height"]
        assert 0.4 <= abs(tau) <= 0.45 and gamma != 0.0
        assert st["lobe_depth"] * (1 + abs(gamma)) <= 0.8 + 1e-9
        tree = draw.equation.with_d(draw.d).to_tree()
        # along the column's axis: the radius where F crosses 0, halfway up and halfway down
        axis = "xyz".index(st["axis"])
        radii = []
        for z in (height / 2, -height / 2):
            r = np.linspace(0.0, draw.box.hi[0], 4001)[1:]
            pts = np.zeros((3, r.size))
            pts[axis] = z
            found = []  # around the section: the lobes' phase does not matter for the mean
            for a in np.linspace(0, 2 * np.pi, 24, endpoint=False):
                p = pts.copy()
                p[(axis + 1) % 3] = r * np.cos(a)
                p[(axis + 2) % 3] = r * np.sin(a)
                v = points_evaluator(tree, {})(*p)
                found.append(r[np.argmax(v >= 0)])
            radii.append(np.array(found))
        up, down = radii
        want = (1 - tau / 2) / (1 + tau / 2)  # r ~ 1 / (1 + τ z/H) at the same phase
        mean_ratio = np.exp(np.mean(np.log(up / down)))
        assert abs(math.log(mean_ratio) - math.log(want)) < 0.35 * abs(math.log(want)), (
            i,
            mean_ratio,
            want,
        )
        # the lobes: the spread of the radius around the section grows towards the swell
        spread = [np.ptp(r / np.mean(r)) for r in radii]
        assert (spread[0] > spread[1]) == (gamma > 0), (i, spread, gamma)
        v = evaluate(tree, Grid(draw.box, (32,) * 3), threads=1).values
        inside = v < 0
        faces = np.concatenate([inside[[0, -1]].ravel(), inside[:, [0, -1]].ravel()])
        assert inside.any() and faces.mean() < 0.02


def test_chain_rings_link_their_neighbours_and_clear_the_others() -> None:
    """A chain's rings: n from chain_links; every other one smaller with alternate_prob; any
    two rings at least tube / APART apart (links never touch, rings two apart never cross); one
    mesh piece per ring."""
    cfg = family("assembly").with_settings(
        "assembly", arrangement_weights=[0, 0, 0, 0, 0, 1], join_weights=[0.5, 0.5, 0.0]
    )
    cfg = cfg.with_settings("assembly", alternate_prob=0.5, stretch_prob=0.0)
    counts, alternated, meshed = set(), 0, 0
    for i in range(24):
        draw = draw_equation(4, i, cfg)
        st = draw.structure
        assert st["arrangement"] == "chain" and st["join"] == "product"
        n = st["bodies"]
        counts.add(n)
        alternated += "ratio" in st
        radius = 0.5
        radii = [radius * (st.get("ratio", 1.0) if k % 2 else 1.0) for k in range(n)]
        twist = st["twist"]
        axes = [
            (0.0, math.sin(k * (math.pi / 2 + twist)), math.cos(k * (math.pi / 2 + twist)))
            for k in range(n)
        ]
        steps = [st["gap"] * (radii[k] + radii[k + 1]) / 2 for k in range(n - 1)]
        xs = np.concatenate([[0.0], np.cumsum(steps)])
        centres = [(x - xs[-1] / 2, 0.0, 0.0) for x in xs]
        tube = st["tube"] * radius
        for a in range(n):
            for b in range(a + 1, n):
                gap = _ring_gap(centres[a], axes[a], centres[b], axes[b], radii[a], radii[b])
                assert tube <= APART * gap + 2e-3, (i, a, b, tube, gap)
        if meshed < 3 and n >= 3:
            meshed += 1
            field = evaluate(draw.equation.with_d(draw.d).to_tree(), Grid(draw.box, (56,) * 3))
            pieces = np.bincount(face_components(extract_mesh(field, 0.0, cap=True)))
            assert len(pieces) == n, (i, st)
    assert counts == {2, 3, 4} and 0 < alternated < 24 and meshed == 3


def _column_field(m: int, shape: twist.Shape, cfg: SamplerConfig):
    """The points evaluator of a column's terms (cell 0.02: no lobe is thinned away)."""
    terms = twist._column(m, 0.45, 0.75, 1.6, 3.3, 0.14, False, 0.0, 2, shape, 0.02, cfg)[0]
    return points_evaluator(add_all([mul_all([f.to_tree() for f in t]) for t in terms]), {})


@pytest.mark.parametrize("m", [2, 3, 4, 5, 6])
def test_a_bent_column_is_the_straight_one_sheared(m: int) -> None:
    """``bend``: the column's field is the straight column's at ``(x - b z^2, y, z)`` (b = bend /
    H), near its bent axis too, where the expanded lobes cancel (6 significant digits left
    errors of 10^4 there: beads of inside along the axis)."""
    cfg = family("twist")
    rng = np.random.default_rng(m)
    for bend, axis, tau in ((0.45, 0, 0.0), (-0.3, 1, 0.4)):
        bent = _column_field(m, twist.Shape(0.8, tau, 0.6, bend, axis), cfg)
        straight = _column_field(m, twist.Shape(0.8, tau, 0.6), cfg)
        b = round(bend / 1.6, 4)
        x, y, z = rng.uniform(-3.5, 3.5, (3, 20000))
        near = slice(0, 10000)  # on and around the bent axis
        lean = b * z[near] ** 2
        if axis == 0:
            x[near], y[near] = lean + rng.normal(0, 0.03, 10000), rng.normal(0, 0.03, 10000)
        else:
            x[near], y[near] = rng.normal(0, 0.03, 10000), lean + rng.normal(0, 0.03, 10000)
        sx, sy = (x - b * z**2, y) if axis == 0 else (x, y - b * z**2)
        want = straight(sx, sy, z)
        err = np.abs(bent(x, y, z) - want) / (1.0 + np.abs(want))
        assert err.max() < 1e-3, (bend, err.max())


def test_a_bent_column_stands_free_in_one_piece_and_is_not_braided() -> None:
    cfg = family("twist").with_settings("twist", bend_prob=1.0, braid_prob=1.0, bend=[0.45, 0.5])
    for i in range(4):
        draw = draw_equation(3, i, cfg)
        st = draw.structure
        assert 0.45 <= abs(st["bend"]) <= 0.5 and not st["braid"]
        assert st["bend_toward"] != st["axis"]
        assert json.loads(json.dumps(draw.model_dict()))["structure"]["bend"] == st["bend"]
        field = evaluate(draw.equation.with_d(draw.d).to_tree(), Grid(draw.box, (48,) * 3))
        inside = field.values < 0
        faces = np.concatenate([inside[[0, -1]].ravel(), inside[:, [0, -1]].ravel()])
        assert inside.any() and faces.mean() < 0.02, (i, st)
        assert np.bincount(face_components(extract_mesh(field, 0.0, cap=True))).size == 1, st
    straight = family("twist").with_settings("twist", bend_prob=0.0)
    assert all(draw_equation(3, i, straight).structure["bend"] == 0.0 for i in range(4))


def test_a_hollow_infill_is_a_pierced_shell_of_the_drawn_thickness() -> None:
    """``hollow_prob``: the envelope's inside deeper than the shell is clipped away like its
    outside (so its centre is empty), the shell's inner surface lies the drawn thickness below
    the outer one along the inradius, the pores pierce it (the solid share is at least half),
    and the product envelope (two factors) is never hollowed."""
    cfg = family("infill").with_settings("infill", hollow_prob=1.0, cut_prob=0.0)
    seen = set()
    for i in range(12):
        draw = draw_equation(4, i, cfg)
        st = draw.structure
        env = st["envelope"]
        if env["kind"] == "product":
            assert st["shell"] is None
            continue
        shell = st["shell"]
        assert shell is not None and st["level_quantile"] >= 0.5, st
        seen.add(env["kind"])
        tree = draw.equation.with_d(draw.d).to_tree()
        f = points_evaluator(tree, {})
        clips = 2 * st["clips"]
        inner = type(draw.equation)(draw.equation.terms[-2:], 0.0).to_tree()  # c max(-E - e, 0)
        outer = type(draw.equation)(draw.equation.terms[-clips:-2], 0.0).to_tree()
        g_in, g_out = points_evaluator(inner, {}), points_evaluator(outer, {})
        if env["kind"] == "torus":
            radial = env["axis"].index(0.0)
            centre, surface = env["ring"], env["ring"] + env["tube"]
        else:
            radial = env["radii"].index(min(env["radii"]))
            centre, surface = 0.0, min(env["radii"])
        # along the inradius: outside the envelope, the shell, then the hollow
        r = np.linspace(centre, surface * 1.1, 2001)
        pts = np.zeros((3, r.size))
        pts[radial] = r
        clipped_in = g_in(*pts) > 0
        clipped_out = g_out(*pts) > 0
        shell_pts = ~clipped_in & ~clipped_out
        assert clipped_in[0] and clipped_out[-1] and shell_pts.any(), (i, st)
        # the hollow's edge: the drawn thickness below the envelope's surface
        edge = r[np.argmax(shell_pts)]
        assert abs((surface - edge) - shell["thickness"]) < 0.02 * surface, (i, edge, st)
        if env["kind"] == "superellipsoid":
            assert f(np.zeros(1), np.zeros(1), np.zeros(1))[0] > 0  # the centre is empty
    assert seen == {"superellipsoid", "torus"}
    # cut, a shell is a bowl or a band: a cube or an octahedron would keep little but the hollow
    cut = cfg.with_settings("infill", cut_prob=1.0)
    kinds = [draw_equation(4, i, cut).structure for i in range(24)]
    shells = [st for st in kinds if st["shell"]]
    assert {st["cut"]["kind"] for st in shells if st["cut"]} == {"half", "slab"}
    # ...and a hollow ring is left whole (cut open, it is a torn strip)
    assert all(st["cut"] is None for st in shells if st["envelope"]["kind"] == "torus")
    assert any(st["envelope"]["kind"] == "torus" for st in shells)
    assert {st["cut"]["kind"] for st in kinds if not st["shell"]} >= {"cube", "octahedron"}


def test_rings_that_would_cross_are_linked_into_a_chain() -> None:
    """Rings only (``body_weights`` all on the torus): an arrangement whose rings would cross
    is drawn as a chain of linked rings, never as the balls it once fell back to; rings that
    stay apart keep their arrangement."""
    cfg = family("assembly").with_settings("assembly", body_weights=(0.0, 0.0, 1.0))
    crossing = apart = 0
    for i in range(120):
        info = draw_equation(11, i, cfg).structure
        assert info["body"] == "torus", (i, info)
        crossing += info["arrangement"] == "chain"
        apart += info["arrangement"] in ("triangle", "tetra", "row", "square")
    assert crossing >= 10 and apart >= 10
