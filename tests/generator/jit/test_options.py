"""read_only: one compiled signature for a kernel whose callers hold writable or read-only
arrays, without a copy."""

from __future__ import annotations

import numba
import numpy as np

from surfgen.generator.jit.options import read_only


def test_read_only_is_a_view_or_the_array_itself() -> None:
    a = np.arange(12.0).reshape(3, 4)
    view = read_only(a)
    assert not view.flags.writeable and np.shares_memory(view, a) and a.flags.writeable
    assert read_only(view) is view
    assert numba.typeof(view) == numba.typeof(read_only(a.copy()))
    assert not numba.typeof(view).mutable and numba.typeof(a).mutable
