"""The Dask executor against the local one, in one run, and what limits scale.

    python -m benchmarks.dask_executor [--n 60] [--seed 7] [--workers 2] [--grid 64] [--repeats 2]

1. The same sampling run (same seed, options and config) with the local executor and with a
   ``LocalCluster`` of as many worker processes: accepted shapes per minute, with and without
   the cluster's start-up, as a ratio against the local run (the baseline of this script); the
   two catalogues must be identical.
2. The driver's limits, which do not grow with the cluster: how many accepted shapes per second
   one driver can stage and commit (files handed back as bytes, written and renamed, one SQLite
   transaction each), the bytes per accepted shape that cross the network, and the scheduler's
   cost per chunk (a round trip of empty tasks).

The machine is shared: times are noisy, the ratios are what to quote.
"""

from __future__ import annotations

import json
import os
import sqlite3
import tempfile
import time
from collections import Counter
from pathlib import Path

from benchmarks import harness
from surfgen.filters.verdict import Verdict
from surfgen.generator.eval.tape import warm_up
from surfgen.pipelines.catalogue.store import open_catalogue
from surfgen.pipelines.run.config import load_config
from surfgen.pipelines.run.sampling import _commit, _stage, run_sample
from surfgen.pipelines.run.shapes import ShapeOutcome


def table(root: Path) -> list[tuple]:
    con = sqlite3.connect(root / "catalogue.sqlite")
    rows = con.execute(
        "SELECT idx, key, spec, metrics, verdict, reasons FROM shapes ORDER BY idx"
    ).fetchall()
    con.close()
    return rows


def timed_run(executor: str, args, config, out: Path) -> dict[str, float]:
    """One sampling run with ``executor``: seconds, time to the first commit, shapes/min."""
    marks: list[float] = []
    start = time.perf_counter()
    s = run_sample(
        n=args.n,
        seed=args.seed,
        config=config,
        catalogue=out,
        workers=args.workers,
        executor=executor,
        progress=lambda a, d, n: marks.append(time.perf_counter()),
    )
    total = time.perf_counter() - start
    first = marks[0] - start
    steady = (marks[-1] - marks[0]) or 1e-9
    return {
        "seconds": total,
        "to_first_commit": first,
        "per_minute": 60 * s.accepted / total,
        # from the first commit on: the cluster is up and the workers are warm
        "steady_per_minute": 60 * (s.accepted - 1) / steady,
        "drawn": s.drawn,
    }


def driver_commit_rate(catalogue: Path, repeats: int = 200) -> tuple[float, float]:
    """Accepted shapes per second one driver stages (bytes -> file) and commits, using the
    real files of ``catalogue``; and the mean bytes per accepted shape."""
    with open_catalogue(catalogue, must_exist=True) as cat:
        rows = cat.shapes(verdict="accepted")
    payloads = []
    for r in rows:
        data = [("mesh_file", (catalogue / r["mesh_path"]).read_bytes())]
        for col, name in (("thumb_path", "thumb_file"), ("turntable_path", "turntable_file")):
            if r[col]:
                data.append((name, (catalogue / r[col]).read_bytes()))
        row = {k: r[k] for k in ("spec", "formula", "identity", "verdict", "reasons", "metrics")}
        payloads.append((row, tuple(data)))
    size = sum(len(b) for _, data in payloads for _, b in data) / len(payloads)
    with tempfile.TemporaryDirectory() as tmp, open_catalogue(Path(tmp) / "c") as cat:
        cat.make_dirs()
        run = cat.create_run(0, repeats, 64, {}, "bench", 1, {})
        staging = cat.root / ".staging"
        staging.mkdir()
        counts: Counter[str] = Counter()
        start = time.perf_counter()
        for i in range(repeats):
            row, data = payloads[i % len(payloads)]
            row = dict(row, key=f"{i:016x}")
            out = _stage(ShapeOutcome(i, row, Verdict(True), data=data), staging)
            _commit(cat, run.id, out, counts)
        seconds = time.perf_counter() - start
    return repeats / seconds, size


def chunk_overhead(workers: int, tasks: int = 200) -> float:
    """Seconds per empty task round trip on a LocalCluster (what one chunk costs the scheduler)."""
    import distributed  # deferred: the optional dask extra, needed only here

    with (
        distributed.LocalCluster(
            n_workers=workers, threads_per_worker=1, host="127.0.0.1", dashboard_address=None
        ) as c,
        distributed.Client(c) as client,
    ):
        client.gather(client.map(abs, range(20)))  # warm
        start = time.perf_counter()
        client.gather(client.map(abs, range(-tasks, 0)))
        return (time.perf_counter() - start) / tasks


def main(argv: list[str] | None = None) -> None:
    p = harness.parser(__doc__, repeats=2)
    p.add_argument("--n", type=int, default=60)
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--workers", type=int, default=os.cpu_count() or 2)
    p.add_argument("--grid", type=int, default=64)
    args = p.parse_args(argv)
    run = harness.Run("dask_executor", args)
    config = load_config().with_grid(args.grid)
    warm_up(parallel=False)
    runs: dict[str, list[dict[str, float]]] = {"local": [], "dask": []}
    with tempfile.TemporaryDirectory() as tmp:
        # Alternate the executors, so that a change in the machine's load hits both alike.
        for r in range(args.repeats):
            for executor in runs:
                runs[executor].append(
                    timed_run(executor, args, config, Path(tmp) / f"{executor}{r}")
                )
        same = table(Path(tmp) / "local0") == table(Path(tmp) / "dask0")
        commits, size = driver_commit_rate(Path(tmp) / "local0")
    local, dask = (max(runs[e], key=lambda x: x["per_minute"]) for e in ("local", "dask"))
    overhead = chunk_overhead(args.workers)
    out = {
        "n": args.n,
        "grid": args.grid,
        "workers": args.workers,
        "drawn": local["drawn"],
        "repeats": args.repeats,
        "identical_catalogues": same,
        "local_per_minute": round(local["per_minute"], 1),
        "dask_per_minute": round(dask["per_minute"], 1),
        "dask_over_local": round(dask["per_minute"] / local["per_minute"], 3),
        "local_steady_per_minute": round(local["steady_per_minute"], 1),
        "dask_steady_per_minute": round(dask["steady_per_minute"], 1),
        "dask_over_local_steady": round(dask["steady_per_minute"] / local["steady_per_minute"], 3),
        "dask_seconds_to_first_commit": round(dask["to_first_commit"], 1),
        "local_seconds_to_first_commit": round(local["to_first_commit"], 1),
        "driver_commits_per_second": round(commits, 1),
        "bytes_per_accepted_shape": int(size),
        "accepted_per_second_at_1_gbit": round(125e6 / size, 1),
        "scheduler_seconds_per_chunk": round(overhead, 5),
    }
    run.say(json.dumps(out, indent=2))
    run.record(**out)
    per_core = local["steady_per_minute"] / 60 / args.workers
    run.say(
        f"one core makes {per_core:.2f} accepted shapes/s here: one driver's commits saturate at "
        f"about {commits / per_core:.0f} cores, a 1 Gbit/s link at about "
        f"{125e6 / size / per_core:.0f} cores"
    )
    run.save()


if __name__ == "__main__":
    main()
