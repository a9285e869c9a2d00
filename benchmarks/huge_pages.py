"""Benchmark: the first touch of fresh numpy arrays with and without numpy's huge-page advice.

    python -m benchmarks.huge_pages [--repeats 5] [--mib 1024]

numpy advises the kernel to back arrays of 4 MiB or more with transparent huge pages; where
the kernel's THP defrag setting compacts memory on such a fault (``madvise`` here), the first
touch can stall. Each run is a fresh process that makes ``--mib`` MiB of ``np.ones`` (two
arrays) with the advice on or off, the two taking turns (ABBA), so the machine's state hits
both alike. Prints each side's times, medians and the ratio advice-on / advice-off (above 1:
the advice costs time), with the kernel's defrag setting: what
:func:`surfgen.generator.allocator.no_huge_page_stalls` decides on.
"""

from __future__ import annotations

import statistics
import subprocess
import sys

from benchmarks import harness
from surfgen.generator.allocator import thp_defrag

_CHILD = r"""
import sys, time
import numpy as np
from surfgen.generator.allocator import numpy_huge_page_advice
numpy_huge_page_advice(sys.argv[1] == "on")
n = int(sys.argv[2]) << 16  # float64 values in half the MiB
start = time.perf_counter()
a, b = np.ones(n), np.ones(n)
print(time.perf_counter() - start)
"""


def touch(advice: str, mib: int) -> float:
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, advice, str(mib)],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    return float(out.stdout.strip())


def main(argv: list[str] | None = None) -> None:
    ap = harness.parser(__doc__, repeats=5)
    ap.add_argument("--mib", type=int, default=1024, help="MiB touched per run")
    args = ap.parse_args(argv)
    run = harness.Run("huge_pages", args)
    run.say(f"THP defrag: {thp_defrag()}")
    times: dict[str, list[float]] = {"on": [], "off": []}
    for r in range(args.repeats):
        for advice in ("on", "off") if r % 2 == 0 else ("off", "on"):
            times[advice].append(touch(advice, args.mib))
    for advice, seconds in times.items():
        shown = " ".join(f"{t:.3f}" for t in seconds)
        run.say(f"advice {advice}: {shown} s (median {statistics.median(seconds):.3f})")
    ratio = statistics.median(times["on"]) / statistics.median(times["off"])
    run.say(f"advice on / off (medians): {ratio:.2f}x")
    run.record(times=times, ratio=ratio, defrag=thp_defrag())
    run.save()


if __name__ == "__main__":
    main()
