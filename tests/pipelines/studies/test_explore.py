"""Tests for surfgen.pipelines.studies.explore and the viewer's routes: change sets, GLB, mesh
statistics, POST /api/explore (good, bad formula, oversized grid), saving a variant, the detail
pages live and static."""

from __future__ import annotations

import json
import re
import struct
from urllib.parse import quote

import numpy as np
import pytest
import trimesh

from surfgen.filters.metrics import measure_mesh
from surfgen.generator.errors import GridError
from surfgen.generator.formula.expr import to_string
from surfgen.generator.mesh.exchange import glb_bytes
from surfgen.generator.model.presets import get_preset
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.store import open_catalogue
from surfgen.pipelines.cli.main import main
from surfgen.pipelines.studies.explore import (
    explore,
    mesh_stats,
)
from surfgen.pipelines.studies.knobs import (
    MAX_POINTS,
    ExploreError,
    apply_changes,
    d_of,
    grid_of,
    knobs_of,
    literals_of,
    replace_literals,
)
from surfgen.pipelines.web.app import create_app
from tests.support.browser import build_catalogue

SPHERE = SurfaceSpec("x^2+y^2+z^2-1", (-1.5, 1.5) * 3, (24,) * 3)


@pytest.fixture(scope="module")
def template(tmp_path_factory):
    root = tmp_path_factory.mktemp("explore") / "cat"
    keys = build_catalogue(root)
    assert main(["thumbnails", "-C", str(root)]) == 0
    return root, keys


@pytest.fixture
def keys(template) -> dict[str, str]:
    return template[1]


# ----------------------------------------------------------------------------- change sets


def test_apply_changes() -> None:
    eq_c = get_preset("eqC").spec()
    s = apply_changes(eq_c, {"m": 0.5, "box": 4, "grid": 40, "level": 0.25})
    assert (s.params["m"], s.box, s.grid, s.level) == (0.5, (-4.0, 4.0) * 3, (40,) * 3, 0.25)
    assert s.formula == eq_c.formula and s.provenance == eq_c.provenance
    six = apply_changes(SPHERE, {"box": [-1, 2, -1, 1, -1, 1], "grid": [20, 16, 12]})
    assert six.box == (-1.0, 2.0, -1.0, 1.0, -1.0, 1.0) and six.grid == (20, 16, 12)
    # d of F = S - d: written S + |d| when negative, and read back
    assert d_of(SPHERE) == 1.0
    assert apply_changes(SPHERE, {"d": 0.5}).formula == "x^2+y^2+z^2-0.5"
    neg = apply_changes(SPHERE, {"d": -0.5})
    assert neg.formula == "x^2+y^2+z^2+0.5" and d_of(neg) == -0.5
    # literals, counted parents first: #0 is the exponent of x
    assert [lit.value for lit in literals_of(SPHERE.tree())] == [2.0, 2.0, 2.0, 1.0]
    assert apply_changes(SPHERE, {"#0": 4, "#2": -3}).formula == "x^4+y^2+z^(-3)-1"
    assert apply_changes(SPHERE, {}) == SPHERE


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"q": 1}, "unknown change 'q'"),
        ({"box": -1}, "half-width must be positive"),
        ({"box": [1, 2, 3]}, "6 numbers"),
        ({"grid": 12.5}, "whole number"),
        ({"grid": True}, "must be a number"),
        ({"level": "1"}, "must be a number"),
        ({"level": float("nan")}, "finite"),
        ({"#9": 1}, "4 numeric literals"),
        ({"x; drop": 1}, "unknown change"),
        ({f"#{i}": 1 for i in range(70)}, "at most 64"),
    ],
)
def test_bad_changes(changes, message) -> None:
    with pytest.raises(ExploreError, match=message):
        apply_changes(SPHERE, changes)


