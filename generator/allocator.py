"""A process's memory policy: keep freed memory, or give it back (and no huge-page stalls).

glibc's ``malloc`` maps a block above its *mmap threshold* apart and unmaps it when freed;
smaller blocks come from the heap, whose freed memory it keeps unless the heap's top has more
than the *trim threshold* free.  Both thresholds start at 128 KiB and the mmap threshold then
follows the largest block freed (up to 32 MiB), so a process that frees a 20 MiB array takes its
next ones of that size from the heap, and keeps them mapped after they are freed.

Two kinds of process want the opposite policies:

* a sampler's worker (:func:`keep_freed_memory`) makes and frees arrays of a few MiB for every
  shape: keeping freed memory saves their pages faulting in again;
* a one-shot command on a fine grid (:func:`one_shot_memory_policy`: ``render``, ``export``)
  makes each step's arrays once: what it frees should leave its resident size, which is the
  process's peak, at once (a 512^3 sparse render: a quarter of what it adds, measured), and
  its fresh arrays should not stall for huge pages (below). Within such a command, a loop
  that makes and frees the same small arrays again and again (the sparse evaluator's columns)
  runs under the first policy for its duration (:func:`scratch_kept`), and a step's new array
  may take the memory of an array done with, its pages already there (:func:`recycled`).

Both return whether the allocator took the settings (glibc's; other C libraries are left as
they are).  ``numpy`` and numba's runtime allocate through ``malloc``: both follow the policy.

A one-shot command also stops numpy from asking for huge pages
(:func:`no_huge_page_stalls`): numpy advises the kernel to back every array of 4 MiB or more
with transparent huge pages (``madvise(MADV_HUGEPAGE)``), and where the kernel's THP *defrag*
setting makes such a fault compact memory on the spot (``always``, ``madvise``), the first
touch of a fresh array stalls.  On the project's 2-core VMs (defrag ``madvise``), touching
1 GiB of fresh arrays took 0.37-0.44 s with the advice off and 0.18-3.0 s with it on (median
0.59 s: huge pages when the kernel has them at hand, stalls when it must compact; fresh
processes in turns, ``python -m benchmarks.huge_pages``).  The sampler's workers, whose arrays
are small and reused, are unaffected (the same 35 s for 400 shapes either way).
"""

from __future__ import annotations

import contextlib
import ctypes
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np

# glibc's mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
HEAP_BELOW = 32 << 20  # bytes: smaller blocks from the heap (glibc's largest mmap threshold)
KEEP_FREED = 1 << 30  # bytes of freed heap kept for the next blocks, not given back
GIVE_BACK_FROM = 128 << 10  # bytes: glibc's own starting thresholds, then held fixed
_KEEP = ((_M_MMAP_THRESHOLD, HEAP_BELOW), (_M_TRIM_THRESHOLD, KEEP_FREED))
_GIVE_BACK = ((_M_MMAP_THRESHOLD, GIVE_BACK_FROM), (_M_TRIM_THRESHOLD, GIVE_BACK_FROM))


# Whether this process gives freed memory back (:func:`one_shot_memory_policy` took effect).
_giving_back = False


def _mallopt(settings: tuple[tuple[int, int], ...]) -> bool:
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError, TypeError):  # no C library by that name (Windows: None)
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return all([mallopt(param, value) == 1 for param, value in settings])  # every one set


def keep_freed_memory() -> bool:
    """Have this process's C allocator keep the memory it frees for the next allocations.

    A worker makes and frees arrays of a few MiB for every shape (fields, bricks, meshes,
    picture buffers). glibc maps a block above its mmap threshold afresh and unmaps it when
    freed, so every page of the next such array faults again when first written: about 170 000
    page faults per 400 shapes, 1.5-2 % of a worker's time on a 2-core Zen 4 (measured). Blocks
    below :data:`HEAP_BELOW` then come from the heap, and up to :data:`KEEP_FREED` of freed heap
    stays mapped: a worker's resident size stays near its peak (the shapes' largest arrays),
    which it reaches anyway."""
    return _mallopt(_KEEP)


def one_shot_memory_policy() -> bool:
    """Have this process's C allocator give what it frees back to the system at once, and
    numpy's large arrays not stall for huge pages (:func:`no_huge_page_stalls`).

    Blocks from :data:`GIVE_BACK_FROM` up are mapped apart (and unmapped when freed) and the
    heap is trimmed beyond as much free memory, both held there rather than following the
    largest block freed: a command whose steps each make large arrays once (the field's bricks,
    the cells, the mesh's runs, joined, placed and grouped) then holds at its peak what the
    step alive at that moment holds, not also what the earlier steps freed into the heap, and
    its worker threads' heaps."""
    global _giving_back
    no_huge_page_stalls()
    _giving_back = _mallopt(_GIVE_BACK)
    return _giving_back


