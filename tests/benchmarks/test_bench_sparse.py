"""bench_sparse's runs: each child warms up every kernel its timed run calls, and measures the
run's own peak."""

from __future__ import annotations

import os

import pytest

from benchmarks import bench_sparse
from surfgen.generator.mesh import marching
from surfgen.generator.model.presets import PRESETS


def job(shape: str, grid: int, evaluator: str, walls: str | None = None) -> dict:
    preset = PRESETS[shape]
    return {"shape": shape, "spec": preset.spec().to_json(), "cap": preset.cap, "grid": grid,
            "evaluator": evaluator, "walls": walls}  # fmt: skip


#: Bytes the kernel's page counters may lag by: 3 counters (anon, file, shmem), each a batch
#: of max(32, 2 x CPUs) pages on every CPU (lib/percpu_counter.c): 768 KiB on two CPUs.
_CPUS = os.cpu_count() or 1
COUNTER_SLACK = 3 * max(32, 2 * _CPUS) * _CPUS * 4096


@pytest.mark.parametrize(
    ("shape", "grid", "walls"),
    # a small capped mesh; a large uncapped one, on every thread; render's walls
    [("eqA", 96, None), ("eqB", 128, None), ("eqC", 96, "keep")],
)
def test_the_warm_up_leaves_no_kernel_to_the_timed_run(shape: str, grid: int, walls) -> None:
    """A kernel first called inside the timed run is timed with its compile or its load from
    numba's cache (a 24^3 warm-up left seven to a 512^3 render); the peak is the run's, not
    the warm-up's (which compiles on an empty cache)."""
    sparse = bench_sparse.run_job(job(shape, grid, "sparse", walls))
    dense = bench_sparse.run_job(job(shape, grid, "fast", walls))
    assert sparse is not None and dense is not None
    for run in (sparse, dense):
        assert run["first_called"] == []
        # the floor memory_bound uses, within the kernel's counting: Linux (6.2 on) reads a
        # process's page counts from per-CPU counters that lag by up to a batch of 32 pages a
        # CPU (VmRSS and VmHWM alike), so where a run adds almost nothing (equation A at
        # 96^3: a 6.8 KB mesh) the peak read after it can be pages below the size read before
        assert run["rss0"] + run["mesh_bytes"] <= run["peak"] + COUNTER_SLACK
        assert run["mesh_bytes"] > run["faces"] * 3 * 8  # int64 faces, and the vertices
    if shape == "eqA":  # 96^3 adds a few MiB; the warm-up's 256^3 peaked 75-300 MiB higher
        assert sparse["peak"] - sparse["rss0"] < 40 << 20
        assert dense["peak"] - dense["rss0"] < 40 << 20
    assert sparse["hash"] == dense["hash"] and sparse["faces"] > 0


def test_the_kernels_are_found_with_their_signatures() -> None:
    """What the check reads: every numba kernel of surfgen's loaded modules, and the
    signatures it has so far."""
    found = bench_sparse.kernel_signatures()
    key = f"{marching.mixed_cells.py_func.__module__}.mixed_cells"
    assert key in found and found[key] == len(marching.mixed_cells.overloads)
    assert all(name.startswith("surfgen.") for name in found)


def test_the_memory_bound_is_the_dense_peak_over_the_process_and_its_mesh() -> None:
    """No run that returns a mesh can peak below the process it runs in plus that mesh: the
    bound is what the ratio of the peaks could reach at best."""
    mib = 1 << 20
    dense = {"peak": 1800 * mib}
    sparse = {"rss0": 200 * mib, "mesh_bytes": 25 * mib, "peak": 260 * mib}
    assert bench_sparse.memory_bound(dense, sparse) == pytest.approx(8.0)
    assert bench_sparse.memory_bound(dense, sparse) >= dense["peak"] / sparse["peak"]
