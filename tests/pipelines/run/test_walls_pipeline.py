"""Issue 11 end to end: catalogue meshes survive merges; --walls on render, export, sampler."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from surfgen.filters.metrics import measure_mesh
from surfgen.filters.robust import merge_problems
from surfgen.generator.mesh.exchange import load_mesh
from surfgen.pipelines.cli.main import main
from surfgen.pipelines.run.config import load_config
from surfgen.pipelines.run.sampling import run_sample
from surfgen.pipelines.run.shapes import make_shape

CATALOGUE_N = 60
CATALOGUE_GRID = 16


@pytest.fixture(scope="module")
def catalogue60(tmp_path_factory) -> Path:
    """60 accepted shapes of seed 7 on a 16^3 grid, built once."""
    root = tmp_path_factory.mktemp("cat60")
    cfg = root / "cfg.toml"
    cfg.write_text("[run]\nthumbnails = false\n")
    config = load_config(cfg).with_grid(CATALOGUE_GRID)
    summary = run_sample(n=CATALOGUE_N, seed=7, config=config, catalogue=root / "cat", workers=2)
    assert summary.accepted == CATALOGUE_N
    return root / "cat"


def accepted_rows(cat: Path) -> list[tuple[str, str, dict]]:
    con = sqlite3.connect(cat / "catalogue.sqlite")
    rows = con.execute(
        "SELECT key, mesh_path, metrics FROM shapes WHERE verdict = 'accepted' ORDER BY idx"
    ).fetchall()
    con.close()
    return [(k, p, json.loads(m)) for k, p, m in rows]


def test_every_catalogue_mesh_survives_merges(catalogue60: Path) -> None:
    rows = accepted_rows(catalogue60)
    assert len(rows) == CATALOGUE_N
    for key, path, metrics in rows:
        mesh = load_mesh(catalogue60 / path)  # the float32 PLY a user gets
        assert merge_problems(mesh) == [], key
        m = measure_mesh(mesh)
        assert (m.euler, m.genus, m.components) == (
            metrics["euler"],
            metrics["genus"],
            metrics["components"],
        ), key
        assert 0.0 <= metrics["wall_fraction"] <= 1.0


def test_wall_fraction_is_stored_and_queryable(catalogue60: Path, capsys) -> None:
    fractions = [m["wall_fraction"] for _, _, m in accepted_rows(catalogue60)]
    assert any(f == 0.0 for f in fractions) and any(f > 0.0 for f in fractions)
    assert main(["catalogue", "list", "-C", str(catalogue60), "--where", "wall_fraction > 0",
                 "--json"]) == 0  # fmt: skip
    listed = json.loads(capsys.readouterr().out)
    assert len(listed) == sum(f > 0 for f in fractions)


def test_max_wall_fraction_rejects_walls(tmp_path: Path) -> None:
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(
        '[run]\nthumbnails = false\nwalls = "mark"\n[filters]\nmax_wall_fraction = 0.0\n'
    )
    config = load_config(cfg).with_grid(CATALOGUE_GRID)
    reasons = []
    for index in range(40):  # in this process: no worker pool to start
        outcome = make_shape(index, seed=7, config=config, staging=tmp_path)
        metrics = json.loads(outcome.row["metrics"])
        if "wall_fraction" in metrics:
            rejected = "walls" in outcome.verdict.reasons
            assert rejected == (metrics["wall_fraction"] > 0.0)
            reasons.append(rejected)
        if outcome.verdict.accepted:  # marked files: the labels are in the PLY
            assert load_mesh(outcome.mesh_file).face_kinds is not None
    assert True in reasons and False in reasons


@pytest.mark.parametrize(
    ("toml", "message"),
    [
        ('[run]\nwalls = "drop"\n', "walls must be one of keep, remove, mark"),
        ("[filters]\nmax_wall_fraction = 2.0\n", "max_wall_fraction"),
    ],
)
def test_bad_walls_config_is_refused(toml: str, message: str, tmp_path: Path, capsys) -> None:
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(toml)
    assert main(["sample", "--n", "1", "--config", str(cfg), "--out", str(tmp_path / "c")]) != 0
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


TAN = ["render", "--formula", "tan(x)", "--box", "-3,3", "--grid", "24"]


def test_render_walls_remove_mark_and_check(tmp_path: Path, capsys) -> None:
    stl = tmp_path / "r.stl"
    assert main([*TAN, "--walls", "remove", "-o", str(stl)]) != 0
    assert "--force" in capsys.readouterr().err and not stl.exists()
    assert main([*TAN, "--walls", "remove", "-o", str(stl), "--force", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["walls"] == "remove" and out["wall_fraction"] == pytest.approx(2 / 3)
    assert np.abs(load_mesh(stl).vertices[:, 0]).max() < 0.01
    ply = tmp_path / "m.ply"
    png = tmp_path / "m.png"
    assert main([*TAN, "--cap", "--walls", "mark", "-o", str(ply), "--png", str(png)]) == 0
    capsys.readouterr()
    assert main(["check", str(ply), "--json"]) == 0
    checked = json.loads(capsys.readouterr().out)
    assert 0.3 < checked["wall_fraction"] < 0.7  # caps count in the area
    from PIL import Image

    pixels = np.asarray(Image.open(png).convert("RGB")).reshape(-1, 3).astype(int)
    red = (pixels[:, 0] > 150) & (pixels[:, 1] < 80) & (pixels[:, 2] < 80)
    assert red.sum() > 100  # the pole walls are drawn red


def test_render_without_roots_is_a_clean_error(tmp_path: Path, capsys) -> None:
    out = tmp_path / "x.ply"
    args = ["render", "--formula", "1/x", "--box", "-3,3", "--grid", "24", "--walls", "remove"]
    assert main([*args, "-o", str(out)]) != 0
    err = capsys.readouterr().err
    assert err.startswith("error: no root") and err.count("\n") == 1
    assert not out.exists() and not list(tmp_path.iterdir())


def test_export_walls(tmp_path: Path, capsys) -> None:
    spec = tmp_path / "saw.json"
    assert main(["render", "--formula", "atan(tan(2*x))+0.5", "--box", "-3,3", "--grid", "24",
                 "--json"]) == 0  # fmt: skip
    data = json.loads(capsys.readouterr().out)
    spec.write_text(json.dumps({k: data[k] for k in ("formula", "box", "grid", "level", "params")}))
    assert main(["export", str(spec), "-o", str(tmp_path / "a"), "--walls", "mark"]) != 0
    assert "ply or glb" in capsys.readouterr().err  # STL cannot carry labels
    assert main(["export", str(spec), "-o", str(tmp_path / "a"), "--walls", "remove"]) != 0
    assert "not watertight" in capsys.readouterr().err
    assert main(["export", str(spec), "-o", str(tmp_path / "b"), "--format", "ply", "--walls",
                 "mark", "--json"]) == 0  # fmt: skip
    marked = json.loads(capsys.readouterr().out)[0]
    assert marked["walls"] == "mark" and 0.2 < marked["wall_fraction"] < 0.6
    labelled = tmp_path / "b" / "saw.ply"
    assert load_mesh(labelled).face_kinds is not None
    # A marked file is enough to remove the walls later, without the formula.
    assert main(["export", str(labelled), "-o", str(tmp_path / "c"), "--format", "obj",
                 "--walls", "remove", "--json"]) == 0  # fmt: skip
    removed = json.loads(capsys.readouterr().out)[0]
    assert not removed["watertight"] and removed["faces_after"] < marked["faces_after"]
