"""Imported once by each Dask worker's forkserver (:data:`surfgen.pipelines.run.cluster.PRELOAD`):
loads numba's cached kernels and pymeshlab (:func:`surfgen.pipelines.run.warmup.warm_shape_kernels`),
so that every shape process forked from it starts warm, as the local executor's processes
forked from the warmed driver do. Warming is only an optimisation here: a failure is logged and
the processes warm up on their own.
"""

from __future__ import annotations

import logging

from surfgen.pipelines.run.warmup import warm_shape_kernels

log = logging.getLogger(__name__)

try:
    warm_shape_kernels()
except Exception:  # noqa: BLE001 - an optimisation must not stop the forkserver
    log.warning("could not warm the shape processes up", exc_info=True)
