"""scikit-image's Lewiner marching cubes over a list of cells, bit for bit.

The dense path (:func:`~surfgen.generator.mesh.mesh.extract_with_edges`) hands skimage the whole
float32 volume and a mask of the mixed cells.  The sparse path has no whole volume, only the
mixed cells and their corners, so this module runs the same algorithm on such a list:
skimage's Cython ``marching_cubes`` (``skimage/measure/_marching_cubes_lewiner_cy.pyx``) ported
to numba with skimage's own lookup tables (:mod:`skimage.measure._marching_cubes_lewiner_luts`,
read at import).  Given the cells skimage's mask lets through, in the order skimage visits them
(C order of the volume: axis 0 outer), it returns the vertices and faces skimage returns, in the
same order and with the same float32 bits:

- a vertex's coordinates are computed in double as ``cell + fx / ff`` from the cell's corner
  values and rounded once to float32, with the absolute cell index (a block-wise run shifted
  afterwards would round differently);
- vertices are shared through skimage's two "face layers" (the vertices of the current and the
  next plane of cells, keyed by cell and edge): arrays over a plane as skimage's own, the
  slots set cleared as skimage clears its layers, so the same duplicates appear where
  skimage's cache misses (a plane's cells are visited in order, so the layers are read and
  written along rows: no hashing, few cache misses);
- the ambiguous cases' face and interior tests use the same double arithmetic;
- skimage's Python wrapper is applied as the results are written: vertices in the volume's
  axis order, each triangle reversed ('descent'), the faces int64 as the mesh keeps them.

:func:`lewiner_range` is the kernel, over a run of the cells;
:func:`surfgen.generator.mesh.lewiner_chunks.lewiner_cells` runs it on all of them, on threads
in runs of planes (the same result); ``tests/generator/mesh/test_sparse_lewiner.py`` compares
it with skimage on random volumes full of ambiguous cells.  The axis names follow the Cython
(``x`` is the volume's last axis, ``z`` its first).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from skimage.measure import _marching_cubes_lewiner as _sk
from skimage.measure import _marching_cubes_lewiner_luts as _luts

from surfgen.generator.jit.options import INLINE, KERNEL
from surfgen.generator.mesh.growing import grown

# skimage's FLT_EPSILON is np.spacing(1.0): the double epsilon, despite the name.
_EPS = float(np.spacing(1.0))

# The tables skimage's LutProvider takes, in its order; each is stored flat in one int8 array
# with its shape, and read as skimage's Lut.get1/get2/get3 read them (row-major offsets). The
# kernels read these arrays as globals (numba freezes them into the machine code as constants):
# no argument to count references to in the cell loop.
_NAMES = [
    "CASES",
    "TILING1",
    "TILING2",
    "TILING3_1",
    "TILING3_2",
    "TILING4_1",
    "TILING4_2",
    "TILING5",
    "TILING6_1_1",
    "TILING6_1_2",
    "TILING6_2",
    "TILING7_1",
    "TILING7_2",
    "TILING7_3",
    "TILING7_4_1",
    "TILING7_4_2",
    "TILING8",
    "TILING9",
    "TILING10_1_1",
    "TILING10_1_1_",
    "TILING10_1_2",
    "TILING10_2",
    "TILING10_2_",
    "TILING11",
    "TILING12_1_1",
    "TILING12_1_1_",
    "TILING12_1_2",
    "TILING12_2",
    "TILING12_2_",
    "TILING13_1",
    "TILING13_1_",
    "TILING13_2",
    "TILING13_2_",
    "TILING13_3",
    "TILING13_3_",
    "TILING13_4",
    "TILING13_5_1",
    "TILING13_5_2",
    "TILING14",
    "TEST3",
    "TEST4",
    "TEST6",
    "TEST7",
    "TEST10",
    "TEST12",
    "TEST13",
    "SUBCONFIG13",
]
(
    CASES, T1, T2, T3_1, T3_2, T4_1, T4_2, T5, T6_1_1, T6_1_2, T6_2, T7_1, T7_2, T7_3, T7_4_1,
    T7_4_2, T8, T9, T10_1_1, T10_1_1_, T10_1_2, T10_2, T10_2_, T11, T12_1_1, T12_1_1_, T12_1_2,
    T12_2, T12_2_, T13_1, T13_1_, T13_2, T13_2_, T13_3, T13_3_, T13_4, T13_5_1, T13_5_2, T14,
    TEST3, TEST4, TEST6, TEST7, TEST10, TEST12, TEST13, SUBCONFIG13,
) = range(len(_NAMES))  # fmt: skip


def _tables() -> tuple[np.ndarray, np.ndarray]:
    """The tables in one flat int8 array, and per table ``(offset, L1, L2)`` (skimage's Lut)."""
    arrays = [_sk._to_array(getattr(_luts, name)) for name in _NAMES]
    meta = np.zeros((len(arrays), 3), dtype=np.int64)
    offset = 0
    for t, a in enumerate(arrays):
        meta[t] = (offset, a.shape[1] if a.ndim > 1 else 1, a.shape[2] if a.ndim > 2 else 1)
        offset += a.size
    flat = np.concatenate([a.reshape(-1) for a in arrays]).astype(np.int8)
    return flat, meta


LUT, LUT_META = _tables()
# Edge -> relative corner positions (skimage's EDGETORELATIVEPOS{X,Y,Z}), shape (12, 2).
EDGE_X = np.ascontiguousarray(_sk.EDGETORELATIVEPOSX, dtype=np.int64)
EDGE_Y = np.ascontiguousarray(_sk.EDGETORELATIVEPOSY, dtype=np.int64)
EDGE_Z = np.ascontiguousarray(_sk.EDGETORELATIVEPOSZ, dtype=np.int64)


@njit(**INLINE)
def _get1(t, i0):
    return np.int64(LUT[LUT_META[t, 0] + i0])


@njit(**INLINE)
def _get2(t, i0, i1):
    return np.int64(LUT[LUT_META[t, 0] + i0 * LUT_META[t, 1] + i1])


@njit(**INLINE)
def _get3(t, i0, i1, i2):
    m = LUT_META
    return np.int64(LUT[m[t, 0] + i0 * m[t, 1] * m[t, 2] + i1 * m[t, 2] + i2])


@njit(**KERNEL)
def _test_face(v, face):
    """skimage's ``test_face``: whether the face ``face`` (signed) holds part of the surface;
    ``v`` the cell's corners v0..v7.  A function of its own, not copied into each of the big
    switch's nine calls (numba's ``inline``): the marching compiles faster (alone 7.2 -> 5.4 s;
    6.5 -> 6.2 s within a warm-up, whose kernels share their callees) and runs as fast."""
    a = face if face >= 0 else -face
    if a == 1:
        A, B, C, D = v[0], v[4], v[5], v[1]
    elif a == 2:
        A, B, C, D = v[1], v[5], v[6], v[2]
    elif a == 3:
        A, B, C, D = v[2], v[6], v[7], v[3]
    elif a == 4:
        A, B, C, D = v[3], v[7], v[4], v[0]
    elif a == 5:
        A, B, C, D = v[0], v[3], v[2], v[1]
    else:
        A, B, C, D = v[4], v[7], v[6], v[5]
    ac_bd = A * C - B * D
    if ac_bd > -_EPS and ac_bd < _EPS:
        return face >= 0
    return np.float64(face) * A * ac_bd >= 0


# skimage's test_internal, per edge of the cell: the edge's two corners, then the corner pairs of
# the three other interpolations (Bt, Ct, Dt)
_EDGE_T = np.array(
    [
        [0, 1, 3, 2, 7, 6, 4, 5],
        [1, 2, 0, 3, 4, 7, 5, 6],
        [2, 3, 1, 0, 5, 4, 6, 7],
        [3, 0, 2, 1, 6, 5, 7, 4],
        [4, 5, 7, 6, 3, 2, 0, 1],
        [5, 6, 4, 7, 0, 3, 1, 2],
        [6, 7, 5, 4, 1, 0, 2, 3],
        [7, 4, 6, 5, 2, 1, 3, 0],
        [0, 4, 3, 7, 2, 6, 1, 5],
        [1, 5, 0, 4, 3, 7, 2, 6],
        [2, 6, 1, 5, 0, 4, 3, 7],
        [3, 7, 2, 6, 1, 5, 0, 4],
    ],
    dtype=np.int64,
)


@njit(**INLINE)
def _edge_t(v, p, q, b0, b1, c0, c1, d0, d1):
    """``t`` on the edge from corner p to q and the three other interpolations of
    ``test_internal`` (Bt, Ct, Dt from the corner pairs)."""
    t = v[p] / (v[p] - v[q] + _EPS)
    return t, v[b0] + (v[b1] - v[b0]) * t, v[c0] + (v[c1] - v[c0]) * t, v[d0] + (v[d1] - v[d0]) * t


@njit(**KERNEL)
def _test_internal(v, case, config, subconfig, s):
    """skimage's ``test_internal`` (cases 4, 6, 7, 10, 12, 13)."""
    At = Bt = Ct = Dt = 0.0
    if case == 4 or case == 10:
        a = (v[4] - v[0]) * (v[6] - v[2]) - (v[7] - v[3]) * (v[5] - v[1])
        b = (
            v[2] * (v[4] - v[0])
            + v[0] * (v[6] - v[2])
            - v[1] * (v[7] - v[3])
            - v[3] * (v[5] - v[1])
        )
        t = -b / (2 * a + _EPS)
        if t < 0 or t > 1:
            return s > 0
        At = v[0] + (v[4] - v[0]) * t
        Bt = v[3] + (v[7] - v[3]) * t
        Ct = v[2] + (v[6] - v[2]) * t
        Dt = v[1] + (v[5] - v[1]) * t
    else:
        if case == 6:
            edge = _get2(TEST6, config, 2)
        elif case == 7:
            edge = _get2(TEST7, config, 4)
        elif case == 12:
            edge = _get2(TEST12, config, 3)
        else:
            edge = _get3(T13_5_1, config, subconfig, 0)
        At = 0.0
        if 0 <= edge < 12:  # one call on the edge's row of corners (not 12 inlined copies)
            e = _EDGE_T[edge]
            _t, Bt, Ct, Dt = _edge_t(v, e[0], e[1], e[2], e[3], e[4], e[5], e[6], e[7])
    test = 0
    if At >= 0:
        test += 1
    if Bt >= 0:
        test += 2
    if Ct >= 0:
        test += 4
    if Dt >= 0:
        test += 8
    if test == 5:
        return s > 0 if At * Ct - Bt * Dt < _EPS else False
    if test == 10:
        return s > 0 if At * Ct - Bt * Dt >= _EPS else False
    if test in (7, 11, 13, 14, 15):
        return s < 0
    return s > 0


# ----------------------------------------------------------------------------- the cells


def run_buffers(n_cells: int, plane: int, track: bool) -> list:
    """What :func:`lewiner_range` writes into, for a run of ``n_cells`` cells of a volume
    whose planes have ``plane`` cells, as ``[(shape, dtype), ...]``: the two face layers, and
    the vertices, faces and heads sized for the usual two triangles per cell (grown when a
    surface needs more)."""
    rows = n_cells + n_cells // 4 + 64
    return [
        ((2, 4 * plane), np.int32),
        ((rows, 3), np.float32),
        ((2 * n_cells + n_cells // 4 + 64, 3), np.int32),
        ((rows if track else 0,), np.int32),
    ]


@njit(**KERNEL)
def lewiner_range(keys, corners, c0, c1, nx, ny, track, layers, verts, faces, head):
    """Marching cubes (skimage's Lewiner, step 1, not classic) over the cells ``keys[c0:c1]``
    (int64 flat numbers ``(z * ny + y) * nx + x`` in the volume, sorted: skimage's visiting
    order) with corner values ``corners`` (C, 8) float32 in skimage's order v0..v7
    (``im[z, y, x]``, ``im[z, y, x+1]``, ``im[z, y+1, x+1]``, ``im[z, y+1, x]``, then the same
    at ``z+1``), the level 0.

    ``nx``, ``ny``: the volume's sizes along x (last axis) and y.  Returns what skimage's
    ``marching_cubes(..., gradient_direction="descent")`` returns for those cells: float32
    vertices ``(V, 3)`` in the volume's axis order (z, y, x) and faces ``(F, 3)`` wound for
    'descent' (each triangle of the Cython kernel reversed), here int32 (the run's own
    numbers: half the memory of the mesh's int64 while the runs wait to be joined; a run would
    need 2**31 vertices, 24 GiB of them, to overflow). Both are written in place (no
    reversal afterwards); they are views of arrays sized for the usual two triangles per
    cell, grown when a surface needs more.

    Then what joins a run of planes to the one before it
    (:func:`surfgen.generator.mesh.lewiner_chunks.lewiner_cells`): ``head`` (with ``track``;
    else empty), per vertex the face-layer slot of an x or y edge of the run's first plane
    that it was made for (-1 for the others), which the run before may hold already; the last
    plane's second layer (slot -> vertex: the next plane's first layer; int32, as ``head``)
    and that plane's z. Last, the vertices it made at a cell's centre (int64, ascending): with
    a cap's copies, the only ones that may be one point with another once placed
    (:func:`~surfgen.generator.mesh.placement.same_targets`).

    ``layers``, ``verts``, ``faces``, ``head``: the arrays it writes into (their contents
    undefined; :func:`run_buffers`), which the caller makes (on memory done with:
    :func:`~surfgen.generator.allocator.recycled_many`).
    """
    plane = nx * ny
    n_cells = c1 - c0
    # skimage's two face layers, dense as skimage's own: slot 4 * (nx * y + x) + edge kind
    # (0, 1: the x and y edges of the layer's face, 2: the z edge, 3: the centre) -> vertex;
    # row ``one`` is skimage's first layer, the other its second (a swap flips ``one``). The
    # slots set in each are listed to clear them when skimage clears the layer: a cell sets
    # at most 13, a layer holds those of two planes' cells, and a slot is listed once.
    layers[:] = -1
    used = np.empty((2, min(4 * plane, 26 * _widest_plane(keys, c0, c1, plane))), np.int32)
    one = 0
    n1 = 0
    n2 = 0
    first_z = keys[c0] // plane if n_cells > 0 else np.int64(-2)
    nv = 0
    nf = 0
    centres = np.empty(_RUN, dtype=np.int64)  # the vertices made at a cell's centre
    nc = 0
    v = np.empty(8)  # v0..v7
    vv = np.empty(8)  # skimage's vv: the corners indexed by bits (x, y, z)
    tri = np.empty(36, dtype=np.int64)  # edge indices of the cell's triangles, then vertices
    last_z = np.int64(-2)
    row = np.int64(-(nx + 1))  # the first key of the cells' row (none yet)
    z = y = np.int64(0)
    c = c0
    while c < c1:
        # the cells in runs with room for the most a cell can add (13 vertices, 12
        # triangles), the arrays grown between runs: no array is reassigned within a run,
        # so numba counts no reference per cell (that took most of the marching's time)
        room = min((verts.shape[0] - nv) // _ROOM, (faces.shape[0] - nf) // 12)
        run = min(c1 - c, room, centres.size - nc)  # a cell makes at most one centre
        if run < min(c1 - c, _RUN):
            if room < _RUN:
                verts = grown(verts, np.int64(nv), _ROOM * _RUN)
                if track:
                    head = grown(head, np.int64(nv), _ROOM * _RUN)
                faces = grown(faces, np.int64(nf), np.int64(12) * _RUN)
            if centres.size - nc < _RUN:
                centres = grown(centres, np.int64(nc), _RUN)
            continue
        for cell in range(c, c + run):
            key = keys[cell]
            x = key - row
            if x >= nx or x < 0:  # a new row: its z and y by divisions (40 cycles each)
                z = key // plane
                y = (key - z * plane) // nx
                row = key - (key - z * plane - y * nx)
                x = key - row
            if z != last_z:
                # skimage swaps its layers at every z (new_z_value): a layer's vertices live
                # on for the next plane only
                for u in range(n1):
                    layers[one, used[one, u]] = -1
                if z == last_z + 1:
                    one = 1 - one
                    n1 = n2
                else:
                    for u in range(n2):
                        layers[1 - one, used[1 - one, u]] = -1
                    n1 = 0
                n2 = 0
                last_z = z
            index = 0
            for k in range(8):
                v[k] = np.float64(corners[cell, k])
                if v[k] > 0.0:
                    index += 1 << k
            case = _get2(CASES, index, 0)
            if case <= 0:
                continue
            config = _get2(CASES, index, 1)
            corner_values = (v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7])
            nt, table, i1, three = _big_switch(corner_values, case, config)
            if nt == 0:
                continue
            for q in range(3 * nt):
                if three:
                    tri[q] = _get3(table, config, i1, q)
                else:
                    tri[q] = _get2(table, config, q)
            vv[0], vv[1], vv[2], vv[3] = v[0], v[1], v[3], v[2]
            vv[4], vv[5], vv[6], vv[7] = v[4], v[5], v[7], v[6]
            # the centre vertex (computed on first use, as skimage does)
            cx12 = cy12 = cz12 = 0.0
            have12 = False
            for q in range(3 * nt):
                vi = tri[q]
                # skimage's get_index_in_facelayer
                i = nx * y + x
                j = 0
                second = False
                if vi < 8:
                    e = vi
                    if vi >= 4:
                        e = vi - 4
                        second = True
                    if e == 1:
                        i += 1
                        j = 1
                    elif e == 2:
                        i += nx
                    elif e == 3:
                        j = 1
                elif vi < 12:
                    j = 2
                    if vi == 9:
                        i += 1
                    elif vi == 10:
                        i += nx + 1
                    elif vi == 11:
                        i += nx
                else:
                    j = 3
                at_slot = 4 * i + j
                at = layers[1 - one, at_slot] if second else layers[one, at_slot]
                if at < 0:
                    if vi == 12:
                        if not have12:
                            fx = fy = fz = ff = 0.0
                            for k in range(8):
                                w = 1.0 / (_EPS + abs(v[k]))
                                # corners v0..v7 at (x, y, z) bits 000 100 110 010 001 101 111 011
                                bx = 1.0 if k in (1, 2, 5, 6) else 0.0
                                by = 1.0 if k in (2, 3, 6, 7) else 0.0
                                bz = 1.0 if k >= 4 else 0.0
                                fx += bx * w
                                fy += by * w
                                fz += bz * w
                                ff += w
                            cx12 = np.float64(x) + 1.0 * fx / ff
                            cy12 = np.float64(y) + 1.0 * fy / ff
                            cz12 = np.float64(z) + 1.0 * fz / ff
                            have12 = True
                        centres[nc] = nv
                        nc += 1
                        px, py, pz = cx12, cy12, cz12
                    else:
                        dx1, dx2 = EDGE_X[vi, 0], EDGE_X[vi, 1]
                        dy1, dy2 = EDGE_Y[vi, 0], EDGE_Y[vi, 1]
                        dz1, dz2 = EDGE_Z[vi, 0], EDGE_Z[vi, 1]
                        w1 = 1.0 / (_EPS + abs(vv[dz1 * 4 + dy1 * 2 + dx1]))
                        w2 = 1.0 / (_EPS + abs(vv[dz2 * 4 + dy2 * 2 + dx2]))
                        ff = 0.0 + w1
                        ff += w2
                        px = np.float64(x) + _along(dx1, dx2, w1, w2, ff)
                        py = np.float64(y) + _along(dy1, dy2, w1, w2, ff)
                        pz = np.float64(z) + _along(dz1, dz2, w1, w2, ff)
                    # skimage's wrapper flips the vertices to the volume's axis order
                    verts[nv, 0] = np.float32(pz)
                    verts[nv, 1] = np.float32(py)
                    verts[nv, 2] = np.float32(px)
                    if track:  # an x or y edge of the first plane: the run before may hold it
                        head[nv] = at_slot if (z == first_z and not second and j < 2) else -1
                    at = nv
                    nv += 1
                    if second:
                        layers[1 - one, at_slot] = at
                        used[1 - one, n2] = at_slot
                        n2 += 1
                    else:
                        layers[one, at_slot] = at
                        used[one, n1] = at_slot
                        n1 += 1
                tri[q] = at  # its edge read: the slot holds its vertex now
            for t in range(nt):  # ... and reverses each triangle ('descent'); written by rows
                faces[nf + t, 0] = tri[3 * t + 2]  # with whole-number columns: writing each
                faces[nf + t, 1] = tri[3 * t + 1]  # vertex at [nf + q // 3, 2 - q % 3] took
                faces[nf + t, 2] = tri[3 * t]  # a seventh of the marching (49 -> 42 ns a cell)
            nf += nt
        c += run
    heads = head[: nv if track else 0]
    return verts[:nv], faces[:nf], heads, layers[1 - one], last_z, centres[:nc]


@njit(**INLINE)
def _along(d1, d2, w1, w2, ff):
    """skimage's ``1.0 * (0.0 + d1 w1 + d2 w2) / ff`` for a vertex on an edge between corners
    at offsets ``d1``, ``d2`` (0 or 1) along an axis, with weights ``w1``, ``w2`` (finite,
    positive) and ``ff = 0.0 + w1 + w2``: ``d1`` where the edge does not run along the axis
    (the sum is then 0 or ``ff`` itself), else the upper corner's weight over ``ff`` (the
    other term is 0): the same float64, with one division where skimage has three."""
    if d1 == d2:
        return np.float64(d1)
    return (w1 if d1 else w2) / ff


#: Cells a run of :func:`lewiner_range` takes at least between two growths of its arrays.
_RUN = np.int64(256)


@njit(**KERNEL)
def _widest_plane(keys, c0, c1, plane):
    """The most cells of ``keys[c0:c1]`` (sorted) on one plane (at least 1)."""
    most = 1
    count = 0
    last = np.int64(-1)
    for c in range(c0, c1):
        z = keys[c] // plane
        count = count + 1 if z == last else 1
        last = z
        most = max(most, count)
    return most


_ROOM = np.int64(13)  # room for what one cell adds (at most 12 edge vertices and its centre)


@njit(**KERNEL)
def _big_switch(v, case, config):
    """skimage's ``the_big_switch``: ``(triangles, table, second index, 3-d table?)``."""
    sub = np.int64(0)  # not a literal 0: _test_internal is compiled once, for an int64
    if case == 1:
        return 1, T1, 0, False
    if case == 2:
        return 2, T2, 0, False
    if case == 3:
        if _test_face(v, _get1(TEST3, config)):
            return 4, T3_2, 0, False
        return 2, T3_1, 0, False
    if case == 4:
        if _test_internal(v, case, config, sub, _get1(TEST4, config)):
            return 2, T4_1, 0, False
        return 6, T4_2, 0, False
    if case == 5:
        return 3, T5, 0, False
    if case == 6:
        if _test_face(v, _get2(TEST6, config, 0)):
            return 5, T6_2, 0, False
        if _test_internal(v, case, config, sub, _get2(TEST6, config, 1)):
            return 3, T6_1_1, 0, False
        return 9, T6_1_2, 0, False
    if case == 7:
        if _test_face(v, _get2(TEST7, config, 0)):
            sub += 1
        if _test_face(v, _get2(TEST7, config, 1)):
            sub += 2
        if _test_face(v, _get2(TEST7, config, 2)):
            sub += 4
        if sub == 0:
            return 3, T7_1, 0, False
        if sub == 1:
            return 5, T7_2, 0, True
        if sub == 2:
            return 5, T7_2, 1, True
        if sub == 3:
            return 9, T7_3, 0, True
        if sub == 4:
            return 5, T7_2, 2, True
        if sub == 5:
            return 9, T7_3, 1, True
        if sub == 6:
            return 9, T7_3, 2, True
        if _test_internal(v, case, config, sub, _get2(TEST7, config, 3)):
            return 9, T7_4_2, 0, False
        return 5, T7_4_1, 0, False
    if case == 8:
        return 2, T8, 0, False
    if case == 9:
        return 4, T9, 0, False
    if case == 10 or case == 12:
        test = TEST10 if case == 10 else TEST12
        if _test_face(v, _get2(test, config, 0)):
            if _test_face(v, _get2(test, config, 1)):
                return 4, (T10_1_1_ if case == 10 else T12_1_1_), 0, False
            return 8, (T10_2 if case == 10 else T12_2), 0, False
        if _test_face(v, _get2(test, config, 1)):
            return 8, (T10_2_ if case == 10 else T12_2_), 0, False
        if _test_internal(v, case, config, sub, _get2(test, config, 2)):
            return 4, (T10_1_1 if case == 10 else T12_1_1), 0, False
        return 8, (T10_1_2 if case == 10 else T12_1_2), 0, False
    if case == 11:
        return 4, T11, 0, False
    if case == 13:
        for f in range(6):
            if _test_face(v, _get2(TEST13, config, f)):
                sub += 1 << f
        sub = _get1(SUBCONFIG13, sub)
        if sub == 0:
            return 4, T13_1, 0, False
        if sub <= 6:
            return 6, T13_2, sub - 1, True
        if sub <= 18:
            return 10, T13_3, sub - 7, True
        if sub <= 22:
            return 12, T13_4, sub - 19, True
        if sub <= 26:
            s = sub - 23
            if _test_internal(v, case, config, s, _get2(TEST13, config, 6)):
                return 6, T13_5_1, s, True
            return 10, T13_5_2, s, True
        if sub <= 38:
            return 10, T13_3_, sub - 27, True
        if sub <= 44:
            return 6, T13_2_, sub - 39, True
        if sub == 45:
            return 4, T13_1_, 0, False
        return 0, T1, 0, False  # skimage prints "impossible case 13" and adds nothing
    if case == 14:
        return 4, T14, 0, False
    return 0, T1, 0, False
