"""Marching cubes' vertices placed on the box and grouped (generator/mesh/placement.py)."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.generator.eval.grid import Box, Field, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh import mesh as mesh_module
from surfgen.generator.mesh import placement
from surfgen.generator.mesh.mesh import extract_mesh
from tests.support.refcounts import kernel_ir, refcounts_in_loops


def _index_vertices(rng: np.random.Generator, n: int, shape: np.ndarray) -> np.ndarray:
    """Float32 vertices as marching cubes gives them with a cap's pad (shift 1): most on a
    grid edge (one fractional coordinate), some on samples of the pad (moved), a few at a
    cell's centre (none near a cell's face)."""
    whole = rng.integers(1, shape + 1, size=(n, 3)).astype(np.float64)
    kind = rng.choice(3, size=n, p=[0.8, 0.15, 0.05])
    axis = rng.integers(0, 3, size=n)
    edge = kind == 0
    whole[edge, axis[edge]] += rng.uniform(0.02, 0.98, size=edge.sum())
    whole[kind == 1, 0] = 0.0  # on the pad
    whole[kind == 2] += 0.5
    return whole.astype(np.float32)


@pytest.mark.parametrize("threads", [2, 3])
def test_vertices_placed_in_runs_are_one_pass(threads, monkeypatch):
    rng = np.random.default_rng(3)
    shape = np.array([17, 12, 9], dtype=np.int64)
    lo, hi = np.array([-1.0, -0.5, -2.0]), np.array([1.0, 0.7, 2.0])
    spacing = (hi - lo) / (shape - 1)
    verts = _index_vertices(rng, 500, shape)
    verts[-1] = (3.5, 4.5, 5.005)  # off its cell's face only in the last run
    want = placement.place_vertices(verts, 1.0, shape, lo, hi, spacing, 1)
    monkeypatch.setattr(placement, "PLACE_RUN", 7)
    got = placement.place_vertices(verts, 1.0, shape, lo, hi, spacing, threads)
    for a, b in zip(want[:3], got[:3], strict=True):
        assert np.array_equal(a, b)
    assert want[3] is True and got[3] is True
    verts[-1] = (3.5, 4.5, 5.5)  # in the middle of its cell: none near a face
    assert not placement.place_vertices(verts, 1.0, shape, lo, hi, spacing, threads)[3]


def _groups_both_ways(field, cap, monkeypatch):
    """The vertex groups of ``field``'s mesh as :func:`placement.same_targets` finds them (the
    moved vertices' table, the centres' edges) and by one table of every vertex, each call's
    ``(got, whole, merged, moved)``."""
    seen = []
    real = mesh_module.same_targets

    def spy(verts, shift, edges, moved, centres, shape):
        whole, merged = placement._targets_kernel(verts, shift, edges, moved, shape)
        got = real(verts, shift, edges, moved, centres, shape)
        seen.append((got, whole, merged, moved))
        return got

    monkeypatch.setattr(mesh_module, "same_targets", spy)
    extract_mesh(field, cap=cap)
    return seen


def _assert_whole_meshs(seen):
    for got, whole, merged, _ in seen:
        assert (got is not None) == merged
        assert got is None or np.array_equal(got, whole)


@pytest.mark.parametrize(
    ("formula", "groups"),
    [
        ("x*y*z", True),  # exact zeros on three grid planes: ambiguous cells
        ("floor(2*x)*floor(2*y)-floor(2*z)", True),
        ("z-0.3", True),  # a plane cut by the box: its crossings on the box's edges
        ("x^2+y^2+z^2-2.5", True),  # a ball cut by the box
        ("x^2+y^2+z^2-1.8", False),  # a ball inside the box: no group
    ],
)
def test_vertex_groups_are_the_whole_meshs(formula, groups, monkeypatch):
    grid = Grid(Box((-1.2, -1.0, -1.1), (1.2, 1.3, 1.1)), (23, 26, 21))
    field = evaluate_reference(parse(formula), grid)
    seen = _groups_both_ways(field, True, monkeypatch)
    _assert_whole_meshs(seen)
    assert seen[0][2] == groups


def _ambiguous_field(rng: np.random.Generator, kind: int) -> Field:
    """A small field full of ambiguous cells: random values, or values at the level, a
    hair from it on either side, NaN and infinities (cells' centres drawn onto a corner)."""
    shape = tuple(int(n) for n in rng.integers(4, 17, size=3))
    if kind == 0:
        values = rng.uniform(-1.0, 1.0, size=shape)
    else:
        values = rng.choice([-1.0, 0.0, 1.0, 1e-30, -1e-30, np.nan, np.inf], size=shape)
    return Field(Grid(Box((-1.0, -1.2, -0.9), (1.0, 1.1, 1.3)), shape), values)


@pytest.mark.parametrize("cap", [False, True])
def test_vertex_groups_on_ambiguous_fields_are_the_whole_meshs(cap, monkeypatch):
    # Only a moved vertex or a cell's centre can share a point with another: on fields full of
    # ambiguous cells, a table of every vertex finds the groups same_targets finds
    rng = np.random.default_rng(11)
    by_centres = 0
    for trial in range(40):
        seen = _groups_both_ways(_ambiguous_field(rng, trial % 2), cap, monkeypatch)
        _assert_whole_meshs(seen)
        got, _, _, moved = seen[0]
        by_centres += got is not None and bool((got != np.arange(len(got)))[~moved].any())
    assert by_centres >= 5  # groups of vertices not moved came: the centres' table is needed


def test_centres_on_edges_group_with_their_edges_vertex():
    # each vertex's target is the first vertex on its edge: a centre before the edge's own
    # vertex, one after it, two centres on one edge, a centre alone on its edge, one on none
    shape = np.array([6, 5, 4], dtype=np.int64)
    edges = np.array(
        [
            (0, 3, 3, 3),  # 0, a centre: before its edge's own vertex (10)
            (0, 1, 1, 1),
            (1, 1, 1, 1),
            (2, 1, 1, 1),  # 3
            (0, 2, 3, 1),  # 4
            (0, 2, 3, 1),  # 5, a centre after its edge's vertex (4)
            (-1, -1, -1, -1),  # 6, a centre on no edge
            (1, 4, 4, 3),  # 7, a centre alone on its edge
            (2, 1, 1, 1),  # 8 and 9: two centres on the edge of 3
            (2, 1, 1, 1),
            (0, 3, 3, 3),  # 10
            (1, 2, 2, 2),
        ],
        dtype=np.int64,
    )
    target = np.arange(len(edges), dtype=np.int64)
    centres = np.array([0, 5, 6, 7, 8, 9], dtype=np.int64)
    on_edge = centres[edges[centres, 0] >= 0]
    assert placement._edge_groups(edges, on_edge, shape, target)
    assert target.tolist() == [0, 1, 2, 3, 4, 4, 6, 7, 3, 3, 0, 11]
    alone = np.arange(len(edges), dtype=np.int64)
    assert not placement._edge_groups(edges, np.array([7], dtype=np.int64), shape, alone)
    assert np.array_equal(alone, np.arange(len(edges)))


@pytest.mark.parametrize("kernel", ["_targets_kernel", "_edge_groups"])
def test_vertex_groups_count_no_references_per_vertex(kernel):
    # the vertex's key and its table's probe are read in the loop itself: helpers given the
    # arrays (inlined by numba) counted references to each of them at every vertex, atomic
    # increments that took a third of the groups' time
    verts = np.zeros((4, 3), dtype=np.float32)
    edges = np.zeros((4, 4), dtype=np.int64)
    moved = np.zeros(4, dtype=np.bool_)
    shape = np.array([3, 3, 3], dtype=np.int64)
    if kernel == "_targets_kernel":
        args = (verts, 0.5, edges, moved, shape)
    else:
        args = (edges, np.array([1], dtype=np.int64), shape, np.zeros(4, dtype=np.int64))
    body = kernel_ir(getattr(placement, kernel).py_func, *args)
    assert refcounts_in_loops(body) == 0
