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


def marked(task: int) -> str:
    return os.environ.get("SURFGEN_TEST_KEPT", "")


def test_every_worker_keeps_the_memory_it_frees(monkeypatch) -> None:
    """Each worker calls ``keep_freed_memory`` before its first task (seen through a stand-in
    the forked worker inherits)."""
    from surfgen.pipelines.run import executor

    def stand_in() -> bool:
        os.environ["SURFGEN_TEST_KEPT"] = f"kept in {os.getpid()}"
        return True

    monkeypatch.setattr(executor, "keep_freed_memory", stand_in)
    with KillablePool(marked, workers=2, timeout=60.0) as pool:
        results = list(pool.run([0, 1]))
    assert all(r.status == "ok" and r.value.startswith("kept in ") for r in results)
    assert all(r.value != f"kept in {os.getpid()}" for r in results)
    assert "SURFGEN_TEST_KEPT" not in os.environ  # set in the workers only
