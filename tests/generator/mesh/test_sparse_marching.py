"""The sparse path's mesh is the dense path's, bit for bit.

Every test meshes one field twice: densely (:func:`extract_with_edges`,
:func:`extract_labelled`) and from a :class:`SparseField` sampled where the surface may pass
(:func:`extract_sparse_with_edges`, :func:`extract_sparse_labelled`), and compares the vertices,
faces, edges (and face kinds, wall reports) array for array: same values, same order.

The blocks are bounded by stand-ins for the interval arithmetic, so the tests do not depend on
how tight it is: ``tight`` gives each box the exact range of the grid samples inside it (the
most skipping any bound allows: skipped blocks reach right up to the surface), ``loose`` widens
it, ``none`` decides nothing (every block sampled); ``tests/generator/eval/test_sparse.py``
runs the real bounds.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from surfgen.generator.errors import EmptySurface
from surfgen.generator.eval.brick_lookup import locate
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Field, Grid
from surfgen.generator.eval.sparse import evaluate_sparse
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh import lewiner_chunks, placement, sparse_marching
from surfgen.generator.mesh.mesh import extract_with_edges
from surfgen.generator.mesh.realise import realise
from surfgen.generator.mesh.sparse_marching import (
    _edge_lines,
    extract_sparse_labelled,
    extract_sparse_with_edges,
    sparse_edge_lines,
)
from surfgen.generator.mesh.walls import extract_labelled
from surfgen.generator.model.families import family_names
from surfgen.generator.model.presets import PRESETS
from surfgen.generator.model.sampler import SamplerConfig, choose_d, draw_equation
from surfgen.generator.model.spec import SurfaceSpec

DATA = Path(__file__).resolve().parents[2] / "support" / "data" / "eq13_formulas.jsonl"


def sample_bounds(field: Field, widen: float = 0.0):
    """Bounds of F over a box from the dense field's samples in it (exact at grid points, which
    is all the meshing reads), widened by ``widen`` times the range."""
    axes = field.grid.axes()
    values = field.values

    def bounds(_program, lo, hi):
        k = len(lo)
        flo, fhi, finite = np.empty(k), np.empty(k), np.empty(k, dtype=bool)
        for b in range(k):
            sl = tuple(
                slice(np.searchsorted(axes[a], lo[b, a]), np.searchsorted(axes[a], hi[b, a]) + 1)
                for a in range(3)
            )
            v = values[sl]
            finite[b] = bool(np.isfinite(v).all())
            known = v[~np.isnan(v)]
            if known.size == 0:
                flo[b], fhi[b] = np.inf, -np.inf
                continue
            a, c = float(known.min()), float(known.max())
            span = (c - a) if np.isfinite(c - a) else 0.0
            flo[b], fhi[b] = a - widen * span, c + widen * span
        return flo, fhi, finite

    return bounds


def no_bounds(_program, lo, _hi):
    k = len(lo)
    return np.full(k, -np.inf), np.full(k, np.inf), np.zeros(k, dtype=bool)


def both_paths(tree, grid, params, level, cap, bounds="tight", block=8, threads=1):
    field = evaluate(tree, grid, params)
    dense = extract_with_edges(field, level, cap)
    chosen = {"tight": sample_bounds(field), "loose": sample_bounds(field, 0.5)}
    sf = evaluate_sparse(
        tree, grid, params, level=level, faces=cap, block=block,
        bounds=chosen.get(bounds, no_bounds),
    )  # fmt: skip
    return dense, extract_sparse_with_edges(sf, cap, threads), sf


def assert_same(dense, sparse):
    (dm, de), (sm, se) = dense, sparse
    assert dm.vertices.dtype == sm.vertices.dtype == np.float64
    assert dm.vertices.tobytes() == sm.vertices.tobytes()
    assert dm.faces.tobytes() == sm.faces.tobytes()
    assert de.tobytes() == se.tobytes()


@pytest.mark.parametrize("name", sorted(PRESETS))
@pytest.mark.parametrize("cap", [False, True])
def test_presets(name, cap):
    spec = PRESETS[name].spec()
    grid = Grid(spec.to_grid().box, (40, 37, 34))
    dense, sparse, sf = both_paths(spec.tree(), grid, spec.params, spec.level, cap)
    assert_same(dense, sparse)


def stored_formulas():
    with open(DATA) as f:
        return [json.loads(line) for line in f]


@pytest.mark.parametrize("row", range(50))
def test_stored_eq13_formulas(row):
    r = stored_formulas()[row]
    grid = Grid(Box(tuple(r["lo"]), tuple(r["hi"])), (26, 25, 24) if row % 2 else (23, 24, 25))
    try:
        dense, sparse, _sf = both_paths(parse(r["formula"]), grid, {}, 0.0, bool(row % 3 == 0))
    except EmptySurface:
        with pytest.raises(EmptySurface):
            field = evaluate(parse(r["formula"]), grid)
            extract_with_edges(field, 0.0, bool(row % 3 == 0))
        return
    assert_same(dense, sparse)


def family_shapes():
    out = []
    for name in family_names():
        cfg = SamplerConfig(family=name)
        found = 0
        for index in range(30):
            draw = draw_equation(11, index, cfg)
            d = choose_d(draw, cfg, threads=1)
            if d is None:
                continue
            out.append((f"{name}-{index}", draw.equation.with_d(d).to_tree(), draw.box))
            found += 1
            if found == 2:
                break
    return out


FAMILY_SHAPES = family_shapes()


@pytest.mark.parametrize("case", range(len(FAMILY_SHAPES)), ids=[s[0] for s in FAMILY_SHAPES])
@pytest.mark.parametrize("bounds", ["tight", "loose"])
def test_family_draws(case, bounds):
    _name, tree, box = FAMILY_SHAPES[case]
    n = 48 if case % 2 else 45
    for cap in (False, True):
        dense, sparse, sf = both_paths(tree, Grid(box, (n, n, n)), {}, 0.0, cap, bounds)
        assert_same(dense, sparse)


def test_families_are_all_drawn():
    assert {s[0].split("-")[0] for s in FAMILY_SHAPES} == set(family_names())


@pytest.mark.parametrize(
    "formula, bounds_",
    [
        ("x^2+y^2+z^2-1", (-1.3, 0.7, -2.0, 1.1, -0.4, 1.9)),  # asymmetric box, cut by it
        ("sqrt(1-x^2-y^2-z^2)-0.3", (-1.1, 1.2, -1.0, 1.0, -1.3, 0.9)),  # NaN outside a ball
        ("1/x+y+0.5*z", (-1.0, 1.1, -1.2, 1.0, -1.0, 1.0)),  # a pole: +-inf and walls
        ("log(x)+y^2+z-0.5", (-0.5, 2.0, -1.5, 1.5, -1.0, 1.0)),  # NaN half, -inf at x=0
        ("tan(3*x)+0.3*y-z", (-1.0, 1.0, -1.0, 1.0, -1.0, 1.0)),  # poles, huge values
        ("atan(tan(2*x))+0.5-0.3*y*z", (-2.0, 2.0, -2.0, 2.0, -2.0, 2.0)),  # jumps
        ("0*x+y-0.25", (-1.0, 1.0, -1.0, 1.0, -1.0, 1.0)),  # samples exactly on the level
    ],
)
@pytest.mark.parametrize("shape", [(33, 32, 31), (40, 40, 40)])
@pytest.mark.parametrize("bounds", ["tight", "loose", "none"])
def test_special_fields(formula, bounds_, shape, bounds):
    grid = Grid(Box.from_bounds(bounds_), shape)
    for cap in (False, True):
        dense, sparse, _sf = both_paths(parse(formula), grid, {}, 0.0, cap, bounds)
        assert_same(dense, sparse)


@pytest.mark.parametrize(
    "formula, bounds_",
    [
        ("x^2+y^2+z^2-1", (-1.3, 0.7, -2.0, 1.1, -0.4, 1.9)),  # cut by the box: the pad
        ("sqrt(1-x^2-y^2-z^2)-0.3", (-1.1, 1.2, -1.0, 1.0, -1.3, 0.9)),  # non-finite: mirrors
        ("tan(3*x)+0.3*y-z", (-1.0, 1.0, -1.0, 1.0, -1.0, 1.0)),  # poles
        ("0*x+y-0.25", (-1.0, 1.0, -1.0, 1.0, -1.0, 1.0)),  # on the level: raises
        ("sin(3*x)*cos(2*y)+sin(2*z)-0.2", (-1.3, 0.7, -2.0, 1.1, -0.4, 1.9)),
    ],
)
@pytest.mark.parametrize("threads", [2, 3])
def test_threads_give_the_same_mesh(monkeypatch, formula, bounds_, threads):
    # runs of a brick or more for the offsets, the scan and the cells, of a plane or more for
    # the marching (lewiner_chunks), of a vertex or more for the placement: the one-thread
    # mesh, bit for bit
    from surfgen.generator.mesh import lewiner_chunks, placement, sparse_bricks

    monkeypatch.setattr(sparse_bricks, "RUN_BRICKS", 1)
    monkeypatch.setattr(lewiner_chunks, "CHUNK_CELLS", 1)
    monkeypatch.setattr(placement, "PLACE_RUN", 1)
    grid = Grid(Box.from_bounds(bounds_), (31, 30, 29))
    for cap in (False, True):
        dense, sparse, _sf = both_paths(
            parse(formula), grid, {}, 0.0, cap, block=4, threads=threads
        )
        assert_same(dense, sparse)


def test_cap_copies_on_a_box_edge_merge_as_the_dense_ones():
    # a box edge along x inside the surface: the cap's vertices moved onto its samples from
    # two faces group (same_targets' moved vertices), made in runs of planes on two threads
    grid = Grid(Box.from_bounds((-3.0, 3.0, -1.0, 1.0, -0.5, 0.5)), (30, 31, 29))
    dense, sparse, _sf = both_paths(
        parse("y^2+z^2+0.1*x-1.3"), grid, {}, 0.0, True, block=4, threads=2
    )
    assert_same(dense, sparse)
    vertices = dense[0].vertices
    assert len(np.unique(vertices, axis=0)) == len(vertices)  # one vertex a point: merged


def test_steps_on_recycled_memory_give_the_same_mesh(monkeypatch):
    # under the one-shot policy, with the samples released, each step's arrays take the
    # memory of the step before's where they fit (allocator.recycled_many): the cells'
    # corners the bricks' (once the scan counts them), the runs the offsets', the joined
    # vertices the cells', the placement's edges the runs'; bit for bit the dense mesh, each
    # step on recycled memory
    from surfgen.generator import allocator

    monkeypatch.setattr(allocator, "_giving_back", True)
    monkeypatch.setattr(lewiner_chunks, "CHUNK_CELLS", 1)
    taken: list[tuple[str, bool]] = []  # holding the arrays would stop the next step's

    def spy(module, name):
        real = getattr(allocator, name)

        def recorded(held, *args):
            made = real(held, *args)
            arrays = made if isinstance(made, list) else [made]
            taken.append(
                (module.__name__.rsplit(".", 1)[1], any(a.base is not None for a in arrays))
            )
            return made

        monkeypatch.setattr(module, name, recorded)

    tree = parse("sin(3*x)*cos(2*y)+sin(2*z)-0.2")
    grid = Grid(Box.from_bounds((-1.3, 0.7, -2.0, 1.1, -0.4, 1.9)), (31, 30, 29))
    dense = extract_with_edges(evaluate(tree, grid, {}), 0.0, True)  # (fresh arrays)
    for module, name in [(sparse_marching, "recycled"), (lewiner_chunks, "recycled_many"),
                         (placement, "recycled_many")]:  # fmt: skip
        spy(module, name)
    sf = evaluate_sparse(tree, grid, {}, level=0.0, faces=True, block=4)
    assert_same(dense, extract_sparse_with_edges(sf, True, threads=2, release=True))
    # the cells' corners on the samples once counted, the runs, the join, the placement
    assert taken == [("sparse_marching", True), ("lewiner_chunks", True),
                     ("lewiner_chunks", True), ("placement", True)]  # fmt: skip


def test_the_cells_refuse_corners_of_another_size(monkeypatch):
    # the listing's kernel writes the corners unchecked: an array of another size is refused
    monkeypatch.setattr(sparse_marching, "recycled", lambda held, shape, dtype: np.empty(
        (shape[0] - 1, 8), dtype=dtype))  # fmt: skip
    tree = parse("x^2+y^2+z^2-1")
    sf = evaluate_sparse(tree, Grid(Box.cube(1.5), (20,) * 3), {}, level=0.0, block=4)
    with pytest.raises(ValueError, match=r"corners: expected float32 \(\d+, 8\)"):
        extract_sparse_with_edges(sf, False)


@pytest.mark.parametrize("block", [1, 3, 4, 16])
def test_block_sizes(block):
    grid = Grid(Box.from_bounds((-1.3, 0.7, -2.0, 1.1, -0.4, 1.9)), (30, 29, 31))
    for cap in (False, True):
        dense, sparse, _sf = both_paths(
            parse("sin(3*x)*cos(2*y)+sin(2*z)-0.2"), grid, {}, 0.0, cap, "tight", block
        )
        assert_same(dense, sparse)


def test_tight_bounds_skip_most_blocks():
    """The comparisons above mesh from partly sampled fields: the tight stand-in skips most of
    a sphere's blocks at 64^3 (and the meshes still agree)."""
    grid = Grid(Box.cube(1.5), (64, 64, 64))
    dense, sparse, sf = both_paths(parse("x^2+y^2+z^2-1"), grid, {}, 0.0, True)
    assert_same(dense, sparse)
    assert sf.share < 0.6
    assert sf.stats["boxes"] > 0


