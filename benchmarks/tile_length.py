"""The interpreter's tile length (``tape.TILE_MAX``, points per W row) against time, in one run.

    python -m benchmarks.tile_length [--grid 128] [--formulas 50] [--tiles 512 1024 2048]

The 50 stored eq. (13) formulas (``tests/support/data/eq13_formulas.jsonl``), each evaluated
on one thread at every tile length in turn (best of ``--repeats`` rounds, interleaved, so a busy
moment hits them alike). Prints, per tile length, the median over the formulas of its time
divided by the first tile length's, and the total time. The fields are the same bits at every
tile length (every operation is elementwise; ``tests/generator/eval/test_tape.py`` checks it).
"""

from __future__ import annotations

import statistics

import numpy as np

from benchmarks import harness
from benchmarks.workloads import stored_eq13
from surfgen.generator.eval import tape
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.grid import Grid


def _with_tile(tile: int, program, grid: Grid):
    """One evaluation on one thread with ``tape.TILE_MAX = tile``, as a timed candidate."""

    def evaluate() -> None:
        tape.TILE_MAX = tile
        tape.evaluate_program(program, grid, threads=1)

    return evaluate


def main(argv: list[str] | None = None) -> None:
    parser = harness.parser(__doc__, repeats=3)
    parser.add_argument("--grid", type=int, default=128)
    parser.add_argument("--formulas", type=int, default=50)
    parser.add_argument("--tiles", type=int, nargs="+", default=[512, 1024, 2048])
    args = parser.parse_args(argv)
    run = harness.Run("tile_length", args)
    keep = tape.TILE_MAX
    tape.warm_up(parallel=False)  # the interpreter loaded (or compiled) before any timing
    programs = [
        (compile_tree(tree), Grid(box, (args.grid,) * 3))
        for tree, box in stored_eq13(args.formulas)
    ]
    times: dict[int, list[float]] = {t: [] for t in args.tiles}
    try:
        for program, grid in programs:
            timings = harness.take_turns(
                {tile: _with_tile(tile, program, grid) for tile in args.tiles}, args.repeats
            )
            for tile in args.tiles:
                times[tile].append(timings[tile].best)
    finally:
        tape.TILE_MAX = keep
    base = np.array(times[args.tiles[0]])
    run.say(f"{len(programs)} formulas at {args.grid}^3, 1 thread, best of {args.repeats}")
    for tile in args.tiles:
        ratio = np.array(times[tile]) / base
        run.say(
            f"TILE_MAX {tile:>5}: median time / TILE_MAX {args.tiles[0]}'s "
            f"{statistics.median(ratio):.3f} (quartiles {np.percentile(ratio, 25):.3f} / "
            f"{np.percentile(ratio, 75):.3f}), total {sum(times[tile]):.3f} s"
        )
    run.record(seconds_by_tile=times)
    run.save()


if __name__ == "__main__":
    main()
