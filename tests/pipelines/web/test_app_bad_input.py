"""The web API's share of the bad-input suite (issue 12): bodies, queries and exports out of
bounds get a 400 (or 413) naming what is wrong and store nothing; a corrupted catalogue is not
served."""

from __future__ import annotations

import io
import sqlite3
import zipfile
from pathlib import Path

import pytest

from surfgen.pipelines.catalogue.store import CatalogueError
from surfgen.pipelines.web.app import create_app
from tests.support.bad_input import bad_input_catalogue, corrupt


@pytest.fixture(scope="module")
def template(tmp_path_factory) -> tuple[Path, dict[str, str]]:
    """Two accepted shapes, one draw the filters rejected and one whose worker crashed."""
    return bad_input_catalogue(tmp_path_factory.mktemp("bad") / "cat")


def curation_rows(root: Path) -> list[tuple]:
    con = sqlite3.connect(f"file:{root / 'catalogue.sqlite'}?mode=ro", uri=True)
    rows = con.execute("SELECT key, action, value FROM curation").fetchall()
    rows += con.execute("SELECT key, stars, note, user_rejected FROM shapes").fetchall()
    con.close()
    return rows


@pytest.mark.parametrize(
    ("action", "body", "status", "message"),
    [
        ("tag", {"tags": 5}, 400, "'tags' must be a text or a list"),
        ("tag", {"tags": {"a": 1}}, 400, "'tags' must be"),
        ("tag", {"tags": [None]}, 400, "'tags' must be"),
        ("tag", {"tags": ["ok"] * 500}, 400, "at most 50"),
        ("note", {"note": {"text": "x"}}, 400, "'note' must be text"),
        ("note", {"note": "x" * 20_000}, 400, "too long"),
        ("reject", {"why": ["x"]}, 400, "'why' must be text"),
        ("reject", {"why": None}, 400, "'why' must be given"),
        ("star", {"stars": "3"}, 400, "'stars' must be a whole number from 0 to 5"),
        ("star", {"stars": 2.5}, 400, "'stars' must be"),
        ("star", {"stars": True}, 400, "'stars' must be"),
        ("star", {"stars": 10**30}, 400, "'stars' must be"),
        ("star", {"stars": 1, "extra": 2}, 400, "unknown field 'extra'"),
        ("note", {"note": [[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[["x"]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]}, 400, "nests more than"),
        ("note", {"note": "x" * (2 << 20)}, 413, "larger than"),
    ],
)  # fmt: skip
def test_api_validates_bodies(cat_dir, template, action, body, status, message) -> None:
    key = template[1]["torus"]
    before = curation_rows(cat_dir)
    client = create_app(cat_dir).test_client()
    res = client.post(f"/api/shapes/{key}/{action}", json=body)
    assert res.status_code == status, res.get_data(as_text=True)[:200]
    assert message in res.get_json()["error"]
    assert curation_rows(cat_dir) == before  # nothing stored


def test_api_query_and_export_limits(cat_dir, template) -> None:
    keys = template[1]
    client = create_app(cat_dir).test_client()
    for query, message in [
        ({"limit": str(10**30)}, "'limit' must be a whole number"),
        ({"limit": "-1"}, "'limit' must be"),
        ({"limit": "x"}, "'limit' must be"),
        ({"where": "genus = 1 or " * 2000 + "genus = 1"}, "too long"),
        ({"where": "(" * 60 + "genus = 1" + ")" * 60}, "nested"),
        ({"sort": "genus," * 100}, "at most"),
        ({"all": "maybe"}, "'all' must be 1 or 0"),
    ]:
        res = client.get("/api/shapes", query_string=query)
        assert res.status_code == 400 and message in res.get_json()["error"], query
    # a key repeated 2,000 times is one shape; too many distinct keys are refused
    res = client.post("/api/export", data={"keys": ",".join([keys["torus"]] * 2000)})
    assert res.status_code == 200
    names = zipfile.ZipFile(io.BytesIO(res.data)).namelist()
    assert names.count(f"meshes/{keys['torus']}.ply") == 1
    many = ",".join(f"{i:016x}" for i in range(600))
    res = client.post("/api/export", data={"keys": many})
    assert res.status_code == 400 and "at most 500" in res.get_json()["error"]
    res = client.post("/api/export", data={"keys": "../../etc/passwd"})
    assert res.status_code == 400 and "not a shape key" in res.get_json()["error"]
    res = client.post("/api/export", data={"keys": "x" * (1 << 20)})
    assert res.status_code == 413


def test_api_on_a_corrupted_catalogue_refuses_to_start(cat_dir) -> None:
    corrupt(cat_dir)
    with pytest.raises(CatalogueError, match="catalogue check"):
        create_app(cat_dir)
