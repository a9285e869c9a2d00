"""Filters: field screening and mesh verdicts on shapes whose answer is known."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.filters.shape import solidity
from surfgen.filters.verdict import (
    FilterConfig,
    field_statistics,
    judge,
    plain,
    quick_metrics,
    screen_field,
    shape_metrics,
)
from surfgen.generator.errors import SpecError
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import extract_mesh
from surfgen.generator.mesh.outline import outline_fill
from surfgen.generator.model.families import family_names, get_family
from surfgen.generator.model.presets import PRESETS

CFG = FilterConfig(min_faces=100)


def mesh_of(formula: str, half: float, n: int = 32, cap: bool = True):
    grid = Grid(Box.cube(half), (n, n, n))
    return extract_mesh(evaluate_reference(parse(formula), grid), cap=cap), grid


def test_convex_lump_is_a_blob_and_a_torus_is_not() -> None:
    sphere, g = mesh_of("x^2+y^2+z^2-1", 1.5)
    m = shape_metrics(sphere, g.box.bounds())
    assert 0.9 < m["total_curvature"] < 1.1  # Gauss-Bonnet: integral |K| = 4 pi for convex
    assert judge(m, CFG, capped=True).reasons == ("blob",)
    torus, g = mesh_of("(sqrt(x^2+y^2)-1)^2+z^2-0.16", 1.6, 40)
    # not a blob (a ring), but a plain one: plain since sampler 7
    assert judge(shape_metrics(torus, g.box.bounds()), CFG, capped=True).reasons == ("plain",)


def test_a_slab_cut_by_the_box_is_box_dominated_and_convex() -> None:
    slab, g = mesh_of("z-0.5", 1.0, 16)
    m = shape_metrics(slab, g.box.bounds())
    assert m["box_fraction"] > 0.7
    assert set(judge(m, CFG, capped=True).reasons) == {"box_dominated", "blob"}


def test_speckle_many_small_components() -> None:
    speckle, g = mesh_of("sin(6*x)*sin(6*y)*sin(6*z)-0.7", 3.0, 48)
    q = quick_metrics(speckle, g.box.bounds())
    assert q["components"] > 60
    assert "speckle" in judge(q, CFG, capped=True).reasons


def test_quick_metrics_agree_with_full_metrics() -> None:
    torus, g = mesh_of("(sqrt(x^2+y^2)-1)^2+z^2-0.16", 1.6, 40)
    q, m = quick_metrics(torus, g.box.bounds()), shape_metrics(torus, g.box.bounds())
    assert q["components"] == m["components"] == 1 and q["faces"] == m["faces"]


def test_quick_metrics_take_the_face_areas_a_caller_has() -> None:
    from surfgen.generator.mesh.mesh import face_areas

    slab, g = mesh_of("z-0.5+0.2*sin(3*x)", 1.0, 24)
    areas = face_areas(slab)
    assert quick_metrics(slab, g.box.bounds(), areas) == quick_metrics(slab, g.box.bounds())
    # they are used, not measured again: other areas, other shares
    half = areas.copy()
    half[: len(half) // 2] = 0.0
    assert quick_metrics(slab, g.box.bounds(), half) != quick_metrics(slab, g.box.bounds())


def test_screen_field_reasons() -> None:
    cfg = FilterConfig()
    g = Grid(Box.cube(1), (24, 24, 24))
    x, y, z = g.open_axes()
    assert screen_field(np.broadcast_to(x + 5.0, g.shape), 0, cfg, coarse=True).reasons == (
        "empty",
    )
    assert screen_field(np.broadcast_to(x - 5.0, g.shape), 0, cfg, coarse=True).reasons == ("full",)
    noise = np.random.default_rng(0).standard_normal(g.shape)
    assert screen_field(noise, 0, cfg, coarse=True).reasons == ("noise",)
    nan = np.full(g.shape, np.nan)
    assert screen_field(nan, 0, cfg, coarse=True).reasons == ("nonfinite",)
    sphere = np.broadcast_to(x**2 + y**2 + z**2 - 0.5, g.shape)
    assert screen_field(sphere, 0, cfg, coarse=True).accepted
    slab = np.broadcast_to(z + 0 * x - 0.5, g.shape)
    assert screen_field(slab, 0, cfg, coarse=True).reasons == ("full",) or screen_field(
        slab, 0, cfg, coarse=True
    ).reasons == ("box_dominated",)


def test_field_statistics_counts_nonfinite_as_outside() -> None:
    v = np.array([[[-1.0, np.nan], [np.inf, -np.inf]]] * 2)
    s = field_statistics(v)
    assert s["nonfinite_fraction"] == 0.75 and s["inside_fraction"] == 0.25


def test_exact_zeros_of_a_staircase_give_a_manifold_mesh() -> None:
    """stair2 makes F exactly 0 on whole slabs; exact zeros are outside (F < level is inside)."""
    mesh, g = mesh_of("stair1(z,0.5,1,4)+0*x", 1.3, 27)
    values = evaluate_reference(parse("stair1(z,0.5,1,4)+0*x"), g).values
    assert (values == 0).sum() > 1000
    m = shape_metrics(mesh, g.box.bounds())
    assert m["nonmanifold_edges"] == 0 and m["nonmanifold_vertices"] == 0 and m["watertight"]


def test_config_validation() -> None:
    with pytest.raises(SpecError, match="max_box_fraction must be in"):
        FilterConfig(max_box_fraction=2)
    with pytest.raises(SpecError, match="unknown key 'nope'"):
        FilterConfig.from_mapping({"nope": 1})


def test_a_stack_of_plates_is_a_blob() -> None:
    plates, g = mesh_of("sin(3*z)+0.6+0*x", 2.0, 32)
    m = shape_metrics(plates, g.box.bounds())
    assert m["components"] >= 2 and m["genus"] == 0
    assert "blob" in judge(m, CFG, capped=True).reasons


def _closed_metrics(formula: str, half: float, n: int) -> dict:
    mesh, g = mesh_of(formula, half, n)
    m = shape_metrics(mesh, g.box.bounds())
    m["solidity"] = solidity(mesh, m["volume"])
    return m


def test_a_sphere_with_a_tiny_bump_is_plain() -> None:
    m = _closed_metrics("x^2+y^2+z^2-1-0.25*exp(-((x-1)^2+y^2+z^2)/0.02)", 1.5, 32)
    assert m["genus"] == 0 and m["components"] == 1 and m["solidity"] > 0.99
    assert plain(m, CFG)
    assert "plain" in judge(m, CFG, capped=True).reasons
    # the envelope measure alone would not see it: there is no envelope
    assert "departure" not in m


def test_plain_keeps_the_papers_equation_a() -> None:
    # Equation A as printed, in a box its body fills (in the preset's box of +-155 it is a
    # speck of 140 faces): a rounded box carved with ridges, a ninth of its hull cut away.
    spec = PRESETS["eqA"].spec()
    grid = Grid(Box.cube(8.0), (82,) * 3)
    mesh = extract_mesh(evaluate_reference(spec.tree(), grid, spec.params), cap=True)
    m = shape_metrics(mesh, grid.box.bounds())
    m["solidity"] = solidity(mesh, m["volume"])
    assert m["solidity"] < 0.9
    assert not plain(m, CFG)
    assert not plain({**m, "components": 1}, CFG)  # not for its debris: for its carving


def test_plain_by_departure_solidity_or_curvature_and_only_when_measured() -> None:
    assert not plain({}, CFG)
    assert plain({"departure": 0.05}, CFG) and not plain({"departure": 0.2}, CFG)
    body = {"genus": 0, "components": 1, "solidity": 0.95, "total_curvature": 9.0}
    assert plain(body, CFG)
    assert not plain({**body, "solidity": 0.85}, CFG)
    assert plain({**body, "genus": 1}, CFG)  # a box with a pinhole: solidity whatever the genus
    assert not plain({**body, "components": 2}, CFG)
    assert not plain(body, FilterConfig(plain_min_solidity=0.97))
    # a lump with a few dents: one genus-0 piece of low total curvature, whatever its solidity
    lump = {"genus": 0, "components": 1, "solidity": 0.7, "total_curvature": 3.0}
    assert plain(lump, CFG)
    assert not plain({**lump, "total_curvature": 6.5}, CFG)  # carved: saddles add curvature
    # one plain ring (a torus has exactly 2): plain; a frame of genus 5 with little curvature
    # to spare is not judged this way; nor are two rings
    assert plain({**lump, "genus": 1}, CFG)
    assert not plain({**lump, "genus": 1, "total_curvature": 6.5}, CFG)
    assert not plain({**lump, "genus": 1, "components": 2}, CFG)
    assert not plain({**lump, "genus": 5, "total_curvature": 5.5}, CFG)
    assert plain({**lump, "components": 2}, CFG)  # two dented balls: summed, still low
    assert not plain({**lump, "components": 2, "total_curvature": 8.0}, CFG)
    assert not plain(lump, FilterConfig(plain_max_curvature=0.0))  # off
    assert plain({**lump, "total_curvature": 6.5}, FilterConfig(plain_max_curvature=7.0))


def test_a_peanut_is_plain_by_curvature_and_a_carved_ball_is_not() -> None:
    peanut = _closed_metrics("((x-0.7)^2+y^2+z^2)*((x+0.7)^2+y^2+z^2)-0.3", 1.8, 48)
    assert peanut["genus"] == 0 and peanut["components"] == 1
    assert peanut["solidity"] < CFG.plain_min_solidity  # the solidity alone would keep it
    assert peanut["total_curvature"] < CFG.plain_max_curvature
    assert "plain" in judge(peanut, CFG, capped=True).reasons
    carved = _closed_metrics("x^2+y^2+z^2-1+0.5*cos(7*x)*cos(7*y)", 1.7, 48)
    assert carved["genus"] == 0 and carved["components"] == 1
    assert carved["total_curvature"] > 2 * CFG.plain_max_curvature
    assert not plain(carved, CFG)


def test_a_plain_ring_and_a_ring_with_a_knob_are_plain_and_a_frame_is_not() -> None:
    """One piece of genus 1 below ``plain_max_curvature``: a torus (exactly 2) and a torus
    with a ball on it are plain; a cube frame (genus 5, smooth) is not judged by curvature."""
    ring = "(x^2+y^2+z^2+0.49-0.04)^2-4*0.49*(x^2+y^2)"
    torus = _closed_metrics(ring, 1.2, 48)
    assert torus["genus"] == 1 and torus["components"] == 1
    assert abs(torus["total_curvature"] - 2.0) < 0.3
    assert "plain" in judge(torus, CFG, capped=True).reasons
    knob = _closed_metrics(f"min({ring}, (x-0.7)^2+y^2+z^2-0.09)", 1.2, 48)
    assert knob["genus"] == 1 and knob["components"] == 1 and plain(knob, CFG)
    frame = _closed_metrics("x^4-5*x^2+y^4-5*y^2+z^4-5*z^2+11.8", 3.0, 56)  # tanglecube
    assert frame["genus"] == 5 and frame["components"] == 1, frame
    assert not plain(frame, CFG)


def test_a_body_broken_into_pieces_is_fragmented_only_where_drawn_as_one() -> None:
    """Families drawn as one body (sculpture, infill, twist) reject a shape whose largest piece
    holds under ``min_body_fraction`` of the area; others (assemblies of separate bodies,
    chains, lattices cut by the box) are judged as before."""
    two = _closed_metrics("((x-0.8)^2+y^2+z^2-0.25)*((x+0.8)^2+y^2+z^2-0.3)", 1.6, 40)
    assert two["components"] == 2 and 0.4 < two["largest_component_fraction"] < 0.6
    assert "fragmented" in judge(two, CFG, capped=True, one_body=True).reasons
    assert "fragmented" not in judge(two, CFG, capped=True).reasons
    assert "fragmented" not in judge(two, FilterConfig(min_body_fraction=0.5), True, True).reasons
    one = {**two, "components": 1, "largest_component_fraction": 1.0}
    assert "fragmented" not in judge(one, CFG, capped=True, one_body=True).reasons
    bodies = {name for name in family_names() if get_family(name).one_body}
    assert bodies == {"sculpture", "infill", "twist"}


def test_bodies_with_flying_debris_are_fragmented_unless_porous() -> None:
    """A body with specks around it (nine balls: one large, eight small satellites) is
    fragmented in the families of bodies (more than ``max_pieces`` pieces), not in the porous
    ones (lattice, infill: struts cut by the box or an envelope), nor when no family is known."""
    body = "(x^2+y^2+z^2-0.64)"
    satellites = "*".join(
        f"((x-{1.2 * a})^2+(y-{1.2 * b})^2+(z-{1.2 * c})^2-0.01)"
        for a in (-1, 1)
        for b in (-1, 1)
        for c in (-1, 1)
    )
    nine = _closed_metrics(f"{body}*{satellites}", 1.6, 48)
    assert nine["components"] == 9 and nine["largest_component_fraction"] > 0.9, nine
    assert "fragmented" in judge(nine, CFG, capped=True, porous=False).reasons
    assert "fragmented" not in judge(nine, CFG, capped=True, porous=True).reasons
    assert "fragmented" not in judge(nine, CFG, capped=True).reasons  # no family: not judged
    up_to_nine = FilterConfig(max_pieces=9, min_piece_fraction=0.0)
    assert "fragmented" not in judge(nine, up_to_nine, True, porous=False).reasons
    eight = {**nine, "components": 8, "smallest_piece": 1.0}
    assert "fragmented" not in judge(eight, CFG, capped=True, porous=False).reasons
    porous = {name for name in family_names() if get_family(name).porous}
    assert porous == {"lattice", "infill"}
    with pytest.raises(SpecError, match="max_pieces must be >= 1"):
        FilterConfig(max_pieces=0)


def test_a_body_with_a_speck_of_debris_is_fragmented_unless_porous() -> None:
    """Two pieces, one a speck beside the body (its area under ``min_piece_fraction`` of the
    body's): fragmented in the families of bodies, whatever ``max_pieces``; two equal bodies
    are not."""
    speck = _closed_metrics("(x^2+y^2+z^2-0.64)*((x-1.25)^2+y^2+z^2-0.02)", 1.6, 48)
    assert speck["components"] == 2 and 0.02 < speck["smallest_piece"] < 0.1, speck
    assert "fragmented" in judge(speck, CFG, capped=True, porous=False).reasons
    assert "fragmented" not in judge(speck, CFG, capped=True, porous=True).reasons
    loose = FilterConfig(min_faces=100, min_piece_fraction=0.02)
    assert "fragmented" not in judge(speck, loose, capped=True, porous=False).reasons
    pair = _closed_metrics("((x-0.8)^2+y^2+z^2-0.25)*((x+0.8)^2+y^2+z^2-0.25)", 1.6, 40)
    assert pair["smallest_piece"] > 0.9
    assert "fragmented" not in judge(pair, CFG, capped=True, porous=False).reasons
    one = _closed_metrics("x^2+y^2+z^2-1", 1.3, 24)
    assert one["smallest_piece"] == 1.0
    with pytest.raises(SpecError, match="min_piece_fraction"):
        FilterConfig(min_piece_fraction=1.5)


def test_plain_by_outline_only_for_one_piece_of_low_genus() -> None:
    body = {"genus": 0, "components": 1, "solidity": 0.7, "total_curvature": 20.0}
    assert not plain(body, CFG)  # not measured: not judged
    assert plain({**body, "outline": 0.9}, CFG)
    assert not plain({**body, "outline": 0.8}, CFG)
    assert plain({**body, "genus": 7, "outline": 0.9}, CFG)
    assert not plain({**body, "genus": 8, "outline": 0.9}, CFG)
    assert not plain({**body, "components": 2, "outline": 0.9}, CFG)
    assert not plain({**body, "outline": 0.9}, FilterConfig(plain_min_outline=0.95))
    with pytest.raises(SpecError, match="plain_outline_max_genus"):
        FilterConfig(plain_outline_max_genus=-1)


def test_a_dented_ball_is_plain_by_its_outline_and_a_carved_star_is_not() -> None:
    """Dents everywhere give a ball curvature to spare (total |K| / 4 pi 14) and take a sixth
    of its hull away, so neither of the other mesh measures calls it plain; its outline does."""
    dented_formula = "x^2+y^2+z^2-1+0.35*cos(6*x)*cos(6*y)*cos(6*z)"
    dented = _closed_metrics(dented_formula, 1.6, 48)
    assert dented["genus"] == 0 and dented["components"] == 1
    assert dented["solidity"] < 0.85 and dented["total_curvature"] > 10
    assert not plain(dented, CFG)
    dented["outline"] = outline_fill(mesh_of(dented_formula, 1.6, 48)[0])
    assert plain(dented, CFG) and "plain" in judge(dented, CFG, capped=True).reasons
    star_formula = "min(min(y^2+z^2, x^2+z^2), x^2+y^2)-0.09+0.01*(x^2+y^2+z^2)"
    star = _closed_metrics(star_formula, 1.4, 48)
    star["outline"] = outline_fill(mesh_of(star_formula, 1.4, 48)[0])
    assert star["genus"] <= CFG.plain_outline_max_genus and star["components"] == 1
    assert not plain(star, CFG)


def test_every_family_but_twist_is_judged_by_its_outline() -> None:
    assert {name for name in family_names() if not get_family(name).outline} == {"twist"}
