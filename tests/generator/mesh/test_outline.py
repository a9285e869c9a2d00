"""The outline measure: every view's silhouette against its convex hull."""

from __future__ import annotations

import numpy as np

from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import Mesh, extract_mesh
from surfgen.generator.mesh.outline import VIEWS, outline_fill, outline_fills


def mesh_of(formula: str, half: float, n: int = 40) -> Mesh:
    grid = Grid(Box.cube(half), (n, n, n))
    return extract_mesh(evaluate_reference(parse(formula), grid), cap=True)


def test_a_ball_fills_its_outline_in_every_view() -> None:
    fills = outline_fills(mesh_of("x^2+y^2+z^2-1", 1.3))
    assert fills.shape == (len(VIEWS),)
    assert np.all(fills > 0.95) and np.all(fills <= 1.0)


def test_a_dented_ball_is_a_convex_outline_and_a_star_is_not() -> None:
    dented = mesh_of("x^2+y^2+z^2-1+0.15*cos(5*x)*cos(5*y)*cos(5*z)", 1.4)
    assert outline_fill(dented) > 0.9  # dents do not show in the silhouette
    # three bars crossing at the centre: every view shows arms
    star = mesh_of("min(min(y^2+z^2, x^2+z^2), x^2+y^2)-0.09+0.01*(x^2+y^2+z^2)", 1.4, 48)
    assert outline_fill(star) < 0.7


def test_a_hole_one_sees_through_counts_as_empty() -> None:
    """A torus along its axis is a ring (the hole is part of its hull, not of its silhouette):
    filled (1.3^2 - 0.7^2) / 1.3^2 = 0.71; from the side it is a rounded bar."""
    torus = mesh_of("(sqrt(x^2+y^2)-1)^2+z^2-0.09", 1.4, 56)
    fills = outline_fills(torus)
    along_z = fills[2]
    assert abs(along_z - 0.71) < 0.06
    assert fills[0] > 0.9 and fills[1] > 0.9
    assert outline_fill(torus) == fills.min()


def test_the_measure_is_a_function_of_the_surface_alone() -> None:
    """The faces' order and the vertices' order do not change it (coverage is a union), nor does
    a translation by a power of two (the projection is about the bounding box's centre)."""
    mesh = mesh_of("x^2+2*y^2+z^4-1+0.3*sin(3*x)", 1.6)
    want = outline_fills(mesh)
    rng = np.random.default_rng(0)
    faces = mesh.faces[rng.permutation(len(mesh.faces))]
    assert np.array_equal(outline_fills(Mesh(mesh.vertices, faces)), want)
    moved = Mesh(mesh.vertices + 4.0, mesh.faces)
    assert np.array_equal(outline_fills(moved), want)
    assert np.array_equal(outline_fills(Mesh(mesh.vertices, mesh.faces[:0])), np.ones(len(VIEWS)))