@pytest.mark.parametrize("walls", ["keep", "mark", "remove"])
@pytest.mark.parametrize(
    "formula", ["tan(3*x)+0.3*y-z", "atan(tan(2*x))+0.5-0.3*y*z", "1/x+y+0.5*z"]
)
@pytest.mark.parametrize("cap", [False, True])
def test_walls(walls, formula, cap):
    tree = parse(formula)
    grid = Grid(Box.from_bounds((-1.1, 1.0, -1.0, 1.2, -0.9, 1.0)), (34, 33, 35))
    field = evaluate(tree, grid)
    try:
        dm, dr = extract_labelled(field, tree, {}, 0.0, cap, walls)
    except EmptySurface:
        dm = None
    sf = evaluate_sparse(tree, grid, level=0.0, faces=cap, bounds=sample_bounds(field))
    if dm is None:
        with pytest.raises(EmptySurface):
            extract_sparse_labelled(sf, tree, {}, cap, walls)
        return
    sm, sr = extract_sparse_labelled(sf, tree, {}, cap, walls)
    assert dm.vertices.tobytes() == sm.vertices.tobytes()
    assert dm.faces.tobytes() == sm.faces.tobytes()
    assert (dm.face_kinds is None) == (sm.face_kinds is None)
    if dm.face_kinds is not None:
        assert dm.face_kinds.tobytes() == sm.face_kinds.tobytes()
    assert dr == sr


