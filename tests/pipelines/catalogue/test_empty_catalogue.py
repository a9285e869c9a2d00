"""An empty (0-byte) catalogue.sqlite is an empty catalogue, as SQLite treats it: the commands
that read list nothing and change nothing; `sample` makes it a catalogue."""

from __future__ import annotations

from pathlib import Path

import pytest

from surfgen.pipelines.catalogue.check import check_catalogue
from surfgen.pipelines.catalogue.store import DB_NAME, open_catalogue
from surfgen.pipelines.cli.main import main


@pytest.fixture
def empty(tmp_path: Path) -> Path:
    root = tmp_path / "cat"
    root.mkdir()
    (root / DB_NAME).write_bytes(b"")
    return root


def unchanged(root: Path) -> bool:
    return (
        sorted(p.name for p in root.iterdir()) == [DB_NAME] and (root / DB_NAME).stat().st_size == 0
    )


def test_reading_lists_nothing_and_leaves_the_file(empty: Path, capsys) -> None:
    with open_catalogue(empty, readonly=True) as cat:
        assert cat.conn.execute("SELECT count(*) FROM shapes").fetchone()[0] == 0
    assert main(["catalogue", "list", "-C", str(empty), "--json"]) == 0
    assert capsys.readouterr().out.strip() in ("", "[]")
    assert main(["catalogue", "show", "-C", str(empty), "abc"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: no shape with key 'abc' in {empty}"]
    assert unchanged(empty)


def test_check_finds_an_empty_sound_catalogue(empty: Path) -> None:
    report = check_catalogue(empty)
    assert report.shapes == 0 and not report.integrity and not report.unrepaired
    assert check_catalogue(empty, repair=True).unrepaired == []
    assert unchanged(empty)


def test_sample_fills_it(empty: Path, capsys) -> None:
    args = ["sample", "--n", "1", "--seed", "3", "--grid", "20", "--workers", "1"]
    assert main([*args, "--out", str(empty), "--no-thumbnails"]) == 0
    with open_catalogue(empty, readonly=True) as cat:
        assert (
            cat.conn.execute("SELECT count(*) FROM shapes WHERE verdict='accepted'").fetchone()[0]
            == 1
        )