@contextlib.contextmanager
def scratch_kept() -> Iterator[None]:
    """Within: freed memory kept for the next blocks (:func:`keep_freed_memory`'s thresholds),
    then :func:`one_shot_memory_policy`'s again and the heap given back (``malloc_trim``), where
    that policy is in force (elsewhere nothing changes).

    For a loop that makes and frees the same temporaries again and again: the sparse
    evaluator's groups of columns, whose output, stores and scratch (up to about 1 MiB each at
    512^3) the one-shot policy maps and unmaps afresh for every group — measured when each
    column was its own grid: 13,000 page faults, 15-30 ms of a 0.37 s render of a sculpture at
    512^3 (sampling 0.14-0.15 s -> 0.12 s; the same peak: the heap grows by a group's
    temporaries per thread, and is trimmed after). Blocks allocated
    before the window (the bricks' array) are not affected; what is allocated within and
    outlives it stays in the heap (keep such arrays out of the window)."""
    if not _giving_back:
        yield
        return
    _mallopt(_KEEP)
    try:
        yield
    finally:
        _mallopt(_GIVE_BACK)
        _trim()


#: Bytes between the starts of the arrays :func:`recycled_many` makes on one block (a cache line).
ALIGN = 64


def recycled(held: list[np.ndarray], shape: tuple[int, ...], dtype) -> np.ndarray:
    """An array of ``shape`` and ``dtype`` (its contents undefined) on the memory of the last
    array in ``held``, taken out of the list, where it fits (:func:`recycled_many`)."""
    return recycled_many(held, [(shape, dtype)])[0]


def recycled_many(held: list[np.ndarray], specs) -> list[np.ndarray]:
    """Arrays ``[(shape, dtype), ...]`` (their contents undefined) on the memory of the last
    array in ``held``, taken out of the list: under :func:`one_shot_memory_policy`, a step's
    new arrays take an array that is done with instead of freeing it and mapping fresh blocks,
    whose every page would fault on first write. Those that fit in it, in order, are laid one
    after the other (each from a multiple of :data:`ALIGN` bytes), and the block is shrunk to
    them (numpy's in-place ``resize``: glibc's ``realloc`` of a mapped block keeps the pages it
    keeps, without copying them, and unmaps the rest); the others are fresh. A block is never
    grown: numpy would zero the new part on one thread, which costs what the faults on the
    threads that write the arrays would (measured). The sparse path's cells take the bricks'
    samples, the marching's runs the offsets, the joined vertices the cells, the placement's
    edges the runs.

    A view is replaced by the array it views. Anything else holding that array (numpy's
    reference check: another name, a view, a weak reference), memory it does not own (numba's
    arrays), an empty ``held``, or a process that keeps its freed memory (where a fresh array
    comes from the heap, without faults) gives fresh arrays only."""
    dead = held.pop() if held else None
    owner = dead if dead is None or dead.base is None else dead.base
    del dead
    sizes = [int(np.prod(shape)) * np.dtype(dtype).itemsize for shape, dtype in specs]
    room = owner.nbytes if _giving_back and isinstance(owner, np.ndarray) else 0
    starts: list[int | None] = []
    used = 0
    for n in sizes:
        step = -(-n // ALIGN) * ALIGN
        fits = n > 0 and used + step <= room
        starts.append(used if fits else None)
        used += step if fits else 0
    if used:
        try:
            owner.resize((used // owner.itemsize,))  # refcheck: nothing else holds it
        except (ValueError, SystemError):  # held elsewhere, or not its own memory
            starts = [None] * len(specs)
    raw = owner.view(np.uint8) if any(start is not None for start in starts) else None
    del owner
    return [
        np.empty(shape, dtype=dtype)
        if start is None
        else raw[start : start + n].view(dtype).reshape(shape)
        for (shape, dtype), start, n in zip(specs, starts, sizes, strict=True)
    ]


def _trim() -> None:
    """Give the heap's free memory back to the system (glibc's ``malloc_trim``, every arena)."""
    try:
        trim = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError, TypeError):
        return
    trim.argtypes, trim.restype = (ctypes.c_size_t,), ctypes.c_int
    trim(0)


#: The kernel's transparent huge page defrag setting (the bracketed word).
THP_DEFRAG = Path("/sys/kernel/mm/transparent_hugepage/defrag")
#: Defrag settings under which a fault in a region advised for huge pages compacts memory
#: synchronously (the kernel's admin-guide/mm/transhuge).
STALLING_DEFRAG = ("always", "madvise", "defer+madvise")


def thp_defrag(path: Path = THP_DEFRAG) -> str | None:
    """The kernel's THP defrag setting (``madvise``, ``defer``...), or None where unknown."""
    try:
        text = path.read_text()
    except OSError:
        return None
    start, end = text.find("["), text.find("]")
    return text[start + 1 : end] if 0 <= start < end else None


def numpy_huge_page_advice(enabled: bool) -> bool | None:
    """Turn numpy's huge-page advice for its large arrays on or off; returns what it was, or
    None where this numpy has no such switch (then nothing changed)."""
    core = getattr(np, "_core", None) or np.core  # numpy 2 / 1.26
    setter = getattr(core.multiarray, "_set_madvise_hugepage", None)
    return None if setter is None else bool(setter(enabled))


def no_huge_page_stalls(path: Path = THP_DEFRAG) -> bool:
    """Stop numpy advising huge pages for its large arrays where the kernel would compact
    memory synchronously to honour the advice (:data:`STALLING_DEFRAG`; the module's
    docstring), unless the user chose with ``NUMPY_MADVISE_HUGEPAGE``.  Returns whether the
    advice is now off."""
    if "NUMPY_MADVISE_HUGEPAGE" in os.environ or thp_defrag(path) not in STALLING_DEFRAG:
        return False
    return numpy_huge_page_advice(False) is not None