def test_walls_read_samples_no_brick_holds():
    """A crossing on a leaf's face looks along its grid line into a skipped leaf: those
    samples are evaluated (``sparse_edge_lines``) and the classification agrees."""
    tree = parse("tan(3*x)+0.3*y-z")
    grid = Grid(Box.cube(1.0), (41, 41, 41))
    field = evaluate(tree, grid)
    sf = evaluate_sparse(tree, grid, bounds=sample_bounds(field), block=4)
    dm, dr = extract_labelled(field, tree, {}, 0.0, False, "mark")
    sm, sr = extract_sparse_labelled(sf, tree, {}, False, "mark")
    assert dr == sr and dr.poles > 0
    assert dm.face_kinds.tobytes() == sm.face_kinds.tobytes()


@pytest.mark.parametrize("where", ["inside", "outside"])
def test_empty_surfaces(where):
    tree = parse("x^2+y^2+z^2+1" if where == "outside" else "x^2+y^2+z^2-100")
    grid = Grid(Box.cube(1.0), (20, 20, 20))
    field = evaluate(tree, grid)
    sf = evaluate_sparse(tree, grid, bounds=sample_bounds(field))
    with pytest.raises(EmptySurface, match=f"are {where}"):
        extract_sparse_with_edges(sf)


@pytest.mark.parametrize("walls", [None, "keep", "mark", "remove"])
def test_realise_sparse_is_realise_dense(walls):
    spec = SurfaceSpec("tan(2*x)*0.1+sin(3*x)*cos(2*y)+sin(2*z)-0.2", (-1.5, 1.5) * 3, (36,) * 3)
    a = realise(spec, evaluator="fast", cap=True, walls=walls)
    b = realise(spec, field=evaluate_sparse(
        spec.tree(), spec.to_grid(), faces=True, bounds=no_bounds), cap=True, walls=walls)  # fmt: skip
    assert b.sparse and not a.sparse
    assert a.mesh.vertices.tobytes() == b.mesh.vertices.tobytes()
    assert a.mesh.faces.tobytes() == b.mesh.faces.tobytes()
    assert a.walls == b.walls