def test_grid_cap() -> None:
    assert grid_of(128) == (128,) * 3 and grid_of([160, 100, 100]) == (160, 100, 100)
    with pytest.raises(ExploreError, match="more than the 2097152"):
        grid_of([160, 160, 100])
    with pytest.raises(ExploreError, match="out of range"):
        grid_of(200)
    with pytest.raises(GridError, match="from 4 to 2048"):  # the CLI's own limit and message
        grid_of(3)
    assert grid_of(300, capped=False) == (300,) * 3 and MAX_POINTS == 128**3


def test_literals_round_trip() -> None:
    """Setting every literal to its own value gives the same formula back (eq. C and A)."""
    for name in ("eqC", "eqA", "eqB"):
        tree = get_preset(name).spec().tree()
        lits = literals_of(tree)
        same = replace_literals(tree, {lit.index: lit.value for lit in lits})
        assert to_string(same) == to_string(tree) and len(lits) > 5
    knobs = {k.name: k for k in knobs_of(get_preset("eqC").spec())}
    assert {"m", "box", "grid", "level", "#0"} <= set(knobs) and knobs["m"].lo < 1 < knobs["m"].hi
    assert "cos(0.5*m*x^(-1))" in apply_changes(get_preset("eqC").spec(), {"#0": 0.5}).formula


def test_glb_and_stats(shape_mesh) -> None:
    torus = shape_mesh("torus")
    data = glb_bytes(torus, web=True)
    magic, version, length = struct.unpack("<III", data[:12])
    assert (magic, version, length) == (0x46546C67, 2, len(data))
    loaded = trimesh.load(
        trimesh.util.wrap_as_stream(data), file_type="glb", force="mesh", process=False
    )
    assert len(loaded.faces) == torus.n_faces and len(loaded.vertices) == torus.n_vertices
    assert np.allclose(loaded.vertices, torus.vertices, atol=1e-6)
    empty = glb_bytes(None, web=True)
    assert json.loads(empty[20:].decode().strip())["scenes"] == [{"nodes": []}]
    st = mesh_stats(torus)
    m = measure_mesh(torus)
    assert (st["faces"], st["components"], st["euler"], st["genus"]) == (
        m.faces, m.components, m.euler, m.genus,
    )  # fmt: skip
    assert mesh_stats(shape_mesh("two_spheres"))["components"] == 2


def test_explore_step() -> None:
    step = explore(apply_changes(SPHERE, {"d": 0.25}))
    assert step.faces > 500 and step.stats["genus"] == 0 and step.empty is None
    assert set(step.seconds) == {"evaluate", "mesh", "glb", "stats", "cpu"}
    gone = explore(apply_changes(SPHERE, {"d": -1}))
    assert gone.mesh is None and "no surface" in gone.empty and gone.glb[:4] == b"glTF"


# ----------------------------------------------------------------------------- the API


def cli_error(capsys, *args: str) -> str:
    assert main(list(args)) != 0
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1
    return err[len("error: ") :].strip()


def test_api_explore(cat_dir, keys, capsys) -> None:
    client = create_app(cat_dir).test_client()
    # a pasted formula
    res = client.post(
        "/api/explore",
        json={"formula": "x^2+y^2+z^2-r", "params": {"r": 1}, "box": [-1.5, 1.5] * 3, "grid": 32},
    )
    assert res.status_code == 200, res.get_json()
    body = res.get_json()
    assert {"faces", "seconds", "formula", "mesh"} <= set(body)
    assert body["formula"] == "x^2+y^2+z^2-r" and body["faces"] > 500 and body["seconds"] > 0
    glb = client.get("/" + body["mesh"])
    assert glb.status_code == 200 and glb.mimetype == "model/gltf-binary"
    mesh = trimesh.load(trimesh.util.wrap_as_stream(glb.data), file_type="glb", force="mesh")
    assert len(mesh.faces) == body["faces"]
    bigger = client.post(
        "/api/explore",
        json={"formula": "x^2+y^2+z^2-r", "params": {"r": 1}, "box": 1.5, "grid": 32,
              "changes": {"r": 2}},
    ).get_json()  # fmt: skip
    assert bigger["params"] == {"r": 2.0} and bigger["faces"] > body["faces"]
    # a catalogued shape with changes: a thinner torus has fewer faces
    torus = keys["torus"]
    base = client.post("/api/explore", json={"key": torus[:8], "changes": {}}).get_json()
    thin = client.post("/api/explore", json={"key": torus, "changes": {"d": 0.04}}).get_json()
    assert thin["formula"] == "(sqrt(x^2+y^2)-1)^2+z^2-0.04" and thin["faces"] < base["faces"]
    assert thin["stats"]["faces"] == thin["faces"] and "genus" not in thin["stats"]
    topology = client.get("/" + thin["topology"]).get_json()["stats"]
    assert (topology["genus"], topology["components"], topology["faces"]) == (1, 1, thin["faces"])
    assert client.get("/api/explore/stats/nothere").status_code == 404
    preset = client.post("/api/explore", json={"preset": "sphere", "changes": {"grid": 24}})
    assert preset.status_code == 200 and preset.get_json()["grid"] == [24, 24, 24]


