"""The pymeshlab adapter: topology, and every repair returns a valid mesh that did its job."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pymeshlab
import pytest

from surfgen.filters import meshlab
from surfgen.filters.metrics import measure_mesh
from surfgen.generator.errors import MeshError
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import Mesh, extract_mesh

ROOT = Path(__file__).resolve().parents[2]


def assert_valid(mesh: Mesh) -> None:
    assert isinstance(mesh, Mesh) and mesh.n_faces > 0
    assert mesh.vertices.dtype == np.float64 and mesh.faces.dtype == np.int64
    assert not mesh.vertices.flags.writeable and not mesh.faces.flags.writeable
    assert mesh.faces.min() >= 0 and mesh.faces.max() < mesh.n_vertices
    assert np.isfinite(mesh.vertices).all()


def small_sphere() -> Mesh:
    field = evaluate_reference(parse("x^2+y^2+z^2-1"), Grid(Box.cube(1.3), (16, 16, 16)))
    return extract_mesh(field)


REPAIRS = {
    "merge_close_vertices": lambda m: meshlab.merge_close_vertices(m, 1e-9),
    "remove_duplicate_faces": meshlab.remove_duplicate_faces,
    "remove_degenerate_faces": meshlab.remove_degenerate_faces,
    "repair_nonmanifold_edges": meshlab.repair_nonmanifold_edges,
    "repair_nonmanifold_edges_split": lambda m: meshlab.repair_nonmanifold_edges(
        m, "split_vertices"
    ),
    "repair_nonmanifold_vertices": meshlab.repair_nonmanifold_vertices,
    "remove_small_components": lambda m: meshlab.remove_small_components(m, 0.01),
    "close_holes": lambda m: meshlab.close_holes(m, 30),
    "reorient_outward": meshlab.reorient_outward,
    "isotropic_remesh": lambda m: meshlab.isotropic_remesh(m, 0.2, iterations=2),
    "taubin_smooth": lambda m: meshlab.taubin_smooth(m, 5),
}


@pytest.mark.parametrize("name", REPAIRS)
def test_every_repair_keeps_a_closed_sphere_closed(name):
    sphere = small_sphere()
    out = REPAIRS[name](sphere)
    assert_valid(out)
    m = measure_mesh(out)
    assert m.genus == 0 and m.components == 1 and m.volume > 0
    assert m.volume == pytest.approx(4 / 3 * np.pi, rel=0.05)
    # the input was not touched
    assert sphere.n_faces == small_sphere().n_faces


def test_topology_of_the_torus(torus_mesh):
    t = meshlab.topology(torus_mesh)
    assert t["genus"] == 1 and t["components"] == 1 and t["two_manifold"] is True
    assert t["boundary_edges"] == 0 and t["holes"] == 0
    assert t["faces"] == torus_mesh.n_faces and t["vertices"] == torus_mesh.n_vertices
    assert all(type(v) in (int, bool) or v is None for v in t.values())


def test_merge_close_vertices_rebuilds_a_triangle_soup(sphere_mesh):
    soup = Mesh(
        sphere_mesh.vertices[sphere_mesh.faces].reshape(-1, 3), np.arange(3 * sphere_mesh.n_faces)
    )
    assert measure_mesh(soup).boundary_edges > 0
    merged = meshlab.merge_close_vertices(soup)
    assert merged.n_vertices == sphere_mesh.n_vertices
    assert measure_mesh(merged).genus == 0


def test_remove_duplicate_and_degenerate_faces(sphere_mesh):
    doubled = Mesh(sphere_mesh.vertices, np.vstack([sphere_mesh.faces, sphere_mesh.faces[:7]]))
    assert meshlab.remove_duplicate_faces(doubled).n_faces == sphere_mesh.n_faces
    f0 = sphere_mesh.faces[0]
    null = Mesh(sphere_mesh.vertices, np.vstack([sphere_mesh.faces, [[f0[0], f0[1], f0[1]]]]))
    assert meshlab.remove_degenerate_faces(null).n_faces == sphere_mesh.n_faces


def test_repair_nonmanifold_edge_and_vertex():
    sphere = small_sphere()
    a, b = sphere.faces[0, 0], sphere.faces[0, 1]
    fin = Mesh(
        np.vstack([sphere.vertices, [[3, 3, 3]]]),
        np.vstack([sphere.faces, [[a, b, sphere.n_vertices]]]),
    )
    assert measure_mesh(fin).nonmanifold_edges == 1
    assert measure_mesh(meshlab.repair_nonmanifold_edges(fin)).nonmanifold_edges == 0
    # two spheres glued at one vertex
    other = Mesh(sphere.vertices + [2.5, 0, 0], sphere.faces)
    v = np.vstack([sphere.vertices, other.vertices])
    f = np.vstack([sphere.faces, other.faces + sphere.n_vertices])
    f[f == sphere.n_vertices + int(np.argmin(other.vertices[:, 0]))] = int(
        np.argmax(sphere.vertices[:, 0])
    )
    glued = Mesh(v, f)
    assert measure_mesh(glued).nonmanifold_vertices == 1
    fixed = meshlab.repair_nonmanifold_vertices(glued)
    m = measure_mesh(fixed)
    assert m.nonmanifold_vertices == 0 and m.genus == 0 and m.components == 2


def test_remove_small_components_drops_a_speck():
    formula = "min(x^2+y^2+z^2-1, (x-1.4)^2+(y-1.4)^2+(z-1.4)^2-0.04)"
    field = evaluate_reference(parse(formula), Grid(Box.cube(1.7), (40, 40, 40)))
    both = extract_mesh(field)
    assert measure_mesh(both).components == 2
    kept = meshlab.remove_small_components(both, 0.1)
    m = measure_mesh(kept)
    assert m.components == 1 and m.area == pytest.approx(4 * np.pi, rel=0.03)
    assert meshlab.remove_small_components(both, 0.0).n_faces == both.n_faces


def test_close_holes_fills_a_small_hole():
    sphere = small_sphere()
    holed = meshlab.remove_small_components(Mesh(sphere.vertices, sphere.faces[3:]), 0.0)
    assert measure_mesh(holed).boundary_edges > 0
    closed = measure_mesh(meshlab.close_holes(holed, 30))
    assert closed.watertight and closed.genus == 0


def test_reorient_outward_fixes_flipped_faces(two_spheres_mesh):
    faces = np.array(two_spheres_mesh.faces)[:, ::-1]  # all inward ...
    faces[:25] = faces[:25, ::-1]  # ... but a few
    m = measure_mesh(meshlab.reorient_outward(Mesh(two_spheres_mesh.vertices, faces)))
    assert m.components == 2 and m.genus == 0 and m.volume > 0


def test_isotropic_remesh_hits_the_target_length():
    out = meshlab.isotropic_remesh(small_sphere(), 0.15, iterations=3)
    edges = out.vertices[out.faces] - out.vertices[np.roll(out.faces, 1, axis=1)]
    assert np.median(np.linalg.norm(edges, axis=2)) == pytest.approx(0.15, rel=0.3)


def test_errors():
    with pytest.raises(MeshError, match="split_vertices"):
        meshlab.repair_nonmanifold_edges(small_sphere(), "glue")
    with pytest.raises(MeshError, match="empty"):
        meshlab.topology(Mesh(np.zeros((0, 3)), np.zeros((0, 3))))


def test_pinned_version_is_installed():
    assert meshlab.installed_version() == meshlab.PYMESHLAB_VERSION
    for name in meshlab.FILTERS.values():
        assert hasattr(pymeshlab.MeshSet, name), name


def test_only_the_adapter_imports_pymeshlab():
    pattern = re.compile(r"^\s*(import|from)\s+pymeshlab\b", re.MULTILINE)
    offenders = [
        str(p.relative_to(ROOT))
        for folder in ("generator", "filters", "pipelines")
        for p in (ROOT / folder).rglob("*.py")
        if pattern.search(p.read_text()) and p.name != "meshlab.py"
    ]
    assert offenders == []
