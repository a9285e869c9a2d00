"""Arrays grown as a kernel fills them: :func:`grown`, for the sparse passes and the marching
(:mod:`~surfgen.generator.mesh.sparse_lewiner`, :mod:`~surfgen.generator.mesh.sparse_bricks`,
:mod:`~surfgen.generator.mesh.marching`, :mod:`~surfgen.generator.mesh.raise_table`)."""

from __future__ import annotations

import numpy as np
from numba import njit

from surfgen.generator.jit.options import KERNEL


@njit(**KERNEL)
def grown(a, n, more):
    """``a`` (rows ``:n`` used) moved to an array half as large again, room for ``more`` (the
    marching's arrays, the scan's lists, the raises' worklist).  Pass ``n`` and ``more`` as
    int64 values, never literals: numba would compile it again per literal."""
    out = np.empty((a.shape[0] + a.shape[0] // 2 + more,) + a.shape[1:], dtype=a.dtype)
    # element by element: a slice copy would compile numba's shape error (1-2 s)
    width = a.size // a.shape[0] if a.shape[0] else 0
    flat_a, flat_out = a.reshape(-1), out.reshape(-1)
    for i in range(n * width):
        flat_out[i] = flat_a[i]
    return out
