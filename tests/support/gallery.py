"""What the thumbnails, static-site and live-gallery tests share: a catalogue with pictures
(``template``, ``keys``), the turntables recorded (``renders``), and small helpers. The test
modules import the fixtures by name (pytest finds fixtures in a module's namespace)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from surfgen.pipelines.catalogue.store import open_catalogue
from surfgen.pipelines.cli.main import main
from surfgen.pipelines.pictures import thumbnails
from surfgen.pipelines.web import site
from tests.support.browser import build_catalogue


def cli(capsys, *args: str) -> tuple[int, str, str]:
    """Run ``surfgen ARGS`` in this process: exit code, stdout, stderr."""
    rc = main(list(args))
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture(scope="module")
def template(tmp_path_factory) -> tuple[Path, dict[str, str]]:
    """A catalogue whose pictures were made by `surfgen thumbnails`."""
    root = tmp_path_factory.mktemp("gallery") / "cat"
    keys = build_catalogue(root)
    assert main(["thumbnails", "-C", str(root)]) == 0
    return root, keys


@pytest.fixture
def keys(template) -> dict[str, str]:
    return template[1]


def page_data(html: str) -> dict:
    """The JSON a gallery page carries."""
    m = re.search(r'<script id="gallery-data" type="application/json">(.*?)</script>', html, re.S)
    assert m, "no data in the page"
    return json.loads(m.group(1))


def without_turntables(root: Path) -> None:
    """What `surfgen sample` leaves: thumbnails, but no turntable rendered or recorded."""
    with open_catalogue(root, must_exist=True) as cat, cat.conn:
        cat.conn.execute("UPDATE shapes SET turntable_path=NULL")
    for f in (root / "turntables").glob("*.png"):
        f.unlink()


@pytest.fixture
def renders(monkeypatch) -> list[str]:
    """The file names of the turntables drawn and recorded in the catalogue, in order: by the
    live gallery's image route, the static gallery or a batch (drawn on any process, recorded
    by the parent)."""
    calls: list[str] = []
    record = thumbnails.record_picture

    def recording(cat, key, kind, data):
        if kind == "turntable":
            calls.append(f"{key}.png")
        return record(cat, key, kind, data)

    monkeypatch.setattr(thumbnails, "record_picture", recording)
    monkeypatch.setattr(site, "record_picture", recording)
    return calls
