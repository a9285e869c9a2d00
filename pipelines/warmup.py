"""Load (or compile, the first time on a machine) every numba kernel a shape goes through.

The sampling driver calls :func:`warm_shape_kernels` before it forks its workers, so they
start with the kernels in memory: on a fresh checkout, compiling them took a worker a minute
or more, longer than a shape's ``timeout`` on a loaded machine, and the first shapes were then
rejected as ``timeout`` — a catalogue that depended on the cache. Dask's shape processes get
the same through :mod:`surfgen.pipelines.warm`, imported by their forkserver.
"""

from __future__ import annotations

import logging
import time

import numpy as np

log = logging.getLogger(__name__)

# A small ball with a pole inside the box (so the walls' classification runs its kernel) and
# one cut by the box (caps).
WARM_FORMULA = "x^2 + y^2 + z^2 - 1 + 0.02*tan(2*x + 0.3)"


def warm_shape_kernels() -> float:
    """Evaluate, mesh, classify, measure, describe and draw a tiny shape once; returns the
    seconds it took."""
    from surfgen.filters.descriptor import descriptor
    from surfgen.filters.shape import quality_metrics
    from surfgen.filters.verdict import quick_metrics, shape_metrics
    from surfgen.generator.evaluate import evaluate
    from surfgen.generator.families import envelope_departure, pieces
    from surfgen.generator.grid import Box, Field, Grid
    from surfgen.generator.mesh import _merge_same, extract_with_edges
    from surfgen.generator.parser import parse
    from surfgen.generator.walls import label_walls
    from surfgen.pipelines.pictures import render_image

    t0 = time.perf_counter()
    tree = parse(WARM_FORMULA)
    box = Box.cube(1.1)
    field = evaluate(tree, Grid(box, (14, 14, 14)), threads=1)
    mesh, edges = extract_with_edges(field, 0.0, cap=True)
    label_walls(mesh, edges, field, tree, {}, 0.0, True, "keep")
    quick = quick_metrics(mesh, box.bounds())
    quality_metrics(mesh, shape_metrics(mesh, box.bounds(), quick=quick))
    descriptor(mesh)
    render_image(mesh, size=16)
    # read-only fields (the sampler's) and a carved copy (the ornament checks'): two signatures
    envelope_departure(field.values, field.values)
    envelope_departure(field.values + 0.0, field.values)
    pieces(field.values)
    # Kernels only some shapes run: vertices of one grid edge given one index (a crossing on a
    # box edge of a capped shape, an ambiguous cell), and non-finite samples (a pole on a
    # sample) given an offset from their neighbours; the warm ball has neither.
    _merge_same(np.zeros((3, 3)), np.array([[0, 1, 2]], dtype=np.int64), np.arange(3))
    holed = field.values.copy()
    holed[7, 7, 7] = np.nan
    extract_with_edges(Field(field.grid, holed), 0.0, cap=True)  # read-only, as the sampler's
    seconds = time.perf_counter() - t0
    log.debug("shape kernels ready in %.2f s", seconds)
    return seconds