def test_api_explore_refusals(cat_dir, keys, capsys) -> None:
    client = create_app(cat_dir).test_client()

    def post(body, **kw):
        res = (
            client.post("/api/explore", json=body, **kw)
            if body is not None
            else client.post("/api/explore", **kw)
        )
        return res.status_code, (res.get_json() or {}).get("error", "")

    # a bad formula: 400 with the CLI's one-line message
    status, error = post({"formula": "sin(x)+cos(y", "grid": 16})
    assert status == 400
    assert error == cli_error(capsys, "render", "--formula", "sin(x)+cos(y", "--grid", "16")
    status, error = post({"formula": "sinn(x)+y", "grid": 16})
    assert status == 400 and error == cli_error(capsys, "render", "--formula", "sinn(x)+y")
    # grids: outside the CLI's range, the CLI's message; over the cap, the cap's
    status, error = post({"formula": "x+y+z", "grid": 5000})
    assert status == 400
    assert error == cli_error(capsys, "render", "--formula", "x+y+z", "--grid", "5000")
    status, error = post({"formula": "x+y+z", "grid": 150})
    assert status == 400 and "more than the 2097152 (128³)" in error
    status, error = post({"key": keys["sphere"], "changes": {"grid": 161}})
    assert status == 400 and "allowed: 4 to 160" in error
    # shapes of the body
    assert post({"formula": "x", "grid": "64"})[1] == "'grid' must be a number, got \"64\""
    assert "unknown field 'evil'" in post({"formula": "x", "evil": 1})[1]
    assert "give 'key' or 'preset'" in post({"key": "ab", "preset": "eqC"})[1]
    assert post({"key": "0000000000"})[0] == 404
    assert post([1, 2])[1] == "the body must be a JSON object"
    assert post(None, data="x", content_type="text/plain")[0] == 415
    assert post(None, data="{", content_type="application/json")[1] == "the body is not valid JSON"
    big = {"formula": "x" + "+x" * 40000}
    assert "over 65536 bytes" in post(big)[1]
    assert "at most 4000" in post({"formula": "x" + "+x" * 2500})[1]
    assert client.get("/api/explore/mesh/nothere.glb").status_code == 404


