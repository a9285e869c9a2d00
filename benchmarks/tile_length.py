"""The interpreter's tile length (``fast.TILE_MAX``, points per W row) against time, in one run.

    python benchmarks/bench_tiles.py [--grid 128] [--formulas 50] [--tiles 512 1024 2048]

The 50 stored eq. (13) formulas (``tests/support/data/eq13_formulas.jsonl``), each evaluated
on one thread at every tile length in turn (best of ``--repeat`` rounds, interleaved, so a busy
moment hits them alike). Prints, per tile length, the median over the formulas of its time
divided by the first tile length's, and the total time. The fields are the same bits at every
tile length (every operation is elementwise; ``tests/generator/test_fast.py`` checks it).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import surfgen.generator.eval.tape as fast
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.grid import Grid

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_eval import stored_eq13  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", type=int, default=128)
    parser.add_argument("--formulas", type=int, default=50)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--tiles", type=int, nargs="+", default=[512, 1024, 2048])
    args = parser.parse_args()
    keep = fast.TILE_MAX
    programs = [
        (compile_tree(tree), Grid(box, (args.grid,) * 3))
        for tree, box in stored_eq13(args.formulas)
    ]
    times: dict[int, list[float]] = {t: [] for t in args.tiles}
    try:
        for program, grid in programs:
            best = dict.fromkeys(args.tiles, float("inf"))
            for _ in range(args.repeat):
                for tile in args.tiles:
                    fast.TILE_MAX = tile
                    start = time.perf_counter()
                    fast.evaluate_program(program, grid, threads=1)
                    best[tile] = min(best[tile], time.perf_counter() - start)
            for tile in args.tiles:
                times[tile].append(best[tile])
    finally:
        fast.TILE_MAX = keep
    base = np.array(times[args.tiles[0]])
    print(f"{len(programs)} formulas at {args.grid}^3, 1 thread, best of {args.repeat}")
    for tile in args.tiles:
        ratio = np.array(times[tile]) / base
        print(
            f"TILE_MAX {tile:>5}: median time / TILE_MAX {args.tiles[0]}'s "
            f"{statistics.median(ratio):.3f} (quartiles {np.percentile(ratio, 25):.3f} / "
            f"{np.percentile(ratio, 75):.3f}), total {sum(times[tile]):.3f} s"
        )


if __name__ == "__main__":
    main()
