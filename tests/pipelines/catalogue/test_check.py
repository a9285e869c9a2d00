"""`surfgen catalogue check` and `surfgen check` show the shapes' resolution figures."""

from __future__ import annotations

import json
import shutil
import sqlite3
from pathlib import Path

import pytest

from surfgen.filters.resolution import measure_resolution
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.mesh.mesh import extract_mesh
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.check import check_catalogue, stored_resolution
from surfgen.pipelines.catalogue.store import DB_NAME
from surfgen.pipelines.cli.main import main
from tests.support.catalogues import catalogue_shapes

SHAPES = {"sphere": ("x^2+y^2+z^2-1", 1.5), "torus": ("(sqrt(x^2+y^2)-1)^2+z^2-0.16", 1.6)}


@pytest.fixture(scope="module")
def template(tmp_path_factory) -> tuple[Path, dict[str, str]]:
    """Two accepted shapes with their measured resolution, and one sampled before the check."""
    root = tmp_path_factory.mktemp("check") / "cat"
    specs = [
        SurfaceSpec(f, (-h, h) * 3, (24,) * 3, provenance={"index": i})
        for i, (f, h) in enumerate(SHAPES.values())
    ]
    specs.append(SurfaceSpec("x^2+y^2+z^2-0.8", (-1.5, 1.5) * 3, (24,) * 3))
    items = []
    for s in specs:
        field = evaluate_reference(s.tree(), s.to_grid())
        items.append((s, extract_mesh(field, 0.0, cap=True), field))
    keys = catalogue_shapes(root, [(s, m) for s, m, _ in items], grid=24)
    conn = sqlite3.connect(root / DB_NAME)
    for (spec, mesh, field), key in list(zip(items, keys, strict=True))[:2]:
        figures = measure_resolution(spec.tree(), field, mesh, 0.0, cap=True).to_metrics()
        (text,) = conn.execute("SELECT metrics FROM shapes WHERE key=?", (key,)).fetchone()
        metrics = {**json.loads(text), **figures}
        conn.execute("UPDATE shapes SET metrics=? WHERE key=?", (json.dumps(metrics), key))
    conn.commit()
    conn.close()
    return root, dict(zip([*SHAPES, "old"], keys, strict=True))


def test_catalogue_check_summarises_resolution(template, tmp_path, capsys) -> None:
    root, keys = template
    report = check_catalogue(root)
    assert report.resolution is not None
    assert report.resolution.accepted == 3 and len(report.resolution.shifts) == 2
    assert max(report.resolution.shifts) < 0.6 and report.resolution.over == []
    text = "\n".join(report.lines())
    assert "resolution (twice-as-fine grid): 2 of 3 accepted shapes measured, 1 not" in text
    assert "above the default limits (shift > 0.6 or area > 1.1): 0" in text
    # a shape above the limits (accepted under a laxer config) is named
    copy = tmp_path / "cat"
    shutil.copytree(root, copy)
    conn = sqlite3.connect(copy / DB_NAME)
    (text,) = conn.execute("SELECT metrics FROM shapes WHERE key=?", (keys["torus"],)).fetchone()
    metrics = {**json.loads(text), "resolution_shift": 2.5}
    conn.execute("UPDATE shapes SET metrics=? WHERE key=?", (json.dumps(metrics), keys["torus"]))
    conn.commit()
    conn.close()
    assert check_catalogue(copy).resolution.over == [keys["torus"]]
    assert main(["catalogue", "check", "-C", str(copy)]) == 0
    out = capsys.readouterr().out
    assert "above the default limits (shift > 0.6 or area > 1.1): 1" in out
    assert keys["torus"] in out


def test_check_of_a_catalogued_mesh_shows_its_resolution(template, tmp_path, capsys) -> None:
    root, keys = template
    mesh = root / "meshes" / f"{keys['sphere']}.ply"
    figures = stored_resolution(mesh)
    assert figures is not None and 0 < figures["resolution_shift"] < 0.6
    assert 0.95 < figures["resolution_area"] < 1.05
    assert main(["check", str(mesh), "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["resolution_shift"] == figures["resolution_shift"] and shown["genus"] == 0
    assert main(["check", str(mesh)]) == 0
    assert "resolution_to_coarse" in capsys.readouterr().out
    # not measured (an older shape), or not in a catalogue: nothing to show
    assert stored_resolution(root / "meshes" / f"{keys['old']}.ply") is None
    loose = tmp_path / "sphere.ply"
    shutil.copy(mesh, loose)
    assert stored_resolution(loose) is None
    assert main(["check", str(loose), "--json"]) == 0
    assert "resolution_shift" not in json.loads(capsys.readouterr().out)
