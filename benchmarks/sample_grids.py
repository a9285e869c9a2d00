"""Throughput of `surfgen sample` across grids, before and after, in one run.

    python benchmarks/bench_sample_grids.py [--grids 48 64 96 128] [--n 6 6 4 3] [--seed 7]
        [--workers 2] [--baseline REV] [--repeats 1]

For every grid it runs ``sample --n N --seed S`` (default config, thumbnails on) with the code
of this checkout and, with ``--baseline REV`` (a git revision, e.g. ``main``), with the code of
that revision exported into a temporary folder; both run as child processes, interleaved grid by
grid so a change in the machine's load hits both alike. It prints accepted shapes per minute,
the acceptance rate, worker seconds per accepted shape by stage, and the ratio new / baseline.

Each version first samples one shape at a tiny grid so numba's compilation (cached per code
folder) is not timed. The machine this project is developed on is shared: read the ratios,
not the absolute figures. Without ``--baseline`` only this checkout is measured, and
"grid cost" (worker seconds per accepted shape / grid points, relative to the first grid) shows
whether the cost grows linearly with the grid.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("generator", "filters", "pipelines")

_CHILD = r"""
import json, sys, tempfile, time
from pathlib import Path
import surfgen.pipelines.run.sampling as sampling
from surfgen.pipelines.run.config import load_config
n, seed, grid, workers = (int(a) for a in sys.argv[1:5])
config = load_config().with_grid(grid).with_run(timeout=3600.0)
with tempfile.TemporaryDirectory() as tmp:
    t = time.perf_counter()
    s = sampling.run_sample(n=n, seed=seed, config=config, catalogue=Path(tmp) / "cat",
                            workers=workers)
    wall = time.perf_counter() - t
print(json.dumps({"code": sampling.__file__, "wall": wall, "accepted": s.accepted,
                  "drawn": s.drawn, "stages": s.stage_seconds}))
"""


def export_revision(rev: str, into: Path) -> Path:
    """``git archive REV`` unpacked under ``into``, laid out as an importable ``surfgen``."""
    tree = into / "tree"
    tree.mkdir(parents=True)
    archive = subprocess.run(
        ["git", "-C", str(ROOT), "archive", rev], check=True, capture_output=True
    ).stdout
    with tarfile.open(fileobj=__import__("io").BytesIO(archive)) as tar:
        tar.extractall(tree, filter="data")
    pkg = into / "path" / "surfgen"
    pkg.mkdir(parents=True)
    for name in PACKAGES:
        (pkg / name).symlink_to(tree / name)
    return into / "path"


def run_child(path: Path | None, n: int, seed: int, grid: int, workers: int) -> dict:
    return run_code(path, _CHILD, n, seed, grid, workers)


def run_code(path: Path | None, code: str, *args: object) -> dict:
    """Run ``code`` with ``args`` in a child Python with the checkout at ``path`` (None: this
    one) and return the JSON its last line prints; it must report its ``code`` file."""
    env = dict(os.environ)
    if path is not None:  # the baseline's packages shadow the installed ones
        env["PYTHONPATH"] = str(path) + os.pathsep + env.get("PYTHONPATH", "")
    out = subprocess.run(
        [sys.executable, "-c", code, *map(str, args)],
        check=True,
        capture_output=True,
        text=True,
        env=env,
        cwd=tempfile.gettempdir(),
    ).stdout
    result = json.loads(out.strip().splitlines()[-1])
    expected = str(path) if path is not None else str(ROOT)
    if not result["code"].startswith(expected):
        raise SystemExit(f"error: ran {result['code']}, expected code under {expected}")
    return result


def describe(label: str, r: dict, grid: int) -> str:
    acc = max(r["accepted"], 1)
    rate = 60.0 * r["accepted"] / r["wall"]
    stages = ", ".join(f"{k} {v / acc:.2f}" for k, v in sorted(r["stages"].items()))
    per = sum(r["stages"].values()) / acc
    return (
        f"  {label:<9} {rate:7.1f} shapes/min  {r['accepted']}/{r['drawn']} accepted  "
        f"worker s/accepted {per:.2f} ({stages})"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grids", type=int, nargs="+", default=[48, 64, 96, 128])
    ap.add_argument("--n", type=int, nargs="+", default=[6, 6, 4, 3], help="per grid")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--baseline", default=None, help="git revision to compare against")
    args = ap.parse_args()
    ns = (args.n * len(args.grids))[: len(args.grids)] if len(args.n) == 1 else args.n
    if len(ns) != len(args.grids):
        raise SystemExit("error: give one --n, or one per grid")
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs (shared machine?)")
    with tempfile.TemporaryDirectory() as tmp:
        versions: dict[str, Path | None] = {"new": None}
        if args.baseline:
            versions = {"baseline": export_revision(args.baseline, Path(tmp)), "new": None}
        for path in versions.values():  # compile numba's kernels outside the timings
            run_child(path, 1, args.seed, 16, 1)
        first_cost = None
        for grid, n in zip(args.grids, ns, strict=True):
            print(f"grid {grid} (n {n}, seed {args.seed}, {args.workers} workers)")
            results = {label: run_child(p, n, args.seed, grid, args.workers) for label, p in
                       versions.items()}  # fmt: skip
            for label, r in results.items():
                print(describe(label, r, grid))
            new = results["new"]
            cost = sum(new["stages"].values()) / max(new["accepted"], 1) / grid**3
            first_cost = first_cost or cost
            print(f"  grid cost (worker s per accepted shape per grid point) x{cost / first_cost:.2f}"
                  f" of grid {args.grids[0]}'s")  # fmt: skip
            if "baseline" in results:
                b = results["baseline"]
                speed = (new["accepted"] / new["wall"]) / (b["accepted"] / b["wall"])
                work_b = sum(b["stages"].values()) / max(b["accepted"], 1)
                work_n = sum(new["stages"].values()) / max(new["accepted"], 1)
                print(f"  ratio new/baseline: shapes/min x{speed:.2f}, "
                      f"worker time per accepted shape x{work_n / work_b:.2f}")  # fmt: skip
            sys.stdout.flush()


if __name__ == "__main__":
    main()
