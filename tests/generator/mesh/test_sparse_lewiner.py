"""The Lewiner port (:mod:`surfgen.generator.mesh.sparse_lewiner`) against scikit-image itself:
the same vertices (float32 bits) and faces, in the same order, on volumes full of ambiguous
cells, tiny and huge offsets, and masks that skip cells and whole planes."""

from __future__ import annotations

import numpy as np
import pytest
from skimage.measure import marching_cubes

from surfgen.generator.mesh import sparse_lewiner as lw
from surfgen.generator.mesh.lewiner_chunks import lewiner_cells
from surfgen.generator.mesh.marching import mixed_cells
from tests.support.mesh_reference import skimage_mask
from tests.support.refcounts import kernel_ir, loop_refcounts


def cells_of(work: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cells ``mask`` lets through (skimage reads a cell's mask at its far corner): their
    flat numbers and corners, as :func:`lewiner_cells` takes them."""
    z, y, x = (a.astype(np.int64) for a in np.nonzero(mask[1:, 1:, 1:]))
    w = work
    corners = np.stack(
        [
            w[z, y, x], w[z, y, x + 1], w[z, y + 1, x + 1], w[z, y + 1, x],
            w[z + 1, y, x], w[z + 1, y, x + 1], w[z + 1, y + 1, x + 1], w[z + 1, y + 1, x],
        ],
        axis=1,
    ).astype(np.float32)  # fmt: skip
    return (z * work.shape[1] + y) * work.shape[2] + x, np.ascontiguousarray(corners)


def run_port(
    work: np.ndarray, mask: np.ndarray, threads: int = 1, min_cells: int = 1
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The port on the cells ``mask`` lets through: it returns what skimage's
    ``marching_cubes`` returns ('descent'), faces int64, and the centre vertices' numbers."""
    keys, corners = cells_of(work, mask)
    return lewiner_cells([keys, corners], work.shape[2], work.shape[1], threads, min_cells)


def volume(kind: int, shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    if kind == 0:  # noise: every case, many ambiguous faces and interiors
        w = rng.standard_normal(shape)
    elif kind == 1:  # few values, tiny and large: vertices pulled onto samples, ties in tests
        w = rng.choice([-1.0, 1.0, -1e-30, 1e-30, 0.5, -2.0, 3e20, -1e-7], size=shape)
    else:  # a smooth field with noise
        a = np.indices(shape).astype(float)
        w = np.sin(0.9 * a[0]) + np.cos(1.3 * a[1]) * np.sin(0.7 * a[2])
        w += 0.1 * rng.standard_normal(shape)
    w = w.astype(np.float32)
    w[w == 0] = 1e-20
    return w


@pytest.mark.parametrize("kind", [0, 1, 2])
def test_mixed_cells_lists_the_cells_skimage_would_visit(kind):
    # the dense path's list of cells for the port: skimage's mask, in its visiting order
    rng = np.random.default_rng(40 + kind)
    for _ in range(6):
        w = volume(kind, tuple(int(n) for n in rng.integers(2, 12, 3)), rng)
        keys, corners = mixed_cells(w)
        want_keys, want_corners = cells_of(w, skimage_mask(w))
        assert keys.dtype == np.int64 and corners.dtype == np.float32
        assert np.array_equal(keys, want_keys) and np.array_equal(corners, want_corners)
    keys, corners = mixed_cells(np.ones((4, 5, 6), dtype=np.float32))
    assert keys.shape == (0,) and corners.shape == (0, 8)


@pytest.mark.parametrize("threads", [1, 2, 5])
@pytest.mark.parametrize("kind", [0, 1, 2])
def test_port_is_skimage_bit_for_bit(kind, threads):
    # threads > 1: runs of whole planes (down to one plane each here) joined into one numbering
    rng = np.random.default_rng(100 + kind)
    checked = found = 0
    for _ in range(12):
        shape = tuple(int(n) for n in rng.integers(2, 12, 3))
        w = volume(kind, shape, rng)
        if not ((w < 0).any() and (w > 0).any()):
            continue
        mask = skimage_mask(w)
        ref_v, ref_f, _n, _v = marching_cubes(w, 0.0, gradient_direction="descent", mask=mask)
        v, f, centres = run_port(w, mask, threads)
        assert v.dtype == ref_v.dtype == np.float32
        assert np.array_equal(v, ref_v)
        assert np.array_equal(f, ref_f)
        # every vertex not listed as a cell's centre lies on a grid edge: two whole coordinates
        whole = (v == np.floor(v)).sum(axis=1)
        assert (whole[np.setdiff1d(np.arange(len(v)), centres)] >= 2).all()
        assert np.array_equal(centres, np.unique(centres))
        assert np.array_equal(centres, run_port(w, mask, 1)[2])  # the runs' join: one pass's
        found += (whole[centres] < 2).sum()
        checked += 1
    assert checked >= 8
    assert found > 0 or kind == 2  # centres off the edges: listed (noise has many)


def test_the_case_tests_are_compiled_once():
    # _big_switch passes an int64 sub-configuration, never a literal 0: numba compiles
    # _test_internal for one signature, not a second one for Literal[int](0).
    import numba
    from numba import types

    from surfgen.generator.jit.options import KERNEL

    # a fresh (uncached) compile of the switch: typing it asks _test_internal for the
    # signatures of its calls, which a copy loaded from numba's cache would not
    v = (0.0,) * 8  # the cell's corner values, as lewiner_range hands them
    case = config = np.int64(1)
    args = (v, case, config)
    numba.njit(**{**KERNEL, "cache": False})(lw._big_switch.py_func).compile(
        tuple(numba.typeof(a) for a in args)
    )
    signatures = lw._test_internal.signatures
    assert signatures
    assert not [s for s in signatures if any(isinstance(t, types.Literal) for t in s)]


@pytest.mark.parametrize("threads", [1, 2, 4, 9])
def test_port_follows_skimage_layers_with_gaps(threads):
    """Masks that skip whole planes and rows: skimage's face layers are cleared as it moves
    on, so the vertices it shares (and the duplicates where it does not) are reproduced; in
    runs of planes, a run after a skipped plane shares nothing with the one before."""
    rng = np.random.default_rng(7)
    w = volume(0, (9, 7, 8), rng)
    mask = skimage_mask(w)
    mask[3] = False
    mask[:, 2] = False
    mask[5, :, ::2] = False
    ref_v, ref_f, _n, _v = marching_cubes(w, 0.0, gradient_direction="descent", mask=mask)
    v, f, _ = run_port(w, mask, threads)
    assert np.array_equal(v, ref_v) and np.array_equal(f, ref_f)


def test_runs_are_whole_planes_of_about_equal_counts():
    from surfgen.generator.mesh.lewiner_chunks import _runs

    plane = 100
    keys = np.sort(np.r_[np.arange(0, 40), np.arange(100, 190), np.arange(300, 310)]).astype(
        np.int64
    )  # 40 cells in plane 0, 90 in plane 1, 10 in plane 3
    assert _runs(keys, plane, 1) == [0, len(keys)]
    assert _runs(keys, plane, 2) == [0, 40, len(keys)]  # the middle cell's plane starts at 40
    assert _runs(keys, plane, 3) == [0, 40, len(keys)]  # plane 1 holds two shares: one run
    assert _runs(keys, plane, 4) == [0, 40, len(keys)]
    assert _runs(keys, plane, 14) == [0, 40, 130, len(keys)]  # a share ends in plane 3
    for n in range(1, 20):
        bounds = _runs(keys, plane, n)
        assert bounds[0] == 0 and bounds[-1] == len(keys) and bounds == sorted(set(bounds))
        assert all(keys[b] // plane != keys[b - 1] // plane for b in bounds[1:-1])


def test_threads_need_enough_cells_for_a_run(monkeypatch):
    # below min_cells per run, one pass (no vertex tracked for a join); the same result
    from surfgen.generator.mesh import lewiner_chunks

    calls = []
    kernel = lewiner_chunks.lewiner_range

    def counted(*args):
        calls.append(args[6])  # track
        return kernel(*args)

    monkeypatch.setattr(lewiner_chunks, "lewiner_range", counted)
    rng = np.random.default_rng(11)
    w = volume(2, (10, 9, 8), rng)
    mask = skimage_mask(w)
    one = run_port(w, mask, threads=1)
    assert calls == [False]
    for min_cells, runs in ((1, 3), (50, 3), (10**9, 1)):
        calls.clear()
        v, f, _ = run_port(w, mask, threads=3, min_cells=min_cells)
        assert np.array_equal(v, one[0]) and np.array_equal(f, one[1])
        # the runs number in int32; the joined (or single) pass hands the mesh's int64
        assert f.dtype == one[1].dtype == np.int64 and v.dtype == np.float32
        assert calls == ([True] * runs if runs > 1 else [False])


@pytest.mark.parametrize("giving_back", [True, False])
def test_the_joined_mesh_takes_the_cells_memory(monkeypatch, giving_back):
    # lewiner_cells takes the cells out of the list it is given; under the one-shot policy
    # the joined vertices are made on the cells' corners (nothing else holds them; the
    # faces do not fit there), otherwise the cells are dropped and the join's arrays are fresh
    import weakref

    from surfgen.generator import allocator

    monkeypatch.setattr(allocator, "_giving_back", giving_back)
    rng = np.random.default_rng(5)
    w = volume(2, (12, 9, 8), rng)
    keys, corners = cells_of(w, skimage_mask(w))
    # a weak reference would stop numpy resizing the cells: watched only when they are freed
    alive = [] if giving_back else [weakref.ref(keys), weakref.ref(corners)]
    cells = [keys, corners]
    del keys, corners
    v, f, _ = lewiner_cells(cells, w.shape[2], w.shape[1], threads=2, min_cells=1)
    assert cells == [] and len(f) > 0
    if giving_back:
        assert v.base.dtype == np.float32 and v.base.size >= 3 * len(v) and f.base is None
    else:
        assert v.base is None and f.base is None
        assert alive[0]() is None and alive[1]() is None


@pytest.mark.parametrize("giving_back", [True, False])
def test_the_runs_share_the_spare_memory_kind_by_kind(monkeypatch, giving_back):
    # a spare block too small for every run's arrays holds every run's faces and vertices
    # (the arrays the runs write most) and no run's layers: the runs fault in about as many
    # fresh pages each; the mesh is the one pass's either way
    from surfgen.generator import allocator
    from surfgen.generator.mesh.lewiner_chunks import _shared_out

    monkeypatch.setattr(allocator, "_giving_back", giving_back)
    specs = [spec for n in (400, 300) for spec in lw.run_buffers(n, 100, True)]
    # each run's layers, vertices, faces and heads; room for both runs' vertices and faces
    writes = [specs[i] for i in (1, 2, 5, 6)]
    size = sum(int(np.prod(s)) * np.dtype(t).itemsize + allocator.ALIGN for s, t in writes)
    spare = [np.empty(size // 8)]
    made = _shared_out(spare, specs, 2)
    assert [(m.shape, m.dtype) for m in made] == [(s, np.dtype(t)) for s, t in specs]
    on_spare = [m.base is not None for m in made]
    if giving_back:  # faces and vertices of both runs, then what still fits: not the layers
        assert on_spare[1] and on_spare[2] and on_spare[5] and on_spare[6]
        assert not on_spare[0] and not on_spare[4]
    else:
        assert not any(on_spare)
    rng = np.random.default_rng(8)
    w = volume(2, (14, 11, 9), rng)
    mask = skimage_mask(w)
    one = run_port(w, mask, threads=1)
    keys, corners = cells_of(w, mask)
    spare = [np.empty(keys.size * 6, dtype=np.float32)]
    v, f, _ = lewiner_cells([keys, corners], w.shape[2], w.shape[1], 2, 1, spare=spare)
    assert np.array_equal(v, one[0]) and np.array_equal(f, one[1])


def test_every_case_is_met():
    """The noise volumes above reach every Lewiner case (1-14) and the centre vertex."""
    rng = np.random.default_rng(3)
    seen = set()
    for _ in range(20):
        w = volume(0, (6, 6, 6), rng)
        v = w.astype(np.float64)
        for z in range(5):
            for y in range(5):
                for x in range(5):
                    c = [v[z, y, x], v[z, y, x + 1], v[z, y + 1, x + 1], v[z, y + 1, x],
                         v[z + 1, y, x], v[z + 1, y, x + 1], v[z + 1, y + 1, x + 1],
                         v[z + 1, y + 1, x]]  # fmt: skip
                    index = sum(1 << k for k in range(8) if c[k] > 0)
                    seen.add(int(lw.LUT[lw.LUT_META[lw.CASES, 0] + 2 * index]))
    assert set(range(1, 15)) <= seen


def test_the_pass_grows_its_arrays_with_one_compile_per_array_type(monkeypatch):
    # lewiner_range passes grown int64 values, never literals (a count numba types as 0, the
    # room 13): grown is compiled once per array type, not again per literal (1.3 -> 0.8 s
    # of a cold warm-up). A fresh caller types its calls into a fresh grown.
    import numba
    from numba import types

    from surfgen.generator.jit.options import KERNEL

    fresh = numba.njit(**{**KERNEL, "cache": False})(lw.grown.py_func)
    monkeypatch.setattr(lw, "grown", fresh)
    keys = np.zeros(1, dtype=np.int64)
    corners = np.ones((1, 8), dtype=np.float32)
    buffers = [np.empty(shape, dtype=dtype) for shape, dtype in lw.run_buffers(1, 4, True)]
    args = (keys, corners, 0, 1, 2, 2, True, *buffers)
    numba.njit(**{**KERNEL, "cache": False})(lw.lewiner_range.py_func).compile(
        tuple(numba.typeof(a) for a in args)
    )
    assert len(fresh.signatures) == 4  # float32 vertices, int32 faces and heads, int64 centres
    assert not [s for s in fresh.signatures if any(isinstance(t, types.Literal) for t in s)]


def test_the_cell_loop_counts_no_references():
    # numba counted references (atomic increments) to every array reassigned in the cell loop
    # (grown there, the face layers swapped), a dozen a cell: most of the pass's time. The
    # cells now run in runs with room made between them, and the layers are two rows.
    keys = np.zeros(1, dtype=np.int64)
    corners = np.ones((1, 8), dtype=np.float32)
    for track in (False, True):
        made = lw.run_buffers(1, 4, track)
        args = (keys, corners, 0, 1, 2, 2, track, *(np.empty(s, dtype=d) for s, d in made))
        body = kernel_ir(lw.lewiner_range.py_func, *args)
        assert loop_refcounts(body, "_big_switch") == 0
