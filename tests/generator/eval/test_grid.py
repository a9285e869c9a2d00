"""Boxes and grids: both ends included, and the limits that keep meshes and their files sound."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.generator.errors import GridError
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import MAX_COORDINATE, MIN_RELATIVE_SPACING, Box, Grid
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.exchange import load_mesh, save_mesh
from surfgen.generator.mesh.mesh import extract_mesh


def test_axes_include_both_ends() -> None:
    grid = Grid(Box((-1.0, 0.0, 2.0), (1.0, 3.0, 2.5)), (5, 4, 6))
    x, y, z = grid.axes()
    assert x.tolist() == [-1.0, -0.5, 0.0, 0.5, 1.0]
    assert (y[0], y[-1], z[0], z[-1]) == (0.0, 3.0, 2.0, 2.5)
    assert grid.spacing == (0.5, 1.0, 0.1)


@pytest.mark.parametrize(
    ("lo", "hi", "message"),
    [
        (
            (0.0, 0.0, 0.0),
            (1e308, 1.0, 1.0),
            "the x bounds must lie within ±1000000, got 0.0, 1e+308",
        ),
        ((0.0, -1e308, 0.0), (1.0, 1e308, 1.0), "the y bounds must lie within ±1000000"),
        ((0.0, 0.0, -1_000_001.0), (1.0, 1.0, 0.0), "the z bounds must lie within ±1000000"),
        ((0.0, 0.0, 0.0), (1.0, float("inf"), 1.0), "the y bounds must be finite numbers"),
        ((0.0, 0.0, 0.0), (1.0, 1.0, float("nan")), "the z bounds must be finite numbers"),
        ((1.0, 0.0, 0.0), (1.0, 1.0, 1.0), "xmin must be less than xmax"),
    ],
)
def test_boxes_out_of_bounds_are_refused(lo, hi, message) -> None:
    with pytest.raises(GridError, match=message.replace("+", r"\+")):
        Box(lo, hi)


def test_boxes_at_the_limit_are_accepted() -> None:
    box = Box((-MAX_COORDINATE,) * 3, (MAX_COORDINATE,) * 3)
    assert Grid(box, (2048, 4, 4)).spacing[0] == 2 * MAX_COORDINATE / 2047


def test_grid_points_finer_than_float32_files_hold_are_refused() -> None:
    # 64 points over [999999, 1000000]: 0.016 apart, where float32 steps by 0.0625
    box = Box((999_999.0, 0.0, 0.0), (1_000_000.0, 1.0, 1.0))
    with pytest.raises(GridError, match=r"64 points over x in \[999999.0, 1000000.0\]"):
        Grid(box, (64, 64, 64))
    # the same width far from nothing is fine, as is the same box at fewer points
    Grid(Box((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)), (2048, 2048, 2048))
    far = 1000.0
    n = 64
    edge = (n - 1) * far * MIN_RELATIVE_SPACING
    with pytest.raises(GridError, match="too fine for mesh files"):
        Grid(Box((far - edge * 0.99, 0.0, 0.0), (far, 1.0, 1.0)), (n, 4, 4))
    Grid(Box((far - edge * 1.01, 0.0, 0.0), (far, 1.0, 1.0)), (n, 4, 4))


def test_the_finest_grid_allowed_keeps_its_mesh_in_a_float32_file(tmp_path) -> None:
    # A ball in the finest box allowed at 1000 from the origin: written as binary PLY (float32
    # coordinates) and read back, every vertex stays within 1/16 of a cell of its place.
    n, far = 24, 1000.0
    width = 1.01 * (n - 1) * far * MIN_RELATIVE_SPACING
    lo, hi = far - width, far
    grid = Grid(Box((lo, lo, lo), (hi, hi, hi)), (n, n, n))
    c, r = (lo + hi) / 2, 0.35 * width
    tree = parse(f"(x-({c!r}))^2+(y-({c!r}))^2+(z-({c!r}))^2-{r * r!r}")
    mesh = extract_mesh(evaluate(tree, grid), 0.0)
    assert mesh.n_faces > 100
    back = load_mesh(save_mesh(mesh, tmp_path / "ball.ply"))
    assert np.array_equal(back.faces, mesh.faces)
    assert np.max(np.abs(back.vertices - mesh.vertices)) <= grid.spacing[0] / 16
