"""How an ornament carves its envelope, measured on samples: the checks a sculpture's draw
runs on its ornaments (:mod:`.sculpture`) and the departure the ``plain`` filter judges.

This module holds the numba kernels and scipy calls of the sculpture family, so the registry
(read by ``--help``, ``config show`` and ``catalogue list``) loads none of them.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from scipy import ndimage

from surfgen.generator.eval.compiler import Program, compile_tree
from surfgen.generator.eval.evaluate import evaluate_compiled
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.jit.options import KERNEL, read_only
from surfgen.generator.model.draw import round_significant
from surfgen.generator.model.equation13 import Factor
from surfgen.generator.model.families.symmetry import ornament_combos, permute_factor
from surfgen.generator.model.order_stats import median, quantiles
from surfgen.generator.model.slope import gradient_norm


def _inverse(perm: tuple[int, ...]) -> tuple[int, ...]:
    out = [0] * len(perm)
    for k, v in enumerate(perm):
        out[v] = k
    return tuple(out)


def ornament_program(ornament: Factor, mirror: bool) -> Program:
    """The ornament's unit copy (with ``|x|, |y|, |z|`` when ``mirror``) compiled once: a try
    samples it on the feature grid and on the d grid."""
    return compile_tree(permute_factor(ornament, (0, 1, 2), mirror).to_tree())


def unit_samples(
    ornament: Factor,
    perms: tuple[tuple[int, ...], ...],
    mirror: bool,
    k: int,
    box: Box,
    n: int,
    program: Program | None = None,
) -> np.ndarray:
    """The ornament's unit ``(Σ_perms O∘perm)^k`` sampled on the cube ``box`` (``n`` per axis),
    for the checks: the ornament (with ``|x|, |y|, |z|`` when ``mirror``) is evaluated once, and
    its permuted copies are the same samples with the axes transposed (the cube's three axes
    are the same coordinates), then multiplied and summed in numpy as
    :func:`~.symmetry.ornament_terms` writes them. A copy's samples may differ from the evaluation of its
    own formula in the last bits, where the formula adds its terms in another order."""
    if len(set(box.lo)) != 1 or len(set(box.hi)) != 1:
        raise ValueError(f"the ornament's copies are transposed samples: {box} must be a cube")
    if program is None:
        program = ornament_program(ornament, mirror)
    base = evaluate_compiled(program, Grid(box, (n,) * 3), threads=1).values
    # O∘perm(x) = O(x[perm[0]], x[perm[1]], x[perm[2]]): sample i of the copy is sample
    # (i[perm[0]], ...) of O, which is O's array with its axes put in the inverse order.
    copies = [np.transpose(base, _inverse(p)) for p in perms]
    total = None
    with np.errstate(invalid="ignore", over="ignore"):
        for coef, combo in ornament_combos(len(perms), k):
            product = copies[combo[0]]
            for i in combo[1:]:
                product = product * copies[i]
            product = product * coef
            total = product if total is None else total + product
    assert total is not None
    return np.ascontiguousarray(total)


def stray_share(e: np.ndarray, o: np.ndarray, box: Box, depth: float) -> float:
    """The share of the carved surface's crossings (on the feature grid, strength and d as
    :func:`strength_on` sets them) that lie farther from the envelope's surface than twice the
    carving depth plus two cells: debris thrown away from the body. 1 when it cannot tell."""
    return carved(e, o, box, depth)[0]


def carved(
    e: np.ndarray,
    o: np.ndarray,
    box: Box,
    depth: float,
    ge: np.ndarray | None = None,
    strength_d: tuple[float, float | None] | None = None,
) -> tuple[float, float, np.ndarray | None]:
    """The carved surface ``e + s o - d = 0`` on the feature grid (s and d as
    :func:`strength_on` sets them): its stray share (see :func:`stray_share`; 1 when it
    cannot tell), its :func:`envelope_departure` (0 when it cannot tell), which the ``plain``
    filter judges on the full grid, and its samples ``e + s o - d`` (None when it cannot tell;
    :func:`pieces` counts its pieces). ``strength_d``: s and d if already chosen (else
    :func:`strength_on` these samples)."""
    n = e.shape[0]
    step = (box.hi[0] - box.lo[0]) / (n - 1)
    ge = gradient_norm(e, step) if ge is None else ge
    s, d = strength_on(e, o, step, depth, ge) if strength_d is None else strength_d
    if d is None:
        return 1.0, 0.0, None
    with np.errstate(invalid="ignore", over="ignore"):
        f = e + s * o - d
        distance = np.abs(e) / np.where(ge > 0, ge, np.inf)
    inside = f < 0
    crossing = np.zeros_like(inside)
    for axis in range(3):
        change = np.diff(inside, axis=axis)
        lo = [slice(None)] * 3
        lo[axis] = slice(0, -1)
        crossing[tuple(lo)] |= change
    count = np.count_nonzero(crossing)
    if count == 0:
        return 1.0, 0.0, None
    far = crossing & ~(distance <= 2 * depth + 2 * step)
    departure = envelope_departure(f, e)
    stray = np.count_nonzero(far) / count
    return stray, departure if math.isfinite(departure) else 0.0, f


_CUBE = np.ones((3, 3, 3), dtype=bool)


def pieces(values: np.ndarray, level: float = 0.0) -> int:
    """How many pieces the closed surface ``values = level`` has at least, from the samples
    alone: (components of the solid) + (components of the rest, the outside of the box
    included) - 1, both connected through the 26 neighbours of a sample.

    A capped marching-cubes surface separates the solid's regions from the rest's, each of its
    components exactly two of them, and the regions with the surfaces between them form a tree
    (every closed surface in space splits it in two): surfaces = regions - 1. Marching cubes
    joins samples only within a cell, where all are 26-neighbours, so it has at least as many
    regions of each kind as this count: the count never exceeds the mesh's components. The
    solid is the mesher's (finite samples below the level)."""
    with np.errstate(invalid="ignore"):
        solid = np.isfinite(values) & (values < level)
    if not solid.any() or solid.all():
        return 0
    n_solid = ndimage.label(solid, structure=_CUBE)[1]
    n_rest = ndimage.label(np.pad(~solid, 1, constant_values=True), structure=_CUBE)[1]
    return int(n_solid + n_rest - 1)


