"""The missing pictures of a catalogue (``surfgen thumbnails``, ``surfgen gallery -o``) drawn on
one process against all cores, on the same meshes in the same run.

    python -m benchmarks.picture_workers --catalogue out/catalogue [--n 200] [--rounds 2]

Takes the first ``--n`` accepted shapes of the catalogue and draws their turntables (12 views of
256², what ``gallery -o`` makes for each shape) with :func:`surfgen.pipelines.pictures.pool.
draw_all`, on one process and on ``--workers`` (default: every core), in turns (ABBA), in
memory (the catalogue is not changed). Prints the wall times, the ratio one process / all cores
and whether the PNG bytes are the same.
"""

from __future__ import annotations

import time
from pathlib import Path

from benchmarks import harness
from surfgen.pipelines.catalogue.curation import select_shapes
from surfgen.pipelines.catalogue.store import open_catalogue
from surfgen.pipelines.pictures.pool import Job, default_workers, draw_all


def _timed(jobs: list[Job], workers: int) -> tuple[float, dict[str, bytes]]:
    t0 = time.perf_counter()
    drawn = {d.job.key: d.pictures.get("turntable", b"") for d in draw_all(jobs, workers)}
    return time.perf_counter() - t0, drawn


def main(argv: list[str] | None = None) -> int:
    ap = harness.parser(__doc__)
    ap.add_argument("--catalogue", type=Path, default=Path("out/catalogue"))
    ap.add_argument("--n", type=int, default=200, help="shapes (the first accepted ones)")
    ap.add_argument("--workers", type=int, default=default_workers())
    ap.add_argument("--rounds", type=int, default=2, help="ABBA rounds")
    args = ap.parse_args(argv)
    run = harness.Run("picture_workers", args)

    with open_catalogue(args.catalogue, must_exist=True, readonly=True) as cat:
        shapes = [s for s in select_shapes(cat) if s["mesh"]][: args.n]
        jobs = [Job(s["key"], str(cat.root / s["mesh"]), ("turntable",)) for s in shapes]
    _timed(jobs[:1], 1)  # the renderer's kernels loaded before either is timed
    run.say(f"{len(jobs)} turntables from {args.catalogue}")
    times: dict[int, list[float]] = {1: [], args.workers: []}
    results = {}
    for r in range(args.rounds):
        order = [1, args.workers] if r % 2 == 0 else [args.workers, 1]
        for w in order:
            seconds, results[w] = _timed(jobs, w)
            times[w].append(seconds)
            run.say(f"  round {r + 1}: {w} process{'es' if w > 1 else ''}: {seconds:.1f} s")
    one, many = min(times[1]), min(times[args.workers])
    run.say(
        f"best of {args.rounds}: 1 process {one:.1f} s ({one / len(jobs) * 1000:.0f} ms per "
        f"turntable), {args.workers} processes {many:.1f} s: {one / many:.2f}x; "
        f"the same PNG bytes: {results[1] == results[args.workers]}"
    )
    run.record(
        seconds={str(w): t for w, t in times.items()},
        shapes=len(jobs),
        same_png=results[1] == results[args.workers],
    )
    run.save()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
