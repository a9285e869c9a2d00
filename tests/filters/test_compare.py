"""Shape comparison: inside-sample IoU and Hausdorff distance on shapes with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.filters.compare import hausdorff, inside_iou, inside_samples, union_box
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Field, Grid
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import extract_mesh


def _sphere(radius: float, half: float = 1.5, n: int = 40) -> Field:
    grid = Grid(Box.cube(half), (n, n, n))
    return evaluate(parse(f"x^2+y^2+z^2-{radius}^2"), grid)


def test_iou_of_a_field_with_itself_is_one() -> None:
    f = _sphere(1.0)
    assert inside_iou(f, f, 48) == 1.0


def test_iou_of_nested_spheres_is_their_volume_ratio() -> None:
    small, large = _sphere(0.8), _sphere(1.2)
    assert inside_iou(small, large, 96) == pytest.approx((0.8 / 1.2) ** 3, rel=0.05)


def test_iou_does_not_depend_on_the_order_and_empty_pairs_are_equal() -> None:
    a, b = _sphere(0.7), _sphere(1.0, half=2.0, n=33)
    assert inside_iou(a, b, 64) == inside_iou(b, a, 64)
    grid = Grid(Box.cube(1.0), (8, 8, 8))
    empty = Field(grid, np.ones(grid.shape))
    assert inside_iou(empty, empty, 16) == 1.0
    assert inside_iou(empty, a, 16) == 0.0


def test_nonfinite_samples_and_points_beyond_a_box_are_outside() -> None:
    grid = Grid(Box.cube(1.0), (9, 9, 9))
    values = -np.ones(grid.shape)
    values[4, 4, 4] = np.nan
    fine = Grid(Box.cube(2.0), (17, 17, 17))
    inside = inside_samples(Field(grid, values), fine)
    assert not inside[8, 8, 8]  # the NaN sample
    assert not inside[0, 0, 0]  # outside the field's box
    assert inside[5, 5, 5]


def test_union_box_holds_both() -> None:
    box = union_box(Box.cube(7.0), Box((-1.0, -8.0, 0.0), (9.0, 1.0, 1.0)))
    assert box.lo == (-7.0, -8.0, -7.0) and box.hi == (9.0, 7.0, 7.0)


def test_hausdorff_of_concentric_spheres_is_the_radius_gap() -> None:
    a = extract_mesh(_sphere(0.8), 0.0)
    b = extract_mesh(_sphere(1.2), 0.0)
    assert hausdorff(a, b) == pytest.approx(0.4, abs=0.03)
    assert hausdorff(a, a) < 0.05  # two different sample sets: error ~ their spacing (~0.03)
    assert hausdorff(a, b) == hausdorff(a, b)  # seeded: deterministic
