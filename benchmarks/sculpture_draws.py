"""Benchmark: the cost of drawing sculptures (the ornament checks), this checkout against a
baseline revision, in one run.

Draws ``--n`` sculptures of ``--seed`` (``family = "sculpture"``, every other setting the
default of each checkout) in a child process per checkout and round, the checkouts taking turns
(``--rounds``), and prints per checkout the best round's milliseconds per sculpture drawn, the
ornaments tried per sculpture (from the structure each draw records) and milliseconds per
ornament tried, then the ratios. The child warms the kernels on five draws of
other indices first. Ratios are baseline / now (above 1: this checkout is faster). Shared
machines are noisy: the ratios of one run are the figures to quote.

    python -m benchmarks.sculpture_draws [--n 150] [--seed 7] [--rounds 2] [--baseline REV]
"""

from __future__ import annotations

from pathlib import Path

from benchmarks import harness

_CHILD = """
import json, sys, time
from dataclasses import replace
from surfgen.generator.model import sampler
from surfgen.generator.model.sampler import SamplerConfig, draw_equation
n, seed = int(sys.argv[1]), int(sys.argv[2])
cfg = replace(SamplerConfig(), family="sculpture")
for i in range(5):
    draw_equation(seed, 100_000 + i, cfg)
t = time.perf_counter()
tries = 0
for i in range(n):
    draw = draw_equation(seed, i, cfg)
    tries += draw.structure["ornament"].get("tries", 1)
wall = time.perf_counter() - t
print(json.dumps({"code": sampler.__file__, "wall": wall, "n": n, "tries": tries}))
"""


def run_child(path: Path | None, n: int, seed: int) -> dict:
    """Draw ``n`` sculptures in a child process with the code at ``path`` (None: this one)."""
    return harness.run_child(path, _CHILD, n, seed)


def main(argv: list[str] | None = None) -> None:
    ap = harness.parser(__doc__, baseline="optional")
    ap.add_argument("--n", type=int, default=150)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args(argv)
    run = harness.Run("sculpture_draws", args)
    with harness.revisions(args.baseline) as versions:
        best: dict[str, dict] = {}
        for _ in range(args.rounds):
            for label, path in versions.items():
                r = run_child(path, args.n, args.seed)
                if label not in best or r["wall"] < best[label]["wall"]:
                    best[label] = r
    for label, r in best.items():
        per = 1000 * r["wall"] / r["n"]
        per_try = 1000 * r["wall"] / r["tries"]
        run.say(
            f"{label:<9} {per:6.1f} ms per sculpture  {r['tries'] / r['n']:.2f} ornaments "
            f"tried per sculpture  {per_try:5.1f} ms per ornament tried"
        )
    if "baseline" in best:
        b, a = best["baseline"], best["now"]
        per_try = harness.ratio(b["wall"] / b["tries"], a["wall"] / a["tries"])
        run.say(
            f"ratio baseline / now: per sculpture x{harness.ratio(b['wall'], a['wall']):.2f}, "
            f"per ornament tried x{per_try:.2f}"
        )
    run.record(best=best)
    run.save()


if __name__ == "__main__":
    main()
