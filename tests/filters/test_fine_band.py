"""The resolution check's sparse fine field (filters/fine_band.py) holds the dense band field's
values in every brick, leaves out only leaves of one side, and meshes to the dense band field's
mesh, bit for bit: resolved and aliased shapes, poles the fine grid alone samples, shapes cut
by the box (capped and not), odd and even grids, stretched boxes, bands of 0 to 2 cells."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.filters import fine_band as fb
from surfgen.filters.resolution import fine_field, measure_resolution
from surfgen.generator.errors import EmptySurface, SpecError
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.sparse import INSIDE, OUTSIDE, SAMPLED
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import extract_mesh
from surfgen.generator.mesh.sparse_marching import extract_sparse

CASES = [
    ("x^2+y^2+z^2-1", Box.cube(1.5), 24),  # resolved, inside the box
    ("x^2+y^2+z^2-1+0.8*sin(50*x)", Box.cube(1.5), 25),  # stripes finer than a cell
    ("x^2+y^2+z^2-1+0.001/x^2", Box.cube(1.5), 16),  # a pole plane only the fine grid samples
    ("sin(x)*cos(y)+sin(y)*cos(z)+sin(z)*cos(x)", Box.cube(6.3), 21),  # cut by the box
    ("x^2/4+y^2+z^2/0.25-1+0.1*tan(3*y)", Box((-2.5, -1.2, -0.6), (2.1, 1.3, 0.7)), 30),
    ("x^2+y^2+z^2-4", Box.cube(1.0), 17),  # every sample inside: no surface at either grid
]


def _coarse(formula: str, box: Box, n: int):
    tree = parse(formula)
    return tree, evaluate(tree, Grid(box, (n, n + 1, n - 1)), threads=1)


@pytest.mark.parametrize(("formula", "box", "n"), CASES)
@pytest.mark.parametrize("cap", [True, False])
@pytest.mark.parametrize("band", [0, 1, 2])
def test_the_sparse_fine_field_is_the_dense_band_field(formula, box, n, cap, band) -> None:
    tree, coarse = _coarse(formula, box, n)
    dense, evaluated, singular = fine_field(tree, coarse, 0.0, method="band", band=band)
    sf, evaluated_sparse, singular_sparse = fb.fine_band(
        tree, coarse, fb.band_cells(coarse, 0.0, band), 0.0, faces=cap
    )
    assert (evaluated_sparse, singular_sparse) == (evaluated, singular)
    assert sf.grid == dense.grid
    values = dense.values
    for b, (c, e) in enumerate(zip(sf.corner, sf.extent, strict=True)):
        want = values[c[0] : c[0] + e[0], c[1] : c[1] + e[1], c[2] : c[2] + e[2]]
        np.testing.assert_array_equal(sf.values[b, : e[0], : e[1], : e[2]], want)
    # the leaves left out are all of one side, as their state says
    inside = np.isfinite(values) & (values < 0.0)
    block = sf.block
    for leaf in np.argwhere(sf.state != SAMPLED):
        box_of = tuple(slice(x * block, x * block + block + 1) for x in leaf)
        want = INSIDE if inside[box_of].all() else OUTSIDE
        assert not (want == OUTSIDE and inside[box_of].any()), leaf
        assert sf.state[tuple(leaf)] == want, leaf
    # the leaves kept hold both sides (or, capped, are inside leaves on the box's faces)
    top = np.array(sf.state.shape) - 1
    for leaf in np.argwhere(sf.state == SAMPLED):
        flags = inside[tuple(slice(x * block, x * block + block + 1) for x in leaf)]
        on_face = bool(np.any((leaf == 0) | (leaf == top)))
        assert flags.any() and (not flags.all() or (cap and on_face)), leaf
    if cap:  # a capped mesh needs the inside leaves on the box's faces sampled
        for axis in range(3):
            for end in (0, sf.state.shape[axis] - 1):
                assert not (sf.state.take(end, axis) == INSIDE).any()
    try:
        want_mesh = extract_mesh(dense, 0.0, cap=cap)
    except EmptySurface:
        with pytest.raises(EmptySurface):
            extract_sparse(sf, cap)
        return
    got = extract_sparse(sf, cap)
    assert got.vertices.tobytes() == want_mesh.vertices.tobytes()
    assert got.faces.tobytes() == want_mesh.faces.tobytes()


def test_only_the_band_is_built() -> None:
    # a ball in a bigger box: the leaves outside it and those deep inside are not built
    tree, coarse = _coarse("x^2+y^2+z^2-1.44", Box.cube(2.0), 64)
    sf, _, _ = fb.fine_band(tree, coarse, fb.band_cells(coarse, 0.0, 1), 0.0)
    assert 0 < sf.n_bricks < 0.25 * sf.state.size  # the dense path filled all 4096
    assert (sf.state == INSIDE).any() and (sf.state == OUTSIDE).any()


def test_the_check_measures_the_same_either_way() -> None:
    tree, coarse = _coarse("x^2+y^2+z^2-1+0.8*sin(50*x)", Box.cube(1.5), 25)
    mesh = extract_mesh(coarse, 0.0, cap=True)
    sparse = measure_resolution(tree, coarse, mesh, 0.0, cap=True)
    dense_band = fine_field(tree, coarse, 0.0, method="band")
    reference = measure_resolution(tree, coarse, mesh, 0.0, cap=True, method="dense")
    assert sparse.fine_points == dense_band[1] and sparse.fine_points < reference.fine_points
    assert sparse.shift > 1.0  # aliased, both ways
    assert reference.shift > 1.0


def test_bad_bands_and_methods_are_refused() -> None:
    tree, coarse = _coarse("x^2+y^2+z^2-1", Box.cube(1.5), 12)
    mesh = extract_mesh(coarse, 0.0, cap=True)
    with pytest.raises(SpecError, match="band must be >= 0"):
        measure_resolution(tree, coarse, mesh, 0.0, cap=True, band=-1)
    with pytest.raises(SpecError, match="allowed: band, dense"):
        measure_resolution(tree, coarse, mesh, 0.0, cap=True, method="sparse")
