"""Fixtures of the gallery's web tests: a catalogue with pictures, and the turntables drawn."""

from __future__ import annotations

from pathlib import Path

import pytest

from surfgen.pipelines.cli.main import main
from surfgen.pipelines.pictures import thumbnails
from surfgen.pipelines.web import site
from tests.support.browser import build_catalogue


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


@pytest.fixture
def renders(monkeypatch) -> list[str]:
    """The file names of the turntables drawn and recorded in the catalogue, in order: by the
    live gallery or for a batch (drawn on any process, recorded by the parent)."""
    calls: list[str] = []
    record = thumbnails.record_picture

    def recording(cat, key, kind, data):
        if kind == "turntable":
            calls.append(f"{key}.png")
        return record(cat, key, kind, data)

    monkeypatch.setattr(thumbnails, "record_picture", recording)
    monkeypatch.setattr(site, "record_picture", recording)
    return calls
