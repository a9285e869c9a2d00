"""Benchmark: the cost of drawing sculptures (the ornament checks), this checkout against a
baseline revision, in one run.

Draws ``--n`` sculptures of ``--seed`` (``family = "sculpture"``, every other setting the
default of each checkout) in a child process per checkout and round, the checkouts taking turns
(``--rounds``), and prints per checkout the best round's milliseconds per sculpture drawn, the
ornaments tried per sculpture (from the structure each draw records) and milliseconds per
ornament tried, then the ratios new / baseline. The child warms the kernels on five draws of
other indices first. Shared machines are noisy: the ratios of one run are the figures to quote.

    python benchmarks/bench_draws.py [--n 150] [--seed 7] [--rounds 2] [--baseline REV]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_sample_grids import export_revision, run_code  # noqa: E402

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
    return run_code(path, _CHILD, n, seed)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=150)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--baseline", default=None, help="git revision to compare against")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        versions: dict[str, Path | None] = {"new": None}
        if args.baseline:
            versions = {"baseline": export_revision(args.baseline, Path(tmp)), "new": None}
        best: dict[str, dict] = {}
        for _ in range(args.rounds):
            for label, path in versions.items():
                r = run_child(path, args.n, args.seed)
                if label not in best or r["wall"] < best[label]["wall"]:
                    best[label] = r
    for label, r in best.items():
        per = 1000 * r["wall"] / r["n"]
        per_try = 1000 * r["wall"] / r["tries"]
        print(
            f"{label:<9} {per:6.1f} ms per sculpture  {r['tries'] / r['n']:.2f} ornaments "
            f"tried per sculpture  {per_try:5.1f} ms per ornament tried"
        )
    if "baseline" in best:
        b, a = best["baseline"], best["new"]
        print(
            f"ratio new/baseline: per sculpture x{a['wall'] / b['wall']:.2f}, per ornament "
            f"tried x{(a['wall'] / a['tries']) / (b['wall'] / b['tries']):.2f}"
        )


if __name__ == "__main__":
    main()