@pytest.mark.parametrize("threads", [1, 3])
def test_edge_lines_are_the_dense_fields_samples(monkeypatch, threads):
    """``sparse_edge_lines`` reads each edge's line (the sample before, its two, the one after;
    the edge's own at the grid's ends) as the dense field holds it, samples no brick holds
    included (evaluated: here some rows have them), on one thread or in runs of rows on
    several."""
    monkeypatch.setattr(sparse_marching, "_LINE_ROWS", 50)
    tree = parse("tan(3*x)+0.3*y-z")
    grid = Grid(Box.cube(1.0), (41, 41, 41))
    field = evaluate(tree, grid)
    sf = evaluate_sparse(tree, grid, bounds=sample_bounds(field), block=4)
    _, edges = extract_sparse_with_edges(sf)
    lines = sparse_edge_lines(sf, edges, tree, {}, threads)
    shape = np.asarray(grid.shape, dtype=np.int64)
    slot, corner, values, block = sf.lookup()
    line, short = np.zeros((4, len(edges))), np.zeros(len(edges), dtype=np.uint8)
    edges = np.ascontiguousarray(edges)
    _edge_lines(edges, shape, slot, corner, sf.extent, values, block, line, short, 0, len(edges))
    assert short.any()
    for v in np.flatnonzero(edges[:, 0] >= 0):  # bit q: sample q of the row is in no brick
        for q in range(4):
            at = sparse_marching._line_position(edges, v, q, shape)
            assert bool(short[v] >> q & 1) == (locate(slot, block, *at)[0] < 0)
    want = np.zeros_like(lines)
    for v, (axis, *at) in enumerate(edges.tolist()):
        if axis < 0 or at[axis] + 1 >= shape[axis]:
            continue
        pos, length = at[axis], shape[axis]
        for q, step in enumerate((-1 if pos else 0, 0, 1, 2 if pos + 2 < length else 1)):
            ijk = list(at)
            ijk[axis] += step
            want[q, v] = field.values[tuple(ijk)]
    on_edge = edges[:, 0] >= 0
    np.testing.assert_array_equal(lines[:, on_edge], want[:, on_edge])


