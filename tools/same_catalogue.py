"""Check that two sampling runs made the same catalogue: keys, specs, verdicts and metrics.

    python -m tools.same_catalogue CATALOGUE_A CATALOGUE_B

Used to show that a speed change altered nothing a user can see: run
``surfgen sample --n 100 --seed 7 --grid 32`` with the old code into A and the new code into
B, then compare. Timings, file paths and curation are left out (they may differ); everything
the sampler decides is compared row by row, by draw index. Exit code 0 if identical, else 1
with the first differences listed.
"""

from __future__ import annotations

import argparse
import sqlite3
import sys
from pathlib import Path

COLUMNS = (
    "idx",
    "key",
    "spec",
    "formula",
    "identity",
    "d",
    "model",
    "verdict",
    "reasons",
    "metrics",
    "faces",
    "vertices",
    "components",
    "genus",
    "euler",
    "area",
    "volume",
    "descriptor",
)


def rows(root: Path) -> list[tuple]:
    db = root / "catalogue.sqlite"
    if not db.is_file():
        raise SystemExit(f"error: no catalogue at {root}")
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        return con.execute(f"SELECT {', '.join(COLUMNS)} FROM shapes ORDER BY run, idx").fetchall()
    finally:
        con.close()


def differences(a: list[tuple], b: list[tuple], limit: int = 10) -> list[str]:
    out = []
    if len(a) != len(b):
        out.append(f"{len(a)} rows against {len(b)}")
    for ra, rb in zip(a, b, strict=False):
        for name, va, vb in zip(COLUMNS, ra, rb, strict=True):
            if va != vb:
                out.append(f"index {ra[0]}: {name} differs: {str(va)[:120]!r} != {str(vb)[:120]!r}")
        if len(out) >= limit:
            break
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    args = ap.parse_args()
    a, b = rows(args.a), rows(args.b)
    diff = differences(a, b)
    accepted = sum(r[7] == "accepted" for r in a)
    if diff:
        print(f"DIFFERENT ({len(a)} and {len(b)} draws):", *diff, sep="\n  ")
        return 1
    print(f"identical: {len(a)} draws ({accepted} accepted), columns {', '.join(COLUMNS)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
