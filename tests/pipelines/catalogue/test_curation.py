"""Tests for surfgen.pipelines.catalogue.curation: queries, curation writes, the catalogue CLI and
near-duplicate marking, on a catalogue built from the canonical shapes (the --where language
alone: test_query.py)."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest

from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import extract_mesh
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.curation import (
    CurationError,
    apply_action,
    dedupe_catalogue,
    select_shapes,
)
from surfgen.pipelines.catalogue.store import CatalogueError, open_catalogue
from surfgen.pipelines.cli.main import main
from tests.support.catalogues import catalogue_shapes
from tests.support.commands import heavy_modules_loaded

SPHERE = "x^2+y^2+z^2-1"
# name: (formula, half box, grid); sphere_moved and sphere_fine copy the sphere by construction.
SHAPES = {
    "sphere": (SPHERE, 1.5, 40),
    "torus": ("(sqrt(x^2+y^2)-1)^2+z^2-0.16", 1.6, 40),
    "genus2": ("(x^2*(1-x^2)-y^2)^2+z^2-0.04", 1.3, 40),
    "two_spheres": ("min((x-0.8)^2+y^2+z^2-0.25, (x+0.8)^2+y^2+z^2-0.25)", 1.5, 40),
    "sphere_moved": ("(x-0.1)^2+(y+0.06)^2+(z-0.05)^2-1", 1.5, 40),
    "sphere_fine": (SPHERE, 1.5, 52),
}
NOISE = "sin(9*x)*sin(9*y)*sin(9*z)"


def build_catalogue(root: Path) -> dict[str, str]:
    """A catalogue of one run: the SHAPES accepted (meshes, metrics) and one rejected draw.
    Returns {name: key}."""
    specs = {
        name: SurfaceSpec(formula, (-half, half) * 3, (n, n, n), provenance={"index": i})
        for i, (name, (formula, half, n)) in enumerate(SHAPES.items())
    }
    items = [
        (spec, extract_mesh(evaluate_reference(parse(spec.formula), spec.to_grid()), 0.0))
        for spec in specs.values()
    ]
    keys = dict(zip(specs, catalogue_shapes(root, items), strict=True))
    with open_catalogue(root) as cat:
        (run,) = cat.runs()
        run = cat.get_run(run["id"])
        spec = SurfaceSpec(NOISE, (-1.0, 1.0) * 3, (20, 20, 20), provenance={"index": 99})
        row = {
            "key": spec.key,
            "spec": spec.to_json(),
            "formula": spec.formula,
            "identity": spec.key,
            "verdict": "rejected",
            "reasons": '["noise"]',
            "metrics": "{}",
        }
        cat.record_shape(run.id, len(SHAPES), row, False, {"noise": 1})
        keys["noise"] = spec.key
    return keys


@pytest.fixture(scope="module")
def template(tmp_path_factory) -> tuple[Path, dict[str, str]]:
    root = tmp_path_factory.mktemp("curation") / "cat"
    return root, build_catalogue(root)


@pytest.fixture
def keys(template) -> dict[str, str]:
    return template[1]


def names_of(recs, keys) -> set[str]:
    by_key = {v: k for k, v in keys.items()}
    return {by_key[r["key"]] for r in recs}


# ----------------------------------------------------------------------------- --where


def test_where_selects_by_metrics(cat_dir, keys) -> None:
    with open_catalogue(cat_dir, must_exist=True) as cat:

        def sel(expr: str) -> set[str]:
            return names_of(select_shapes(cat, where=expr), keys)

        assert sel("genus >= 1") == {"torus", "genus2"}
        assert sel("genus = 2 and components < 5 and run = 1") == {"genus2"}
        assert sel("components = 2") == {"two_spheres"}
        assert sel("genus = 1 or components > 1") == {"torus", "two_spheres"}
        assert sel("not (genus = 0)") == {"torus", "genus2"}
        assert sel("formula ~ SQRT") == {"torus"}
        assert sel(f"key = {keys['torus'][:6]}") == {"torus"}
        assert sel(f"key != {keys['torus']}") == set(SHAPES) - {"torus"}
        assert sel("faces > 0 and area > 0 and box_fraction = 0") == set(SHAPES)
        assert sel("index <= 1") == {"sphere", "torus"}
        assert sel("") == set(SHAPES)  # accepted only by default
        assert sel("reason = noise") == {"noise"}  # mentions reason: rejected draws included
        assert sel("verdict = rejected") == {"noise"}
        assert names_of(select_shapes(cat, everything=True), keys) == set(keys)


def test_where_tags_stars_and_flags(cat_dir, keys) -> None:
    with open_catalogue(cat_dir, must_exist=True) as cat:
        apply_action(cat, keys["torus"], "tag", ["nice", "donut"])
        apply_action(cat, keys["genus2"], "tag", ["nice"])
        apply_action(cat, keys["genus2"], "star", 3)
        apply_action(cat, keys["sphere"], "reject", "boring")
        apply_action(cat, keys["two_spheres"], "note", "Twin balls")

        def sel(expr: str) -> set[str]:
            return names_of(select_shapes(cat, where=expr), keys)

        assert sel("tag = nice") == {"torus", "genus2"}
        assert sel("tag = NICE and tag != donut") == {"genus2"}
        assert sel("tag ~ don") == {"torus"}
        assert sel("stars > 0") == sel("starred") == {"genus2"}
        assert sel("genus >= 2 and components < 5 and tag = nice and stars > 0 and run = 1") == {
            "genus2"
        }
        assert sel("rejected") == sel("rejected = yes") == {"sphere"}
        assert "sphere" not in sel("not rejected")
        assert sel("note ~ twin") == {"two_spheres"}
        assert sel("note = null and genus = 0") == {"sphere_moved", "sphere_fine", "sphere"}
        assert sel("duplicate = no") == set(SHAPES)


def test_where_values_are_bound_not_spliced(cat_dir, keys) -> None:
    with open_catalogue(cat_dir, must_exist=True) as cat:
        assert select_shapes(cat, where='note = "x\' OR 1=1 --"') == []
        assert select_shapes(cat, where="tag = 'a; DROP TABLE shapes'") == []
        assert len(select_shapes(cat)) == len(SHAPES)  # the table is still there


def test_sort(cat_dir, keys) -> None:
    with open_catalogue(cat_dir, must_exist=True) as cat:
        faces = [r["faces"] for r in select_shapes(cat, sort="-faces")]
        assert faces == sorted(faces, reverse=True)
        recs = select_shapes(cat, sort="genus,-area", limit=3)
        assert len(recs) == 3 and [r["genus"] for r in recs] == [0, 0, 0]
        assert [r["area"] for r in recs] == sorted((r["area"] for r in recs), reverse=True)
        assert len(select_shapes(cat, sort="random")) == len(SHAPES)
        assert select_shapes(cat, limit=0) == []


# ----------------------------------------------------------------------------- writes


def test_actions_commit_at_once_and_are_logged(cat_dir, keys) -> None:
    key = keys["torus"]
    with open_catalogue(cat_dir, must_exist=True) as cat:
        rec = apply_action(cat, key[:7], "star")
        assert rec["stars"] == 1
        other = sqlite3.connect(cat_dir / "catalogue.sqlite")  # another reader sees it now
        assert other.execute("SELECT stars FROM shapes WHERE key=?", (key,)).fetchone() == (1,)
        assert apply_action(cat, key, "star", 0)["stars"] == 0
        assert apply_action(cat, key, "tag", [" Nice ", "nice", "spiky"])["tags"] == [
            "nice",
            "spiky",
        ]
        assert apply_action(cat, key, "untag", "spiky")["tags"] == ["nice"]
        assert apply_action(cat, key, "reject", "  too plain ")["rejected"] == "too plain"
        assert apply_action(cat, key, "unreject")["rejected"] is None
        assert apply_action(cat, key, "note", "a note")["note"] == "a note"
        assert apply_action(cat, key, "note", "")["note"] is None
        actions = [r[0] for r in other.execute("SELECT action FROM curation WHERE key=?", (key,))]
        assert actions == ["star", "star", "tag", "untag", "reject", "unreject", "note", "note"]
        other.close()


@pytest.mark.parametrize(
    ("action", "value", "fragment"),
    [
        ("star", 6, "from 0 to 5"),
        ("star", -1, "from 0 to 5"),
        ("star", "many", "whole number"),
        ("star", True, "whole number"),
        ("reject", "  ", "say why"),
        ("tag", ["bad tag"], "bad tag"),
        ("tag", [], "at least one tag"),
        ("tag", ["-x"], "bad tag"),
        ("explode", None, "unknown action"),
    ],
)
def test_bad_actions_change_nothing(cat_dir, keys, action, value, fragment) -> None:
    with open_catalogue(cat_dir, must_exist=True) as cat:
        with pytest.raises(CurationError, match=fragment):
            apply_action(cat, keys["torus"], action, value)
        assert cat.conn.execute("SELECT count(*) FROM curation").fetchone()[0] == 0


def test_bad_keys(cat_dir) -> None:
    with open_catalogue(cat_dir, must_exist=True) as cat:
        with pytest.raises(CatalogueError, match="not a shape key"):
            apply_action(cat, "zz-top", "star")
        with pytest.raises(CatalogueError, match="no shape with key"):
            apply_action(cat, "0000000000", "star")


# ----------------------------------------------------------------------------- de-duplication


def test_dedupe_marks_duplicates_by_construction(cat_dir, keys) -> None:
    with open_catalogue(cat_dir, must_exist=True) as cat:
        dry = dedupe_catalogue(cat, dry_run=True)
        assert dry.computed == len(SHAPES)
        assert {(k, of) for k, of, _ in dry.marked} == {
            (keys["sphere_moved"], keys["sphere"]),
            (keys["sphere_fine"], keys["sphere"]),
        }
        assert (
            cat.conn.execute(
                "SELECT count(*) FROM shapes WHERE duplicate_of IS NOT NULL"
            ).fetchone()[0]
            == 0
        )
        res = dedupe_catalogue(cat)
        assert res.computed == 0  # descriptors were stored by the dry run
        assert names_of(select_shapes(cat, where="duplicate"), keys) == {
            "sphere_moved",
            "sphere_fine",
        }
        assert cat.shape(keys["sphere_fine"])["duplicate_of"] == keys["sphere"]
        dedupe_catalogue(cat, threshold=1e-9)  # a new threshold replaces the marks
        assert select_shapes(cat, where="duplicate") == []
        with pytest.raises(CurationError, match="threshold"):
            dedupe_catalogue(cat, threshold=0)


# ----------------------------------------------------------------------------- CLI


def run_cli(capsys, *args: str) -> tuple[int, str, str]:
    rc = main(list(args))
    out, err = capsys.readouterr()
    return rc, out, err


def test_cli_list_and_show(cat_dir, keys, capsys) -> None:
    c = str(cat_dir)
    rc, out, _ = run_cli(capsys, "catalogue", "list", "-C", c)
    assert rc == 0 and all(keys[n] in out for n in SHAPES) and keys["noise"] not in out
    rc, out, _ = run_cli(capsys, "catalogue", "list", "-C", c, "--all", "--sort", "-genus")
    assert rc == 0 and keys["noise"] in out and "filtered:noise" in out
    rc, out, _ = run_cli(
        capsys, "catalogue", "list", "-C", c, "--where", "genus >= 1", "--sort", "-genus", "--json"
    )
    recs = json.loads(out)
    assert rc == 0 and [r["genus"] for r in recs] == [2, 1]
    rc, out, _ = run_cli(capsys, "catalogue", "list", "-C", c, "--limit", "2", "--json")
    assert len(json.loads(out)) == 2
    rc, out, _ = run_cli(capsys, "catalogue", "show", keys["torus"][:8], "-C", c)
    assert rc == 0 and "(sqrt(x^2+y^2)-1)^2+z^2-0.16" in out and "genus" in out
    rc, out, _ = run_cli(capsys, "catalogue", "show", keys["torus"], "-C", c, "--json")
    rec = json.loads(out)
    assert rec["key"] == keys["torus"] and rec["genus"] == 1 and rec["run_info"]["seed"] == 0


def test_cli_curation_writes_the_catalogue(cat_dir, keys, capsys) -> None:
    c, k = str(cat_dir), keys["genus2"]
    assert run_cli(capsys, "catalogue", "star", k[:6], "-C", c)[0] == 0
    assert run_cli(capsys, "catalogue", "star", k, "4", "-C", c)[0] == 0
    assert run_cli(capsys, "catalogue", "tag", k, "nice", "Handles", "-C", c)[0] == 0
    assert run_cli(capsys, "catalogue", "untag", k, "nice", "-C", c)[0] == 0
    assert run_cli(capsys, "catalogue", "note", k, "two holes", "-C", c)[0] == 0
    rc, out, _ = run_cli(capsys, "catalogue", "reject", k, "--why", "too thin", "-C", c)
    assert rc == 0 and "rejected too thin" in out
    with open_catalogue(cat_dir, must_exist=True) as cat:
        row = cat.shape(k)
    assert (row["stars"], row["tags"], row["note"], row["user_rejected"]) == (
        4,
        ["handles"],
        "two holes",
        "too thin",
    )
    assert run_cli(capsys, "catalogue", "unreject", k, "-C", c)[0] == 0
    with open_catalogue(cat_dir, must_exist=True) as cat:
        assert cat.shape(k)["user_rejected"] is None


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (("catalogue", "star", "xyz"), "error: 'xyz' is not a shape key"),
        (("catalogue", "show", "0000000000"), "error: no shape with key '0000000000'"),
        (("catalogue", "tag", "0000000000", "nice"), "error: no shape with key"),
        (("catalogue", "star", "{torus}", "9"), "error: stars must be from 0 to 5"),
        (("catalogue", "tag", "{torus}", "no good"), "error: bad tag 'no good'"),
        (("catalogue", "list", "--where", "genus >>= 2"), "error: --where: expected a value"),
        (
            ("catalogue", "list", "--where", "colour = red"),
            "error: --where: unknown field 'colour'",
        ),
        (("catalogue", "list", "--sort", "colour"), "error: --sort: unknown field 'colour'"),
        (("catalogue", "dedupe", "--threshold", "200"), "error: --threshold must be in (0, 100]"),
    ],
)
def test_cli_errors_are_one_line(cat_dir, keys, capsys, args, fragment) -> None:
    args = tuple(a.format(**keys) for a in args)
    rc, out, err = run_cli(capsys, *args, "-C", str(cat_dir))
    assert rc == 1
    assert err.startswith(fragment) and err.count("\n") == 1, err
    if "--where" in args:
        assert "column" in err and "fields:" in err


def test_cli_usage_errors(cat_dir, keys, capsys, tmp_path) -> None:
    rc, _, err = run_cli(capsys, "catalogue", "reject", keys["torus"], "-C", str(cat_dir))
    assert rc == 2 and "--why" in err
    rc, _, err = run_cli(capsys, "catalogue", "list", "-C", str(tmp_path / "nowhere"))
    assert rc == 1 and err.startswith("error: no catalogue at")
    assert not (tmp_path / "nowhere").exists()


def test_cli_dedupe(cat_dir, keys, capsys) -> None:
    rc, out, _ = run_cli(capsys, "catalogue", "dedupe", "-C", str(cat_dir), "--dry-run")
    assert rc == 0 and "2 near duplicates among 6" in out and "dry run" in out
    rc, out, _ = run_cli(capsys, "catalogue", "dedupe", "-C", str(cat_dir))
    assert rc == 0 and f"{keys['sphere_fine']} duplicates {keys['sphere']}" in out
    rc, out, _ = run_cli(capsys, "catalogue", "list", "-C", str(cat_dir), "--where", "duplicate")
    assert keys["sphere_moved"] in out and f"dup:{keys['sphere'][:8]}" in out


def test_catalogue_commands_load_no_kernel_library(cat_dir: Path, keys) -> None:
    root, key = str(cat_dir), next(iter(keys.values()))
    for args in (
        ("catalogue", "list", "-C", root),
        ("catalogue", "show", "-C", root, "--json", key),
        ("catalogue", "tag", "-C", root, key, "light"),
        ("catalogue", "star", "-C", root, key, "3"),
    ):
        assert heavy_modules_loaded(*args) == [], args
    with open_catalogue(cat_dir, readonly=True) as cat:  # and they did their work
        row = cat.shape(key)
    assert row["stars"] == 3 and "light" in row["tags"]