@pytest.mark.parametrize("walls", [None, "keep"])
def test_released_samples_give_the_same_mesh_and_refuse_reads(walls):
    """``realise(..., keep_samples=False)`` frees a sparse field's samples once the meshing
    has read them: the same mesh and walls, the same counts, and reading samples raises."""
    spec = SurfaceSpec("tan(2*x)*0.1+sin(3*x)*cos(2*y)+sin(2*z)-0.2", (-1.5, 1.5) * 3, (36,) * 3)
    kept = realise(spec, evaluator="sparse", cap=True, walls=walls)
    freed = realise(spec, evaluator="sparse", cap=True, walls=walls, keep_samples=False)
    assert not kept.field.released and freed.field.released
    assert kept.mesh.vertices.tobytes() == freed.mesh.vertices.tobytes()
    assert kept.mesh.faces.tobytes() == freed.mesh.faces.tobytes()
    assert kept.walls == freed.walls
    assert freed.field.nonfinite == kept.field.nonfinite
    assert freed.field.points_evaluated == kept.field.points_evaluated
    assert freed.field.nbytes < kept.field.nbytes
    for read in (freed.field.sign_proxy, freed.field.any_inside, freed.field.lookup):
        with pytest.raises(RuntimeError, match="released after meshing"):
            read()
