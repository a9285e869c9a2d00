"""Bodies as power functions and min/max through ``|u|``: the union and intersection of two
spheres meshed, their volumes against the analytic lens and union; polynomials expanded right."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.expr import to_string
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import extract_mesh
from surfgen.generator.model.equation13 import Equation13
from surfgen.generator.model.families.bodies import (
    Polynomial,
    ball,
    body_factor,
    difference,
    intersection,
    positive_part,
    torus,
    union,
)

R1, R2, D = 1.0, 0.8, 1.2  # two spheres, centres D apart along x


def lens_volume(r1: float, r2: float, d: float) -> float:
    """The volume of the intersection of two balls (the textbook lens formula)."""
    return math.pi * (r1 + r2 - d) ** 2 * (d**2 + 2 * d * (r1 + r2) - 3 * (r1 - r2) ** 2) / (12 * d)


def ball_volume(r: float) -> float:
    return 4 / 3 * math.pi * r**3


def meshed_volume(terms, box: Box, n: int = 72) -> float:
    eq = Equation13(tuple(terms), 0.0)
    tree = eq.to_tree()
    assert parse(to_string(tree)) == tree  # a formula K3DSurf/MathMod read
    mesh = extract_mesh(evaluate(tree, Grid(box, (n,) * 3), threads=1), cap=True)
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    assert tm.is_watertight
    return float(tm.volume)


def two_spheres() -> tuple[Polynomial, Polynomial]:
    return ball((0.0, 0.0, 0.0), (R1,) * 3), ball((D, 0.0, 0.0), (R2,) * 3)


def test_intersection_of_two_spheres_is_the_lens() -> None:
    a, b = two_spheres()
    volume = meshed_volume(intersection(a, b), Box((-1.2, -1.2, -1.2), (2.2, 1.2, 1.2)))
    assert volume == pytest.approx(lens_volume(R1, R2, D), rel=0.03)


def test_union_of_two_spheres_is_both_less_the_lens() -> None:
    a, b = two_spheres()
    volume = meshed_volume(union(a, b), Box((-1.2, -1.2, -1.2), (2.2, 1.2, 1.2)))
    want = ball_volume(R1) + ball_volume(R2) - lens_volume(R1, R2, D)
    assert volume == pytest.approx(want, rel=0.02)


def test_difference_of_two_spheres_is_the_first_less_the_lens() -> None:
    a, b = two_spheres()
    volume = meshed_volume(difference(a, b), Box((-1.2, -1.2, -1.2), (2.2, 1.2, 1.2)))
    assert volume == pytest.approx(ball_volume(R1) - lens_volume(R1, R2, D), rel=0.03)


def test_positive_part_clips_a_field_to_a_body() -> None:
    """``L + c max(E, 0)`` is L inside the body E < 0 and L + c E outside."""
    body = ball((0.2, 0.0, 0.0), (0.7, 0.9, 1.0))
    terms = positive_part((body_factor(body),), 3.0)
    grid = Grid(Box.cube(1.5), (13,) * 3)
    clip = evaluate(Equation13(tuple(terms), 0.0).to_tree(), grid, threads=1).values
    e = evaluate(body_factor(body).to_tree(), grid, threads=1).values
    assert np.allclose(clip, 3.0 * np.maximum(e, 0.0), atol=1e-9)


def test_polynomials_expand_shifted_bodies() -> None:
    grid = Grid(Box.cube(2.0), (9,) * 3)
    x, y, z = np.meshgrid(*grid.axes(), indexing="ij")
    got = evaluate(body_factor(ball((0.5, -0.3, 0.1), (1.0, 0.7, 1.2), 4)).to_tree(), grid).values
    want = ((x - 0.5) / 1.0) ** 4 + ((y + 0.3) / 0.7) ** 4 + ((z - 0.1) / 1.2) ** 4 - 1
    assert np.allclose(got, want, rtol=1e-5, atol=1e-5)
    got = evaluate(body_factor(torus((0.3, 0, 0), (0, 1, 0), 1.0, 0.3)).to_tree(), grid).values
    s = (x - 0.3) ** 2 + y**2 + z**2
    want = ((s + 1.0 - 0.09) ** 2 - 4 * (s - y**2)) / (4 * 0.09)
    assert np.allclose(got, want, rtol=1e-5, atol=1e-4)
    with pytest.raises(ValueError, match="even"):
        ball((0, 0, 0), (1, 1, 1), 3)
