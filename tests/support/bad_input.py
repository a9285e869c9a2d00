"""The bad-input suites' shared parts: a refused command's checks, a small catalogue with
accepted, rejected and crashed draws, and a disk that lost sectors."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.store import open_catalogue
from surfgen.pipelines.cli.main import main
from tests.support.catalogues import SPHERE_AND_TORUS, catalogue_formulas


def snapshot(root: Path) -> dict[str, str]:
    """Every file under ``root`` and the hash of its bytes."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def refused(args: list[str], capsys, message: str, watch: Path | None = None) -> str:
    """Run ``surfgen args``: non-zero, one line naming ``message``, nothing written in ``watch``."""
    before = snapshot(watch) if watch is not None else None
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert rc != 0, (out, err)
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err and message in lines[0], lines[0]
    assert len(lines[0]) < 2100
    if watch is not None:
        assert snapshot(watch) == before
    return lines[0]


def bad_input_catalogue(root: Path) -> tuple[Path, dict[str, str]]:
    """A catalogue at ``root`` of two accepted shapes (sphere, torus), one draw the filters
    rejected (``blob``) and one whose worker crashed (``crashed``): ``(root, keys)``."""
    keys = catalogue_formulas(root, SPHERE_AND_TORUS, seed=3, grid=24)
    rejected = SurfaceSpec("x^2+y^2+z^2-0.5", (-1, 1) * 3, (24,) * 3, provenance={"index": 2})
    crashed = SurfaceSpec(
        "x+y+z", (-1, 1) * 3, (24,) * 3, provenance={"index": 3, "failed": "crashed"}
    )
    with open_catalogue(root) as cat:
        for i, (spec, reason) in enumerate([(rejected, "blob"), (crashed, "crashed")], start=2):
            row = {
                "key": spec.key,
                "spec": spec.to_json(),
                "formula": spec.formula,
                "identity": spec.identity,
                "verdict": "rejected",
                "reasons": json.dumps([reason]),
                "metrics": "{}",
            }
            cat.record_shape(1, i, row, False, {reason: 1})
            keys[reason] = spec.key
        cat.conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    return root, keys


def corrupt(root: Path) -> None:
    """Overwrite every page but the first with noise (a disk that lost sectors)."""
    db = root / "catalogue.sqlite"
    data = bytearray(db.read_bytes())
    page = int.from_bytes(data[16:18], "big")
    noise = hashlib.sha256(b"noise").digest() * (page // 32)
    for start in range(page, len(data), page):
        data[start : start + page] = noise
    db.write_bytes(bytes(data))