def envelope_departure(values: np.ndarray, envelope: np.ndarray, level: float = 0.0) -> float:
    """How far the surface ``values = level`` departs from its envelope ``envelope = 0``, both
    sampled on the same grid: the spread (5th to 95th percentile) of the envelope's normal
    offset ``E / |grad E|`` over the surface, divided by the envelope's radius (that of a ball of
    its volume). A shape that is its envelope, or its envelope grown or shrunk evenly, gives
    about 0; a few scratches leave the percentiles alone; deep carving gives 0.2 and more.

    The surface points are where the grid's edges cross the level, interpolated linearly (the
    marching-cubes vertices), so the measure does not see the grid's staircase. Returns
    ``inf`` when the envelope is empty on the grid or the surface has too few points.

    ``|grad E|`` is ``numpy.gradient``'s (central differences inside, one-sided at the faces, in
    grid steps), computed only at the ends of the crossing edges (:func:`_crossing_offsets`:
    the same operations, so the same bits, without the three whole-grid gradient arrays).
    """
    f = np.ascontiguousarray(values, dtype=np.float64)
    env = np.ascontiguousarray(envelope, dtype=np.float64)
    if f.ndim != 3 or f.shape != env.shape or min(f.shape) < 2:
        raise ValueError(f"values and envelope must be one 3-D grid, got {f.shape}, {env.shape}")
    f, env = read_only(f), read_only(env)  # one compiled signature of the kernel
    n_env, off = _crossing_offsets(f, float(level), env)
    if n_env == 0:
        return float("inf")
    off = off[np.isfinite(off)]
    if off.size < 8:
        return float("inf")
    radius = (3.0 * n_env / (4.0 * np.pi)) ** (1.0 / 3.0)  # in grid steps, like the offsets
    lo, hi = quantiles(off, (0.05, 0.95))
    return float((hi - lo) / radius)


@numba.njit(**KERNEL)
def _gradient_norm(e: np.ndarray, i: int, j: int, k: int) -> float:
    """``sqrt(gx² + gy² + gz²)`` of ``numpy.gradient(e)`` (unit spacing, edge order 1) at one
    point, with numpy's operations: ``(e[i+1] - e[i-1]) / 2`` inside, a one-sided difference on
    the faces, the squares summed in axis order."""
    n0, n1, n2 = e.shape
    if i == 0:
        g0 = e[1, j, k] - e[0, j, k]
    elif i == n0 - 1:
        g0 = e[i, j, k] - e[i - 1, j, k]
    else:
        g0 = (e[i + 1, j, k] - e[i - 1, j, k]) / 2.0
    if j == 0:
        g1 = e[i, 1, k] - e[i, 0, k]
    elif j == n1 - 1:
        g1 = e[i, j, k] - e[i, j - 1, k]
    else:
        g1 = (e[i, j + 1, k] - e[i, j - 1, k]) / 2.0
    if k == 0:
        g2 = e[i, j, 1] - e[i, j, 0]
    elif k == n2 - 1:
        g2 = e[i, j, k] - e[i, j, k - 1]
    else:
        g2 = (e[i, j, k + 1] - e[i, j, k - 1]) / 2.0
    return math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)


