"""What equivalent sampling runs must share, read from a catalogue folder: every column the
sampler computes for a draw (not timings, file paths or curation), and the mesh files' bytes."""

from __future__ import annotations

import sqlite3
from pathlib import Path

COMPUTED_COLUMNS = (
    "idx", "key", "spec", "formula", "identity", "d", "model", "verdict", "reasons", "metrics",
    "faces", "vertices", "components", "genus", "euler", "area", "volume", "descriptor",
)  # fmt: skip


def computed_rows(root: Path) -> list[tuple]:
    """:data:`COMPUTED_COLUMNS` of every draw, by draw index."""
    con = sqlite3.connect(root / "catalogue.sqlite")
    try:
        query = f"SELECT {', '.join(COMPUTED_COLUMNS)} FROM shapes ORDER BY idx"
        return con.execute(query).fetchall()
    finally:
        con.close()


def mesh_bytes(root: Path) -> dict[str, bytes]:
    """The accepted shapes' mesh files, by name."""
    return {p.name: p.read_bytes() for p in sorted((root / "meshes").glob("*.ply"))}
