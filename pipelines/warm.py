"""Imported once by each Dask worker's forkserver (:data:`surfgen.pipelines.cluster.PRELOAD`):
loads numba's cached kernels (evaluator, rasteriser) and pymeshlab, so that every shape
process forked from it starts warm, as the local executor's processes forked from a warm driver
do. Warming is only an optimisation: a failure is logged and the processes warm up on their own.
"""

from __future__ import annotations

import logging

log = logging.getLogger(__name__)


def warm_worker() -> None:
    """Evaluate, mesh, measure and render a tiny sphere once."""
    from surfgen.filters.verdict import shape_metrics
    from surfgen.generator.evaluate import evaluate
    from surfgen.generator.grid import Box, Grid
    from surfgen.generator.mesh import extract_mesh
    from surfgen.generator.parser import parse
    from surfgen.pipelines.pictures import render_image

    field = evaluate(parse("x^2+y^2+z^2-1"), Grid(Box.cube(1.5), (12, 12, 12)), threads=1)
    mesh = extract_mesh(field, 0.0, cap=True)
    shape_metrics(mesh, (-1.5, 1.5, -1.5, 1.5, -1.5, 1.5))
    render_image(mesh, size=16)


try:
    warm_worker()
except Exception:  # noqa: BLE001 - an optimisation must not stop the forkserver
    log.warning("could not warm the shape processes up", exc_info=True)