def test_api_save_variant(cat_dir, keys) -> None:
    client = create_app(cat_dir).test_client()
    torus = keys["torus"]
    res = client.post("/api/explore/save", json={"key": torus, "changes": {"d": 0.09, "grid": 28}})
    assert res.status_code == 200, res.get_json()
    rec = res.get_json()["shape"]
    new = rec["key"]
    assert res.get_json()["url"] == f"shape/{new}"
    assert rec["provenance"] == {"derived_from": torus, "changes": {"d": 0.09, "grid": 28}}
    assert rec["formula"] == "(sqrt(x^2+y^2)-1)^2+z^2-0.09" and rec["spec"]["grid"] == [28] * 3
    assert rec["genus"] == 1 and rec["verdict"] == "accepted"
    with open_catalogue(cat_dir, must_exist=True) as cat:
        row = cat.shape(new)
        assert (cat_dir / row["mesh_path"]).is_file() and (cat_dir / row["thumb_path"]).is_file()
        run = cat.conn.execute("SELECT * FROM runs WHERE id=?", (row["run"],)).fetchone()
        assert (run["status"], run["next_index"], run["accepted"]) == ("derived", 1, 1)
    history = client.get(f"/api/shapes/{torus}").get_json()["shape"]["history"]
    assert [(h["action"], h["value"]) for h in history] == [("derive", new)]
    # the same variant again: the same shape, nothing added; a second one is the run's next
    again = client.post(
        "/api/explore/save", json={"key": torus, "changes": {"grid": 28, "d": 0.09}}
    )
    assert again.get_json()["shape"]["key"] == new
    other = client.post("/api/explore/save", json={"key": keys["sphere"], "changes": {"d": 0.5}})
    assert other.get_json()["shape"]["index"] == 1
    assert client.get("/api/health").get_json()["shapes"] == 6
    # refusals
    nothing = client.post("/api/explore/save", json={"key": torus, "changes": {}})
    assert nothing.status_code == 400 and "nothing changed" in nothing.get_json()["error"]
    assert client.post("/api/explore/save", json={"key": torus, "x": 1}).status_code == 400
    gone = client.post("/api/explore/save", json={"key": torus, "changes": {"d": -1}})
    assert gone.status_code == 400 and "no surface" in gone.get_json()["error"]
    assert client.post("/api/explore/save", json={"key": "ffff0000"}).status_code == 404


def test_detail_pages(cat_dir, keys, capsys, tmp_path) -> None:
    client = create_app(cat_dir).test_client()
    torus = keys["torus"]
    page = client.get(f"/shape/{torus[:6]}")
    html = page.get_data(as_text=True)
    assert page.status_code == 200 and '<canvas id="viewer"' in html
    assert "../static/vendor/three/three-viewer.min.js" in html and "https://" not in html
    assert f'src="../thumbs/{torus}.png"' in html  # the poster
    glb = client.get(f"/api/shape/{torus}/mesh.glb")
    assert glb.status_code == 200 and glb.data[:4] == b"glTF"
    assert client.get("/shape/ffff0000").status_code == 404
    assert client.get("/static/vendor/three/three-viewer.min.js").status_code == 200
    assert client.get("/explore?preset=eqC").status_code == 200
    assert client.get("/explore?formula=x%2By%2Bz").status_code == 200
    assert client.get("/explore?formula=sin(").status_code == 400
    # a pasted formula's free names become parameters at 1, each with a slider
    page = client.get("/explore?formula=" + quote("x^2+y^2+z^2-r*cos(a*x)")).get_data(as_text=True)
    data = json.loads(
        re.search(r'id="shape-data" type="application/json">(.*?)</script>', page).group(1)
    )
    assert data["spec"]["params"] == {"a": 1.0, "r": 1.0}
    assert {"a", "r"} <= {k["name"] for k in data["knobs"]}
    # the static gallery with meshes has a 3-D page per shape, readable from disk
    out = tmp_path / "site"
    assert main(["gallery", "-C", str(cat_dir), "-o", str(out), "--meshes"]) == 0
    capsys.readouterr()
    page = (out / "shapes" / f"{torus}.html").read_text()
    assert '<canvas id="viewer"' in page and "../static/viewer.js" in page
    assert page.index("../static/common.js") < page.index("../static/viewer.js")
    mesh_js = (out / "shapes" / f"{torus}.glb.js").read_text()
    assert mesh_js.startswith(f'window.SURFGEN_MESH_LOADED("{torus}","')
    for name in ("three-viewer.min.js", "LICENSE", "VERSION"):
        assert (out / "static" / "vendor" / "three" / name).is_file()
    assert "0.180.0" in (out / "static" / "vendor" / "three" / "VERSION").read_text()
