"""Tests for surfgen.filters.descriptor: invariances, near duplicates by construction, storage."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from surfgen.filters.descriptor import (
    CHANNEL_SCALES,
    D1_BINS,
    D2_BINS,
    DEFAULT_THRESHOLD,
    FORM_SIZE,
    NORMAL_BINS,
    PLACE_SIZE,
    RELIEF_BINS,
    SIZE,
    DescriptorSet,
    channel_distances,
    descriptor,
    descriptor_distance,
    descriptor_distances,
    descriptor_from_text,
    descriptor_to_text,
    is_near_duplicate,
    nearest_distances,
)
from surfgen.generator.errors import MeshError
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import Mesh, extract_mesh


def _mesh(formula: str, half: float, n: int) -> Mesh:
    field = evaluate_reference(parse(formula), Grid(Box.cube(half), (n,) * 3))
    return extract_mesh(field, 0.0)


def _shifted(formula: str, dx: float, dy: float, dz: float) -> str:
    """The same surface moved by (dx, dy, dz) inside its box."""
    return (
        formula.replace("x", "(x-X)")
        .replace("y", "(y-Y)")
        .replace("z", "(z-Z)")
        .replace("X", repr(dx))
        .replace("Y", repr(dy))
        .replace("Z", repr(dz))
    )


def test_descriptor_channels(sphere_mesh: Mesh) -> None:
    d = descriptor(sphere_mesh)
    assert d.shape == (SIZE,) and d.dtype == np.float64
    assert SIZE == FORM_SIZE + PLACE_SIZE + RELIEF_BINS
    # form: five normalised histograms
    edges = np.cumsum([0, D2_BINS, D1_BINS, NORMAL_BINS, NORMAL_BINS, NORMAL_BINS])
    for lo, hi in itertools.pairwise(edges):
        assert d[lo:hi].sum() == pytest.approx(1.0)
        assert (d[lo:hi] >= 0).all()
    # placement: distances to a unit sphere (RMS radius 1) from a lattice, clipped at 0.8
    place = d[FORM_SIZE : FORM_SIZE + PLACE_SIZE].reshape((12,) * 3)
    axis = np.linspace(-1.8, 1.8, 12)
    r = np.sqrt(axis[:, None, None] ** 2 + axis[None, :, None] ** 2 + axis[None, None, :] ** 2)
    assert np.allclose(place, np.minimum(np.abs(r - 1), 0.8), atol=0.08)
    # relief: a histogram; a smooth sphere turns its normal little among neighbours
    relief = d[FORM_SIZE + PLACE_SIZE :]
    assert relief.sum() == pytest.approx(1.0) and relief[:4].sum() > 0.9


def test_carving_and_where_it_is_are_seen() -> None:
    """The same envelope smooth, carved (about 0.2 of its radius deep), or carved elsewhere: three
    different shapes; each is
    a near duplicate of itself on another grid."""
    smooth = "x^2+y^2+z^2-1"
    carved = "x^2+y^2+z^2-1+0.4*sin(4*x)*sin(4*y)"
    elsewhere = "x^2+y^2+z^2-1+0.4*sin(4*y)*sin(4*z)"
    descs = {f: descriptor(_mesh(f, 1.4, 48)) for f in (smooth, carved, elsewhere)}
    for a, b in itertools.combinations(descs, 2):
        assert not is_near_duplicate(descs[a], descs[b]), (a, b)
    for f, d in descs.items():
        assert is_near_duplicate(d, descriptor(_mesh(f, 1.4, 40))), f


def test_descriptor_is_deterministic(torus_mesh: Mesh) -> None:
    a = descriptor(torus_mesh)
    b = descriptor(Mesh(torus_mesh.vertices.copy(), torus_mesh.faces.copy()))
    assert np.array_equal(a, b)


def test_invariant_to_translation_and_scale(genus2_mesh: Mesh) -> None:
    d = descriptor(genus2_mesh)
    moved = Mesh(genus2_mesh.vertices + np.array([3.0, -1.5, 10.0]), genus2_mesh.faces)
    scaled = Mesh(genus2_mesh.vertices * 7.5, genus2_mesh.faces)
    assert descriptor_distance(d, descriptor(moved)) < 1e-3
    assert descriptor_distance(d, descriptor(scaled)) < 1e-3
    assert descriptor_distance(d, d) == 0.0


@pytest.mark.parametrize("name", ["sphere", "torus", "genus2", "two_spheres"])
def test_duplicates_by_construction(name: str, shapes, shape_mesh) -> None:
    """The same shape moved inside its box, or on a finer or coarser grid, is a near duplicate."""
    s = shapes[name]
    base = descriptor(shape_mesh(name))
    moved = descriptor(_mesh(_shifted(s.formula, 0.07, -0.05, 0.04), s.half, s.n))
    finer = descriptor(_mesh(s.formula, s.half, 48))
    coarser = descriptor(_mesh(s.formula, s.half, 28))
    for other in (moved, finer, coarser):
        assert is_near_duplicate(base, other), descriptor_distance(base, other)


def test_distinct_shapes_are_not_duplicates(shape_mesh) -> None:
    names = ["sphere", "torus", "genus2", "two_spheres"]
    descs = {n: descriptor(shape_mesh(n)) for n in names}
    # An ellipsoid and a rounded cube: close to the sphere in D2 alone.
    descs["ellipsoid"] = descriptor(_mesh("x^2/1.2+y^2+z^2/0.7-1", 1.5, 40))
    descs["rounded_cube"] = descriptor(_mesh("x^8+y^8+z^8-1", 1.5, 40))
    for a, b in itertools.combinations(descs, 2):
        dist = descriptor_distance(descs[a], descs[b])
        assert dist > 1.5 * DEFAULT_THRESHOLD, (a, b, dist)
        assert not is_near_duplicate(descs[a], descs[b])


def test_distances_vectorised_match_pairwise(sphere_mesh, torus_mesh, genus2_mesh) -> None:
    a, b, c = (descriptor(m) for m in (sphere_mesh, torus_mesh, genus2_mesh))
    many = descriptor_distances(a, np.stack([a, b, c]))
    assert many.shape == (3,)
    assert many[0] == 0.0
    assert many[1] == pytest.approx(descriptor_distance(a, b))
    assert descriptor_distance(b, c) == pytest.approx(descriptor_distance(c, b))
    assert (many[1:] > 0).all()
    # the distance is the largest channel distance over its scale
    channels = channel_distances(a, np.stack([b, c]))
    want = np.max([channels[k] / CHANNEL_SCALES[k] for k in CHANNEL_SCALES], axis=0)
    assert np.array_equal(many[1:], want)


def test_bad_inputs() -> None:
    flat = Mesh(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], float), np.array([[0, 1, 2]]))
    with pytest.raises(MeshError, match="area"):
        descriptor(flat)
    with pytest.raises(MeshError):
        descriptor(Mesh(np.zeros((0, 3)), np.zeros((0, 3), int)))
    with pytest.raises(ValueError, match="values"):
        descriptor_distance(np.zeros(SIZE), np.zeros(SIZE - 1))


def test_text_round_trip(torus_mesh: Mesh) -> None:
    d = descriptor(torus_mesh)
    back = descriptor_from_text(descriptor_to_text(d))
    assert back is not None and np.allclose(back, d, atol=1e-6)
    assert descriptor_distance(d, back) < 1e-3  # a thousandth of the threshold
    assert descriptor_from_text(None) is None
    assert descriptor_from_text("not json") is None
    assert descriptor_from_text('{"v": 999, "d": []}') is None  # another version: recompute
    assert descriptor_from_text('{"v": 1, "d": [1, 2]}') is None  # version 1: recompute
    assert descriptor_from_text('{"v": 2, "d": [1, 2], "p": ""}') is None  # wrong size
    assert descriptor_from_text('{"v": 2, "d": [], "p": "%%%"}') is None  # not base64
    assert np.array_equal(
        back[FORM_SIZE : FORM_SIZE + PLACE_SIZE], d[FORM_SIZE : FORM_SIZE + PLACE_SIZE]
    )
    assert len(descriptor_to_text(d)) < 6000


def test_nearest_distances_are_the_one_by_one_distances_bit_for_bit() -> None:
    rng = np.random.default_rng(3)
    rows = rng.random((40, SIZE))
    rows[7] = rows[3]  # an exact duplicate: 0 both ways
    expected = []
    for i in range(len(rows)):
        dist = descriptor_distances(rows[i], rows)
        dist[i] = np.inf
        expected.append(dist.min())
    got = nearest_distances(rows)
    assert np.array_equal(got, np.array(expected)) and got[3] == got[7] == 0.0
    assert nearest_distances(rows[:1]).tolist() == [np.inf]
    with pytest.raises(ValueError, match=f"{SIZE} values"):
        nearest_distances(rows[:, :-1])


def _set(rows: np.ndarray) -> DescriptorSet:
    known = DescriptorSet()
    for i, row in enumerate(rows):
        known.add(f"k{i}", row)
    return known


def test_within_is_nearest_below_the_threshold_bit_for_bit() -> None:
    rng = np.random.default_rng(11)
    base = rng.random((30, SIZE))
    # neighbours of the first rows at every scale, so that some fall on each side of a threshold
    near = base[:10] + rng.normal(size=(10, SIZE)) * np.geomspace(1e-4, 3e-2, 10)[:, None]
    rows = np.concatenate([base, near, base[4:5]])  # and an exact repeat of row 4
    known = _set(rows[:-12])
    seen = set()
    for query in rows[-12:]:
        for threshold in (0.3, DEFAULT_THRESHOLD, 4.0, np.inf):
            key, dist = known.nearest(query)
            expected = (key, dist) if dist < threshold else (None, np.inf)
            got = known.within(query, threshold)
            assert got == expected  # the same key and the same float
            seen.add(got[0] is None)
    assert seen == {True, False}
    # a tie: the first of two equal rows, as nearest has it
    assert _set(rows[[4, 4, 40]]).within(rows[40], np.inf)[0] == "k0"
    assert DescriptorSet().within(rows[0], np.inf) == (None, np.inf)


def test_within_measures_a_row_whose_bound_equals_its_distance() -> None:
    """A row shifted by the same amount in every bin has every channel's bound equal to its
    distance (``|sum a - sum b|`` is ``sum |a - b|``): a bound any tighter than the rule drops
    it, a bound that is not a bound (too large) too."""
    rng = np.random.default_rng(5)
    row = rng.random(SIZE)
    shifted = row.copy()
    shifted[FORM_SIZE + PLACE_SIZE :] += 0.05  # the relief alone moves, 0.05 in every bin
    known = _set(np.stack([rng.random(SIZE), shifted]))
    key, dist = known.nearest(row)
    # the cumulative relief moves by 0.05 k in bin k: a mean of 0.05 (bins + 1) / 2
    expected = 0.05 * (RELIEF_BINS + 1) / 2 / CHANNEL_SCALES["relief"]
    assert key == "k1" and dist == pytest.approx(expected)
    assert known.within(row, dist * (1 + 1e-12)) == (key, dist)
    assert known.within(row, dist) == (None, np.inf)


def test_within_measures_rows_with_nan() -> None:
    """A NaN distance wins nearest's argmin (then no duplicate): within measures the row too."""
    rng = np.random.default_rng(2)
    rows = rng.random((3, SIZE))
    bad = rows[1].copy()
    bad[0] = np.nan
    known = _set(np.stack([rows[0], bad, rows[0]]))
    assert known.nearest(rows[0])[0] == "k1"  # NaN first: no duplicate by nearest's rule
    assert known.within(rows[0], np.inf) == (None, np.inf)