@numba.njit(**KERNEL)
def _crossing_offsets(v: np.ndarray, level: float, e: np.ndarray) -> tuple[int, np.ndarray]:
    """The envelope's cell count (finite and < 0) and, for every grid edge whose ends are
    finite and on either side of ``level``, ``E / |grad E|`` interpolated linearly to the
    crossing (axis by axis, in C order: the order does not change the percentiles)."""
    n0, n1, n2 = v.shape
    n_env = 0
    for i in range(n0):
        for j in range(n1):
            for k in range(n2):
                x = e[i, j, k]
                if np.isfinite(x) and x < 0:
                    n_env += 1
    out = np.empty(3 * v.size, np.float64)
    m = 0
    for axis in range(3):
        for i in range(n0 - (axis == 0)):
            for j in range(n1 - (axis == 1)):
                for k in range(n2 - (axis == 2)):
                    i1 = i + (axis == 0)
                    j1 = j + (axis == 1)
                    k1 = k + (axis == 2)
                    f0 = v[i, j, k] - level
                    f1 = v[i1, j1, k1] - level
                    if not (np.isfinite(f0) and np.isfinite(f1)) or (f0 < 0) == (f1 < 0):
                        continue
                    t = f0 / (f0 - f1)
                    e0 = e[i, j, k]
                    g0 = _gradient_norm(e, i, j, k)
                    ee = e0 + t * (e[i1, j1, k1] - e0)
                    g = g0 + t * (_gradient_norm(e, i1, j1, k1) - g0)
                    out[m] = ee / g
                    m += 1
    return n_env, out[:m]


def feature_size(e: np.ndarray, o: np.ndarray, box: Box, ge: np.ndarray | None = None) -> float:
    """How large the ornament ``o``'s features are where the envelope ``e`` has its surface:
    the 10-90 % spread of ``o`` over the median of ``|grad o|`` there, over the box's half-size
    (about 0.36 wavelengths of a sine; a grid too coarse to see the features gives about one
    cell). 0 when it cannot be measured (a constant, non-finite ornament)."""
    n = e.shape[0]
    step = (box.hi[0] - box.lo[0]) / (n - 1)
    ge = gradient_norm(e, step) if ge is None else ge
    go = gradient_norm(o, step)
    ok = np.isfinite(e) & np.isfinite(o) & np.isfinite(ge) & np.isfinite(go) & (ge > 0)
    band = ok & (np.abs(e) < 1.5 * step * np.where(ok, ge, 0.0))
    if np.count_nonzero(band) < 16:
        return 0.0
    lo, hi = quantiles(o[band], (0.1, 0.9))
    slope = float(median(go[band]))
    if not (slope > 0 and math.isfinite(float(hi - lo))):
        return 0.0
    return float(hi - lo) / slope / float(box.hi[0])


def strength_on(
    e: np.ndarray, o: np.ndarray, step: float, depth: float, grad: np.ndarray | None = None
) -> tuple[float, float | None]:
    """The ornament's strength s that moves the envelope's surface by about ``depth`` where
    the ornament is at its 10th or 90th percentile near that surface, and d = s * its median
    there, from the sampled envelope ``e`` and ornament ``o`` (grid step ``step``; ``grad``:
    ``e``'s :func:`~surfgen.generator.model.slope.gradient_norm` if already known). d is None
    when the ornament is constant or non-finite near the surface."""
    grad = gradient_norm(e, step) if grad is None else grad
    ok = np.isfinite(e) & np.isfinite(o) & np.isfinite(grad) & (grad > 0)
    band = ok & (np.abs(e) < 1.5 * step * np.where(ok, grad, 0.0))
    if np.count_nonzero(band) < 16:
        return 1.0, None
    lo, med, hi = quantiles(o[band], (0.1, 0.5, 0.9))
    spread = float(hi - lo)
    if not spread > 0 or not math.isfinite(spread):
        return 1.0, None
    slope = float(median(grad[band]))
    s = round_significant(depth * slope / spread, 3)
    if s == 0:
        return 1.0, None
    return s, round_significant(s * float(med), 6)
