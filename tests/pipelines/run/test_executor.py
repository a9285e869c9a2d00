"""The killable worker pool: results, timeouts and crashes, and the run goes on."""

from __future__ import annotations

import os
import time

from surfgen.pipelines.run.executor import KillablePool


def work(task: int) -> int:
    if task == 3:
        time.sleep(30)  # overruns the pool's timeout
    if task == 5:
        os._exit(7)  # the worker process dies
    if task == 6:
        raise ValueError("a bug in one shape")
    return task * task


def test_results_timeouts_and_crashes() -> None:
    with KillablePool(work, workers=2, timeout=2.0) as pool:
        results = {r.task: r for r in pool.run(range(9))}
    assert sorted(results) == list(range(9))
    for t in (0, 1, 2, 4, 7, 8):
        assert results[t].status == "ok" and results[t].value == t * t
    assert results[3].status == "timeout" and "longer than 2 s" in results[3].message
    assert results[5].status == "crashed" and "exit code 7" in results[5].message
    assert results[6].status == "crashed" and "ValueError: a bug in one shape" in results[6].message


def test_one_worker_keeps_going_after_a_crash() -> None:
    with KillablePool(work, workers=1, timeout=5.0) as pool:
        statuses = [(r.task, r.status) for r in pool.run([5, 1, 2])]
    assert statuses == [(5, "crashed"), (1, "ok"), (2, "ok")]


def frozen(task: int) -> int:
    import gc

    return gc.get_freeze_count()


def test_a_forked_worker_leaves_what_it_inherited_out_of_its_collections() -> None:
    """The parent's heap (after a cold warm-up, the compiler's objects) is frozen in each
    worker: a full collection there would otherwise write to, and so copy, every page of it."""
    with KillablePool(frozen, workers=1, timeout=30.0) as pool:
        (result,) = list(pool.run([0]))
    assert result.status == "ok" and result.value > 1000


def heap_use(task: int) -> tuple[int, int]:
    """glibc's account (``mallinfo2``) of a 20 MiB array: the MiB mapped apart for it while it
    lives, and the MiB the heap grew by and still holds once it is freed."""
    import ctypes

    import numpy as np

    class Info(ctypes.Structure):
        _fields_ = [
            (name, ctypes.c_size_t)
            for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks")
            + ("fsmblks", "uordblks", "fordblks", "keepcost")
        ]

    info = ctypes.CDLL(None).mallinfo2
    info.restype = Info
    start = info()
    block = np.empty(20 << 17)  # 20 MiB of float64
    block.fill(1.0)
    mapped = (info().hblkhd - start.hblkhd) >> 20
    del block
    return mapped, (info().arena - start.arena) >> 20


def test_a_worker_keeps_the_memory_it_frees() -> None:
    """Each worker has glibc take blocks below 32 MiB from its heap and keep the heap it frees
    (``keep_freed_memory``): a shape's arrays reuse the pages of the last one's instead of
    mapping (and faulting in) fresh ones. A fresh process maps such a block apart and gives it
    back when it is freed."""
    import subprocess
    import sys

    probe = "from tests.pipelines.run.test_executor import heap_use; print(*heap_use(0))"
    plain = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    mapped, kept = (int(v) for v in plain.stdout.split())
    assert mapped >= 20 and kept < 20
    with KillablePool(heap_use, workers=1, timeout=60.0) as pool:
        (result,) = list(pool.run([0]))
    assert result.status == "ok"
    mapped, kept = result.value
    assert mapped == 0 and kept >= 20
