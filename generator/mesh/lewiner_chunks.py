"""skimage's marching cubes over a list of cells, on several threads, the same result.

:func:`~surfgen.generator.mesh.sparse_lewiner.lewiner_range` runs skimage's Lewiner algorithm
over a run of the cells (sorted in skimage's visiting order: plane by plane along the volume's
first axis).  Vertices are numbered as they are made and shared between neighbouring cells
through two face layers, the current plane's and the next one's; so a run of whole planes
depends on the run before it through one thing only: the vertices on the plane between them,
which the run before made for its last plane's top faces (its second layer, handed back) and
which skimage's single pass finds in its first layer instead of making them again.

:func:`lewiner_cells` cuts the cells into runs of whole planes of about equal counts, runs them
at once (one per thread, the GIL released), then joins them in order: a vertex a run made for
an x or y edge of its first plane (its ``head``) is the run before's where that run's last
layer holds the same slot and its last plane is the one just below; every other vertex gets
the next number, in the order it was made.  That is skimage's numbering, so the vertices and
faces are the single pass's, bit for bit (a vertex's coordinates are computed from the edge's
two corner values and its cell's absolute index, the same in either run).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.allocator import recycled_many
from surfgen.generator.eval.tape import run_at_once
from surfgen.generator.jit.options import KERNEL
from surfgen.generator.mesh.sparse_lewiner import lewiner_range, run_buffers

#: Cells per run at least: a run of 100,000 cells takes about 7 ms (Xeon: 66 ns a cell), and
#: joining it about a fifth of that (the join's writes: 11 ms for 1.6 million faces, Zen 4).
CHUNK_CELLS = 100_000


def lewiner_cells(
    cells: list[np.ndarray],
    nx: int,
    ny: int,
    threads: int = 1,
    min_cells: int | None = None,
    spare: list[np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """skimage's ``marching_cubes(..., gradient_direction="descent")`` over the cells
    ``[keys, corners]`` taken out of the list ``cells``
    (:func:`~surfgen.generator.mesh.sparse_lewiner.lewiner_range`): float32 vertices (V, 3),
    int64 faces (F, 3) (the runs' own int32 numbers widened) and the numbers of the vertices
    made at a cell's centre (int64, ascending). With ``threads`` > 1, in
    runs of whole planes of at least ``min_cells`` cells (None: :data:`CHUNK_CELLS`), one per
    thread, joined into the same arrays. Once the runs are made, the cells are done with (a
    list, not the arrays, is passed so that nothing else holds them): the keys are freed and
    the joined vertices take the corners' memory
    (:func:`~surfgen.generator.allocator.recycled_many`), so the cells are not held beside
    the join (sculpture-1 at 512^3: the join's peak 309 -> 279 MiB).

    ``spare``: a list holding an array done with (the offsets), on whose memory the runs
    write where their arrays fit (the rest fresh); on return it holds that memory, done with
    too (the placement's arrays take it:
    :func:`~surfgen.generator.mesh.placement.place_vertices`). A single run's arrays are its
    own, and ``spare`` is emptied."""
    keys, corners = cells
    cells.clear()
    n = len(keys)
    plane = nx * ny
    least = CHUNK_CELLS if min_cells is None else max(1, int(min_cells))
    runs = _runs(keys, plane, max(1, min(int(threads), n // least)))
    pairs = list(zip(runs[:-1], runs[1:], strict=True)) or [(0, 0)]
    track = len(pairs) > 1
    specs = [spec for a, b in pairs for spec in run_buffers(b - a, plane, track)]
    if not track:  # one run (or no cell): skimage's single pass, nothing to join; its arrays
        # apart (the layers freed once it is done, the vertices kept)
        if spare is not None:
            spare.clear()
        a, b = pairs[0]
        buffers = [np.empty(shape, dtype=dtype) for shape, dtype in specs]
        verts, faces, _, _, _, centres = lewiner_range(keys, corners, a, b, nx, ny, False, *buffers)
        return verts, faces.astype(np.int64), centres
    buffers = _shared_out(spare if spare is not None else [], specs, len(pairs))
    taken = [b for b in buffers if b.base is not None]
    if spare is not None and taken:  # a view of the block under those that took it
        spare.append(taken[0])
    del taken
    parts = run_at_once(
        [
            lambda a=a, b=b, k=keys, c=corners, run=buffers[4 * r : 4 * r + 4]: lewiner_range(
                k, c, a, b, nx, ny, True, *run
            )
            for r, (a, b) in enumerate(pairs)
        ]
    )
    del buffers
    first_planes = [keys[a] // plane for a in runs[:-1]]
    spent = [corners]
    del keys, corners
    return _join(parts, first_planes, spent)


#: The order in which the runs' arrays (:func:`~.sparse_lewiner.run_buffers`: layers, vertices,
#: faces, heads) take the memory done with: the arrays the runs write most first.
_BY_WRITES = (2, 1, 0, 3)


def _shared_out(spare: list[np.ndarray], specs: list, n_runs: int) -> list[np.ndarray]:
    """The runs' arrays (``specs``: each run's four in turn), on the memory in ``spare`` kind
    by kind (:data:`_BY_WRITES`: every run's faces, then every run's vertices...): where it
    cannot hold them all, each run writes about as many fresh pages as the others (run after
    run, the first took it all and the last faulted in every page of its own: sculpture-1 at
    512^3, 32 and 37 ms), since the runs wait for the slowest."""
    kinds = len(specs) // n_runs
    assert kinds == len(_BY_WRITES), "run_buffers and _BY_WRITES name the same arrays"
    order = [kinds * r + kind for kind in _BY_WRITES for r in range(n_runs)]
    made = recycled_many(spare, [specs[i] for i in order])
    buffers: list[np.ndarray] = [np.empty(0)] * len(specs)
    for i, array in zip(order, made, strict=True):
        buffers[i] = array
    return buffers


def _runs(keys: np.ndarray, plane: int, n: int) -> list[int]:
    """Boundaries of ``n`` runs of whole planes of about equal cell counts (fewer where a plane
    holds more than a run's share): ``[0, ..., len(keys)]``."""
    size = len(keys)
    bounds = [0]
    for k in range(1, n):
        target = size * k // n
        start = int(np.searchsorted(keys, (keys[target] // plane) * plane))  # its plane's first
        if start > bounds[-1]:
            bounds.append(start)
    return [*bounds, size] if size > bounds[-1] else bounds


def _join(parts, first_planes, spent) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The runs' vertices and faces numbered as one pass numbers them, each run written by a
    thread of its own (its new vertices and its faces are rows of their own), on the memory
    of the array in ``spent`` where they fit (the cells' corners: the vertices;
    :func:`~surfgen.generator.allocator.recycled_many`); ``parts`` is emptied once all are
    written; with them, the numbers of the centre vertices (each a new vertex of its run).
    One run after the other, each freed once written, held one run less at the join's peak
    and took longer (sculpture-2 at 512^3: 0.020 s, now 0.014 s); with the cells not held
    beside it (their keys freed, their corners under the vertices), its peak stays below the
    render's (sculpture-1: 301 MiB against the offsets' 303)."""
    numbers, starts, total = _numbering(parts, first_planes)
    out_v, out_f = recycled_many(
        spent, [((total, 3), np.float32), ((sum(len(p[1]) for p in parts), 3), np.int64)]
    )
    f0 = np.cumsum([0] + [len(p[1]) for p in parts])
    run_at_once(
        [
            lambda r=r: _place(
                out_v, out_f, parts[r][0], parts[r][1], numbers[r], starts[r], f0[r]
            )  # fmt: skip
            for r in range(len(parts))
        ]
    )
    centres = np.concatenate([numbers[r][p[5]] for r, p in enumerate(parts)])
    parts.clear()
    return out_v, out_f, centres


def _numbering(parts, first_planes) -> tuple[list[np.ndarray], list[int], int]:
    """Each run's vertex numbers (:func:`_numbers`), the first number of its new vertices, and
    the number of vertices in all."""
    numbers, starts = [], []
    total = 0
    for r, (verts, _, head, _, _, _) in enumerate(parts):
        starts.append(total)
        if r == 0:
            numbers.append(np.arange(len(verts), dtype=np.int64))
            total = len(verts)
            continue
        tail, last_plane = parts[r - 1][3], parts[r - 1][4]
        linked = last_plane == first_planes[r] - 1
        local, total = _numbers(head, tail, numbers[-1], linked, total)
        numbers.append(local)
    return numbers, starts, total


@njit(**KERNEL)
def _numbers(head, tail, tail_numbers, linked, start):
    """A run's vertex numbers: its head vertices the run before's where that run's last layer
    (``tail``: slot -> its vertex, numbered ``tail_numbers``) holds the slot and ``linked`` (its
    last plane is just below), the others ``start``, ``start + 1``, ... in order. Returns them
    and the next free number."""
    out = np.empty(head.size, dtype=np.int64)
    following = start
    for i in range(head.size):
        h = head[i]
        if linked and h >= 0 and tail[h] >= 0:
            out[i] = tail_numbers[tail[h]]
        else:
            out[i] = following
            following += 1
    return out, following


@njit(**KERNEL)
def _place(out_v, out_f, verts, faces, numbers, start, f0):
    """A run's new vertices (numbered from ``start``) and its faces renumbered, written into
    the joined arrays (the faces from row ``f0``)."""
    for i in range(numbers.size):
        k = numbers[i]
        if k >= start:
            for a in range(3):
                out_v[k, a] = verts[i, a]
    for t in range(faces.shape[0]):
        for a in range(3):
            out_f[f0 + t, a] = numbers[faces[t, a]]
