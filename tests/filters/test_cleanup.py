"""The cleanup chain: closed manifold results, each step does its job and says so."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.filters import meshlab
from surfgen.filters.cleanup import (
    CleanupError,
    CleanupOptions,
    clean_mesh,
    edge_lengths,
    repair_mesh,
    signed_volume,
    target_edge_for_faces,
)
from surfgen.filters.metrics import measure_mesh
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import Mesh, extract_mesh

TORUS = "(sqrt(x^2+y^2)-1)^2+z^2-0.16"
CHAIN = (
    "merge_close_vertices",
    "remove_duplicate_faces",
    "remove_degenerate_faces",
    "repair_nonmanifold_edges",
    "repair_nonmanifold_vertices",
    "remove_small_components",
    "close_holes",
    "orient_outward",
)


def surface(formula: str, half: float, n: int, cap: bool = True) -> Mesh:
    field = evaluate_reference(parse(formula), Grid(Box.cube(half), (n,) * 3))
    return extract_mesh(field, 0.0, cap=cap)


@pytest.fixture(scope="module")
def capped_torus() -> Mesh:
    """A torus cut by the box (|z| stays inside, x and y are cut) and closed by flat caps."""
    return surface(TORUS, 1.2, 32)


def assert_closed(mesh: Mesh, genus: int, components: int = 1) -> None:
    m = measure_mesh(mesh)
    assert m.watertight and m.nonmanifold_edges == 0 and m.nonmanifold_vertices == 0
    assert m.genus == genus and m.components == components
    assert m.volume is not None and m.volume > 0


def test_capped_torus_comes_out_watertight_manifold_genus_1(capped_torus):
    result = clean_mesh(capped_torus)
    assert_closed(result.mesh, genus=1)
    assert tuple(s.step for s in result.steps) == CHAIN
    assert signed_volume(result.mesh) == pytest.approx(signed_volume(capped_torus), rel=1e-6)


def test_step_reports_chain_their_counts(capped_torus):
    result = clean_mesh(capped_torus, CleanupOptions(remesh=True, smooth=2))
    steps = result.steps
    assert steps[0].faces_before == capped_torus.n_faces
    assert steps[-1].faces_after == result.mesh.n_faces
    for a, b in zip(steps, steps[1:], strict=False):
        assert a.faces_after == b.faces_before and a.vertices_after == b.vertices_before
    assert [s.step for s in steps[-2:]] == ["isotropic_remesh", "taubin_smooth"]
    for s in steps:
        d = s.to_dict()
        assert d["step"] == s.step and isinstance(d["details"], dict)
        assert s.describe().startswith(f"{s.step}: ")


def test_merging_pinches_and_the_chain_repairs_it():
    # The spheres touch at the origin, a grid point exactly on the level.  surfgen keeps its
    # crossings 1 % of an edge apart, so merging leaves its own mesh alone; a mesh from a
    # marching cubes that puts a vertex of each sphere on that point (simulated by snapping
    # them onto it) pinches when merged (a non-manifold vertex), and the chain repairs it.
    ours = surface("min((x-1)^2+y^2+z^2-1,(x+1)^2+y^2+z^2-1)", 2.5, 41)
    assert measure_mesh(meshlab.merge_close_vertices(ours)).nonmanifold_vertices == 0
    vertices = np.array(ours.vertices)
    near = np.linalg.norm(vertices, axis=1) < 0.05 * 5 / 40
    assert near.sum() >= 2
    vertices[near] = 0.0
    mesh = Mesh(vertices, ours.faces)
    assert measure_mesh(meshlab.merge_close_vertices(mesh)).nonmanifold_vertices >= 1
    result = clean_mesh(mesh)
    assert_closed(result.mesh, genus=0, components=2)
    report = {s.step: s for s in result.steps}
    assert report["merge_close_vertices"].details["vertices_merged"] >= 1
    assert report["repair_nonmanifold_vertices"].details["vertices_split"] >= 1
    # The split copies are apart, so an STL writer/reader that fuses equal points cannot pinch.
    assert len(np.unique(result.mesh.vertices, axis=0)) == result.mesh.n_vertices


def test_a_triangle_soup_is_welded_into_a_closed_mesh(capped_torus):
    soup = Mesh(
        capped_torus.vertices[capped_torus.faces.reshape(-1)],
        np.arange(3 * capped_torus.n_faces).reshape(-1, 3),
    )
    assert not measure_mesh(soup).watertight
    result = clean_mesh(soup)
    assert_closed(result.mesh, genus=1)
    assert result.steps[0].details["vertices_merged"] > 0


def test_small_components_are_dropped_but_never_the_largest():
    mesh = surface("min(x^2+y^2+z^2-1, (x-1.3)^2+(y-1.3)^2+(z-1.3)^2-0.02)", 1.5, 40)
    assert measure_mesh(mesh).components == 2
    result = clean_mesh(mesh, CleanupOptions(min_component=0.02))
    step = next(s for s in result.steps if s.step == "remove_small_components")
    assert step.details["components_removed"] == 1 and step.faces_after < step.faces_before
    assert_closed(result.mesh, genus=0)
    # Asking for more than any component has keeps the largest rather than nothing.
    kept = clean_mesh(mesh, CleanupOptions(min_component=0.999)).mesh
    assert measure_mesh(kept).components == 1


def test_small_holes_are_closed_big_ones_are_left(capped_torus):
    # Remove the faces around one vertex: a hole of a few edges.
    f = capped_torus.faces
    centre = f[len(f) // 2, 0]
    holed = Mesh(capped_torus.vertices, f[~np.any(f == centre, axis=1)])
    result = clean_mesh(holed)
    step = next(s for s in result.steps if s.step == "close_holes")
    assert step.details["holes"] == 1 and step.details["holes_closed"] == 1
    assert_closed(result.mesh, genus=1)
    # An uncapped surface cut by the box keeps its big boundary loops.
    open_sphere = surface("x^2+y^2+z^2-1", 0.9, 30, cap=False)
    result = clean_mesh(open_sphere)
    step = next(s for s in result.steps if s.step == "close_holes")
    assert step.details["holes"] == 6 and step.details["holes_left"] == 6
    assert not measure_mesh(result.mesh).watertight


@pytest.mark.parametrize("flip", ["all", "half"])
def test_faces_end_up_coherent_and_outward(capped_torus, flip):
    faces = capped_torus.faces.copy()
    rows = slice(None) if flip == "all" else slice(0, len(faces) // 2)
    faces[rows] = faces[rows][:, ::-1]
    result = clean_mesh(Mesh(capped_torus.vertices, faces))
    step = result.steps[-1]
    assert step.step == "orient_outward" and step.details["faces_flipped"] > 0
    assert_closed(result.mesh, genus=1)


def test_remeshing_hits_the_target_edge_length(capped_torus):
    target = 0.1
    result = clean_mesh(capped_torus, CleanupOptions(target_edge=target))
    median = float(np.median(edge_lengths(result.mesh)))
    assert median == pytest.approx(target, rel=0.2)
    assert result.steps[-1].details["median_edge"] == pytest.approx(median)
    assert_closed(result.mesh, genus=1)


def test_remeshing_to_a_face_budget(capped_torus):
    repaired = repair_mesh(capped_torus).mesh
    target = target_edge_for_faces(repaired, 3000)
    result = clean_mesh(capped_torus, CleanupOptions(target_faces=3000))
    assert result.steps[-1].details["target_edge"] == pytest.approx(target)
    assert 0.7 * 3000 < result.mesh.n_faces < 1.3 * 3000
    assert_closed(result.mesh, genus=1)


def test_taubin_smoothing_keeps_the_volume(capped_torus):
    before = clean_mesh(capped_torus).mesh
    result = clean_mesh(capped_torus, CleanupOptions(smooth=10))
    step = result.steps[-1]
    assert step.step == "taubin_smooth" and step.details["volume_restored"]
    assert signed_volume(result.mesh) == pytest.approx(signed_volume(before), rel=1e-9)
    assert not np.allclose(result.mesh.vertices, before.vertices)
    assert_closed(result.mesh, genus=1)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"target_edge": 0.1, "target_faces": 100},
        {"target_edge": -1.0},
        {"target_faces": 2},
        {"min_component": 1.0},
        {"smooth": -1},
    ],
)
def test_bad_options_are_refused(kwargs):
    with pytest.raises(CleanupError):
        CleanupOptions(**kwargs)


def test_a_target_edge_larger_than_the_shape_is_refused(capped_torus):
    with pytest.raises(CleanupError, match="quarter"):
        clean_mesh(capped_torus, CleanupOptions(target_edge=10.0))
