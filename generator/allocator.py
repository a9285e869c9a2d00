"""The C allocator's policy for a process: keep freed memory, or give it back.

glibc's ``malloc`` maps a block above its *mmap threshold* apart and unmaps it when freed;
smaller blocks come from the heap, whose freed memory it keeps unless the heap's top has more
than the *trim threshold* free.  Both thresholds start at 128 KiB and the mmap threshold then
follows the largest block freed (up to 32 MiB), so a process that frees a 20 MiB array takes its
next ones of that size from the heap, and keeps them mapped after they are freed.

Two kinds of process want the opposite policies:

* a sampler's worker (:func:`keep_freed_memory`) makes and frees arrays of a few MiB for every
  shape: keeping freed memory saves their pages faulting in again;
* a one-shot command on a fine grid (:func:`give_back_freed_memory`: ``render``, ``export``)
  makes each step's arrays once: what it frees should leave its resident size, which is the
  process's peak, at once (a 512^3 sparse render: a quarter of what it adds, measured).

Both return whether the allocator took the settings (glibc's; other C libraries are left as
they are).  ``numpy`` and numba's runtime allocate through ``malloc``: both follow the policy.
"""

from __future__ import annotations

import ctypes

# glibc's mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
HEAP_BELOW = 32 << 20  # bytes: smaller blocks from the heap (glibc's largest mmap threshold)
KEEP_FREED = 1 << 30  # bytes of freed heap kept for the next blocks, not given back
GIVE_BACK_FROM = 128 << 10  # bytes: glibc's own starting thresholds, then held fixed


def _mallopt(settings: tuple[tuple[int, int], ...]) -> bool:
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError, TypeError):  # no C library by that name (Windows: None)
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return all([mallopt(param, value) == 1 for param, value in settings])


def keep_freed_memory() -> bool:
    """Have this process's C allocator keep the memory it frees for the next allocations.

    A worker makes and frees arrays of a few MiB for every shape (fields, bricks, meshes,
    picture buffers). glibc maps a block above its mmap threshold afresh and unmaps it when
    freed, so every page of the next such array faults again when first written: about 170 000
    page faults per 400 shapes, 1.5-2 % of a worker's time on a 2-core Zen 4 (measured). Blocks
    below :data:`HEAP_BELOW` then come from the heap, and up to :data:`KEEP_FREED` of freed heap
    stays mapped: a worker's resident size stays near its peak (the shapes' largest arrays),
    which it reaches anyway."""
    return _mallopt(((_M_MMAP_THRESHOLD, HEAP_BELOW), (_M_TRIM_THRESHOLD, KEEP_FREED)))


def give_back_freed_memory() -> bool:
    """Have this process's C allocator give what it frees back to the system at once.

    Blocks from :data:`GIVE_BACK_FROM` up are mapped apart (and unmapped when freed) and the
    heap is trimmed beyond as much free memory, both held there rather than following the
    largest block freed: a command whose steps each make large arrays once (the field's bricks,
    the cells, the mesh's runs, joined, placed and grouped) then holds at its peak what the
    step alive at that moment holds, not also what the earlier steps freed into the heap, and
    its worker threads' heaps."""
    return _mallopt(((_M_MMAP_THRESHOLD, GIVE_BACK_FROM), (_M_TRIM_THRESHOLD, GIVE_BACK_FROM)))
