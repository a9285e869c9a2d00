"""Marching cubes' vertices placed on the box and grouped (generator/mesh/placement.py)."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.generator.eval.grid import Box, Grid
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


@pytest.mark.parametrize("threads, halves", [(1, False), (2, True)])
def test_halves_from_their_own_count_on_threads(threads, halves, monkeypatch):
    # below the plane tables' count, a mesh of HALVES_FROM vertices or more is grouped in two
    # halves on more than one thread, in one table on one: the same targets
    # the box cuts the sphere through its edges: the cap's vertices there group
    sphere = evaluate_reference(parse("x^2+y^2+z^2-1"), Grid(Box.cube(0.6), (20, 21, 22)))
    args = []
    monkeypatch.setattr(
        mesh_module, "same_targets", lambda *a: args.append(a[:5]) or placement.same_targets(*a)
    )
    extract_mesh(sphere, cap=True)
    seen = []
    real = placement._targets_in_halves
    monkeypatch.setattr(
        placement, "_targets_in_halves", lambda *a: seen.append(real(*a)) or seen[-1]
    )
    monkeypatch.setattr(placement, "HALVES_FROM", 100)
    monkeypatch.setattr(placement, "PLANE_TABLES_FROM", 1 << 40)
    verts, shift, edges, moved, shape = args[0]
    assert len(verts) > 100
    got = placement.same_targets(verts, shift, edges, moved, shape, threads)
    assert (len(seen) == 1 and seen[0] is not None) == halves
    whole, merged = placement._targets_kernel(verts, shift, edges, moved, shape)
    assert merged and got is not None and np.array_equal(got, whole)


def test_plane_tables_reused_as_they_are_group_as_one_table():
    # Many planes, each table reused every second plane with the keys of its earlier plane
    # left in it (counted as free slots): the groups are those of one table for the mesh.
    rng = np.random.default_rng(5)
    shape = np.array([60, 9, 8], dtype=np.int64)
    rows = []
    for plane in range(shape[0] - 1):  # the cells of a plane make vertices on it and the next
        n = int(rng.integers(20, 90))
        e1 = plane + rng.integers(0, 2, size=n)
        axis = rng.integers(0, 3, size=n)
        e2, e3 = rng.integers(0, 4, size=n), rng.integers(0, 3, size=n)  # many repeats
        rows.append(np.stack([axis, e1, e2, e3], axis=1))
    edges = np.ascontiguousarray(np.concatenate(rows), dtype=np.int64)
    n = len(edges)
    edges[rng.random(n) < 0.05] = -1  # alone: a cell's centre
    verts = np.zeros((n, 3), dtype=np.float32)
    moved = np.zeros(n, dtype=np.bool_)
    by_plane, merged, ordered = placement._targets_by_plane(verts, 0.0, edges, moved, shape)
    whole, merged_whole = placement._targets_kernel(verts, 0.0, edges, moved, shape)
    assert ordered and merged and merged_whole
    assert np.array_equal(by_plane, whole)
    # in two halves at once, the second's vertices of keys the first has linked to them
    for cut in (n // 2, n // 3):  # through a plane's vertices: groups on both sides
        halves, merged_halves = placement._targets_in_halves(verts, 0.0, edges, moved, shape, cut)
        assert merged_halves and np.array_equal(halves, whole)
        assert (halves[cut:] < cut).any()  # some of the second half's groups began before it
    # the groups themselves: each vertex's target is the first vertex with its edge
    key = {}
    for v in range(n):
        if edges[v, 0] >= 0:
            key.setdefault(tuple(edges[v]), v)
            assert whole[v] == key[tuple(edges[v])]
        else:
            assert whole[v] == v


def _groups_both_ways(field, monkeypatch, permute=None):
    """The vertex groups of ``field``'s capped mesh by the per-plane tables and by the whole
    mesh's table (``permute``: the vertices in another order first)."""
    seen = []
    real = mesh_module.same_targets
    monkeypatch.setattr(placement, "PLANE_TABLES_FROM", 0)  # the tables by plane on any mesh

    def spy(verts, shift, edges, moved, shape, threads=1):
        args = (verts, shift, edges, moved, shape)
        if permute is not None:
            order = permute(len(verts))
            args = (verts[order], shift, edges[order], moved[order], shape)
        seen.append(
            (
                placement._targets_by_plane(*args),
                placement._targets_kernel(*args),
                real(*args),
                placement._targets_in_halves(*args),
            )
        )
        return real(verts, shift, edges, moved, shape, threads)

    monkeypatch.setattr(mesh_module, "same_targets", spy)
    extract_mesh(field, cap=True)
    return seen[0]


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
def test_vertex_groups_by_plane_are_the_whole_meshs(formula, groups, monkeypatch):
    grid = Grid(Box((-1.2, -1.0, -1.1), (1.2, 1.3, 1.1)), (23, 26, 21))
    field = evaluate_reference(parse(formula), grid)
    (by_plane, merged, ordered), (whole, merged_whole), got, halves = _groups_both_ways(
        field, monkeypatch
    )
    assert ordered and merged == merged_whole == groups
    assert np.array_equal(by_plane, whole)
    assert (got is None) == (not merged)
    assert np.array_equal(halves[0], whole) and halves[1] == merged


@pytest.mark.parametrize("kernel", ["_targets_kernel", "_plane_groups", "_link_halves"])
def test_vertex_groups_count_no_references_per_vertex(kernel):
    # the vertex's key and its table's probe are read in the loop itself: helpers given the
    # arrays (inlined by numba) counted references to each of them at every vertex, atomic
    # increments that took a third of the groups' time
    verts = np.zeros((4, 3), dtype=np.float32)
    edges = np.zeros((4, 4), dtype=np.int64)
    moved = np.zeros(4, dtype=np.bool_)
    shape = np.array([3, 3, 3], dtype=np.int64)
    args = (verts, 0.5, edges, moved, shape)
    target, v0, v1 = np.zeros(4, dtype=np.int64), np.int64(0), np.int64(4)
    if kernel == "_plane_groups":
        args = (*args, target, v0, v1)
    elif kernel == "_link_halves":
        tables = np.full((2, 2048), -1, dtype=np.int64)
        args = (*args, target, v0, tables, np.uint64(54), np.int64(1023), np.int64(1))
    body = kernel_ir(getattr(placement, kernel).py_func, *args)
    assert refcounts_in_loops(body) == 0


def test_vertex_groups_out_of_plane_order_fall_back_to_one_table(monkeypatch):
    grid = Grid(Box.cube(1.5), (25, 25, 25))
    field = evaluate_reference(parse("z-0.3"), grid)  # cut by the box: merges

    def backwards(n):
        return np.arange(n)[::-1].copy()

    (_, _, ordered), (whole, merged), got, halves = _groups_both_ways(field, monkeypatch, backwards)
    assert not ordered and merged and halves is None
    assert np.array_equal(got, whole)
