"""The bad-input suite (issue 12): every class of bad input ends in exit code != 0, one line
`error: ...` naming what is wrong, no traceback, and no partial or modified file."""

from __future__ import annotations

import builtins
import errno
import hashlib
import json
import sqlite3
from pathlib import Path

import pytest

from surfgen.generator import files
from surfgen.generator.formula import limits
from surfgen.pipelines.catalogue.store import SCHEMA
from surfgen.pipelines.cli.main import main
from tests.support.bad_input import bad_input_catalogue, corrupt, refused, snapshot


@pytest.fixture(scope="module")
def template(tmp_path_factory) -> tuple[Path, dict[str, str]]:
    """Two accepted shapes, one draw the filters rejected and one whose worker crashed."""
    return bad_input_catalogue(tmp_path_factory.mktemp("bad") / "cat")


# ----------------------------------------------------------------------------- 1. depth and size


@pytest.mark.parametrize(
    ("formula", "message"),
    [
        ("(" * 200 + "x" + ")" * 200, "nested too deeply"),
        ("sin(" * 3000 + "x" + ")" * 3000, "nested too deeply"),
        ("-" * 10000 + "x", "nested too deeply"),
        ("x^(-" * 150 + "x" + ")" * 150, "nested too deeply"),
        ("x" * 12_000_001, "formula too long"),
    ],
    ids=["parens", "nested-sin", "minus", "neg-tower", "megabytes"],
)
def test_formula_depth_and_size_limits(formula: str, message: str, tmp_path: Path, capsys) -> None:
    refused(["render", "--formula", formula, "-o", tmp_path / "m.ply"], capsys, message, tmp_path)


def test_a_formula_over_the_node_limit_is_refused(monkeypatch, tmp_path: Path, capsys) -> None:
    # the limit made small here: a real one takes half a million nodes (and seconds) to reach
    monkeypatch.setattr(limits, "MAX_FORMULA_NODES", 20_000)
    formula = "+".join(["x"] * 10_001)
    message = "formula too large: 20001 nodes once written out (at most 20000)"
    refused(["render", "--formula", formula, "-o", tmp_path / "m.ply"], capsys, message, tmp_path)


def test_long_flat_formulas_within_the_limits_work(tmp_path: Path, capsys) -> None:
    # 3,000-term sums (a tree 3,000 deep) and 2,000-high power towers: nothing recurses on them
    flat = "+".join(["0.001*x^2+0.001*y^2+0.001*z^2"] * 1000) + "-0.5"
    assert main(["render", "--formula", flat, "--grid", "8", "--box", "-1,1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["faces"] > 0
    tower = "^".join(["x"] * 2000)
    rc = main(["render", "--formula", tower, "--grid", "6", "--json"])
    err = capsys.readouterr().err
    assert rc in (0, 1) and "Traceback" not in err  # a clean result or 'no surface'


def test_spec_file_beyond_the_longest_formula(tmp_path: Path, capsys) -> None:
    spec = tmp_path / "big.json"
    terms = limits.MAX_SPEC_FILE_BYTES // 2
    spec.write_text(json.dumps({"formula": "x+" * terms + "x", "box": [-1, 1], "grid": 8}))
    message = f"larger than {limits.format_bytes(limits.MAX_SPEC_FILE_BYTES)}"
    refused(["render", "--spec", spec], capsys, message, tmp_path)


@pytest.mark.parametrize(
    ("where", "message"),
    [
        (" or ".join(["genus = 1"] * 3000), "too long"),
        (" or ".join(["genus = 1"] * 300), "more than 200 conditions"),
        ("(" * 100 + "genus = 1" + ")" * 100, "more than 50 nested"),
    ],
    ids=["or-chain", "conditions", "parens"],
)
def test_where_limits(template, where: str, message: str, capsys) -> None:
    root = template[0]
    refused(["catalogue", "list", "-C", root, "--where", where], capsys, message, root)


def test_where_negation_chains_are_flat(template, capsys) -> None:
    root = template[0]
    where = "not " * 5000 + "genus >= 1"
    refused(["catalogue", "list", "-C", root, "--where", where], capsys, "too long", root)
    where = "not " * 900 + "genus >= 1"  # an even number of 'not's: no NOT at all
    assert main(["catalogue", "list", "-C", str(root), "--where", where, "--json"]) == 0
    assert [r["genus"] for r in json.loads(capsys.readouterr().out)] == [1]


# ----------------------------------------------------------------------------- 2. memory


def test_memory_is_estimated_before_anything_is_allocated(template, tmp_path: Path, capsys) -> None:
    dense = ["render", "--preset", "sphere", "--grid", "1000", "--evaluator", "fast"]
    line = refused([*dense, "--max-memory", "4G"], capsys, "needs about", tmp_path)
    assert "7.5 GiB" in line and "limit of 4.0 GiB" in line  # the field alone is 7.45 GiB
    # the default (auto: sparse on large grids) counts the work that grows with the surface
    line = refused(
        ["render", "--preset", "sphere", "--grid", "1000", "--max-memory", "2G"],
        capsys,
        "needs about",
        tmp_path,
    )
    assert "sparse evaluator" in line and "sparse field" in line and "7.5 GiB" not in line
    refused(
        ["render", "--preset", "sphere", "--grid", "2048", "--evaluator", "fast"],
        capsys,
        "the available memory",
    )
    refused(
        ["sample", "--n", "2", "--grid", "2048", "--out", tmp_path / "cat"],
        capsys,
        "needs about",
        tmp_path,
    )
    assert not (tmp_path / "cat").exists()
    root, keys = template
    refused(
        ["export", keys["torus"], "-C", root, "--regrid", "2048", "-o", tmp_path / "o"],
        capsys,
        "needs about",
        root,
    )
    assert not (tmp_path / "o").exists()
    refused(["render", "--preset", "sphere", "--max-memory", "lots"], capsys, "--max-memory must")


def test_input_files_are_capped(tmp_path: Path, capsys) -> None:
    message = f"larger than {limits.format_bytes(limits.MAX_SPEC_FILE_BYTES)}"
    refused(["render", "--spec", "/dev/zero"], capsys, message, tmp_path)
    refused(["sample", "--config", "/dev/zero", "--out", tmp_path / "c"], capsys, "larger than")
    assert not (tmp_path / "c").exists()
    refused(["render", "--spec", tmp_path], capsys, "cannot read spec file")


# ----------------------------------------------------------------------------- 3. types in files

GOOD_SPEC = {"formula": "x^2+y^2+z^2-m", "box": [-1.5, 1.5], "grid": 12, "params": {"m": 1}}


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"params": [1, 2]}, "params must be an object"),
        ({"params": "m=1"}, "params must be an object"),
        ({"params": {"m": None}}, "params.m must be a finite number, got null"),
        ({"params": {"m": "1"}}, "params.m must be a finite number"),
        ({"level": "abc"}, "level must be a finite number"),
        ({"level": True}, "level must be a finite number"),
        ({"provenance": ["seed"]}, "provenance must be an object"),
        ({"provenance": "seed"}, "provenance must be an object"),
        ({"provenance": {"seed": float("inf")}}, "Infinity is not a JSON number"),
        ({"grid": [12, 12]}, "grid must be"),
        ({"grid": 12.5}, "grid must be"),
        ({"grid": True}, "grid must be"),
        ({"box": [0, "1"]}, "box must be 2 or 6 finite numbers"),
        ({"box": None}, "box must be"),
        ({"formula": 5}, "formula must be text"),
    ],
)
def test_spec_field_types(change: dict, message: str, tmp_path: Path, capsys) -> None:
    spec = tmp_path / "s.json"
    spec.write_text(json.dumps({**GOOD_SPEC, **change}))
    refused(["render", "--spec", spec, "-o", tmp_path / "m.ply"], capsys, message, tmp_path)


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        (b'{"formula": "x", "box": [-1, 1], "grid": Infinity}', "Infinity is not a JSON number"),
        (b'{"formula": "x", "box": [-1, NaN], "grid": 8}', "NaN is not a JSON number"),
        ('{"formula": "café", "box": [-1, 1], "grid": 8}'.encode("latin-1"), "not UTF-8"),
        (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "not UTF-8"),
        (b"[" * 10000 + b"]" * 10000, "nested more than 32"),
        (b'{"formula": "x", "box": [-1, 1], "grid": 8, "a\\u0000": 1}', "unknown key"),
        (b"[1, 2]", "expected a JSON object"),
    ],
    ids=["infinity", "nan", "latin-1", "binary", "deep", "nul-key", "list"],
)
def test_spec_file_encodings(raw: bytes, message: str, tmp_path: Path, capsys) -> None:
    spec = tmp_path / "s.json"
    spec.write_bytes(raw)
    refused(["render", "--spec", spec], capsys, message, tmp_path)


@pytest.mark.parametrize(
    ("toml", "message"),
    [
        ('[run]\ncap = "no"\n', 'cap must be true or false, got "no"'),
        ('[run]\nthumbnails = "no"\n', "thumbnails must be true or false"),
        ('[filters]\nrequire_manifold = "yes"\n', "require_manifold must be true or false"),
        ("[sampler]\nd_quantile = [1]\n", "d_quantile must be a list of 2 finite numbers"),
        ("[sampler]\nsum_terms_weights = [inf, 1, 1]\n", "sum_terms_weights must be a list of"),
        (
            "[sampler]\nsum_terms_weights = [1e308, 1e308, 1e308]\n",
            "sum_terms_weights add up to inf (each is divided by their sum, which must be finite)",
        ),
        ("[sampler]\nmix_weights = [1e308, 1e308, 1, 1, 1, 1]\n", "mix_weights add up to inf"),
        ("[sampler.sculpture]\ngroup_weights = [1e308, 1e308, 1, 1, 1, 1]\n", "add up to inf"),
        ("[sampler]\ncoefficient_max = nan\n", "coefficient_max must be a finite number"),
        ("[sampler]\nconstituent_p = [2, 100000000]\n", "constituent_p must be from 1 to 64"),
        ("[sampler]\nsum_terms = [1, 2, 300]\n", "sum_terms must be from 1 to 10"),
        ("[filters]\nmin_faces = 1.5\n", "min_faces must be a whole number"),
        ("[run]\ntimeout = 1e30\n", "timeout must be more than 0"),
        ("[run]\ngrid = true\n", "grid must be a whole number"),
        ("a = " + "[" * 500 + "]" * 500 + "\n", "nested more than 32"),
    ],
)
def test_config_field_types(toml: str, message: str, tmp_path: Path, capsys) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text(toml)
    refused(
        ["sample", "--n", "1", "--config", cfg, "--out", tmp_path / "cat"],
        capsys,
        message,
        tmp_path,
    )
    assert not (tmp_path / "cat").exists()


# ----------------------------------------------------------------------------- 4. output and disks


def fail_writes(monkeypatch, fragment: str, code: int, text: str) -> None:
    """Make writing any file whose name contains ``fragment`` fail with ``code``."""
    real = builtins.open

    def fake_open(file, mode="r", *args, **kwargs):
        if "x" in mode and fragment in Path(file).name:
            raise OSError(code, text, str(file))
        return real(file, mode, *args, **kwargs)

    monkeypatch.setattr(files, "open", fake_open, raising=False)


def test_render_writes_all_or_nothing(tmp_path: Path, monkeypatch, capsys) -> None:
    fail_writes(monkeypatch, "x.png", errno.ENOSPC, "No space left on device")
    line = refused(
        ["render", "--preset", "torus", "--grid", "16", "-o", tmp_path / "ok.ply", "--png",
         tmp_path / "x.png", "--save-field", tmp_path / "f.npy"],
        capsys,
        "No space left on device",
        tmp_path,
    )  # fmt: skip
    assert "x.png" in line
    assert list(tmp_path.iterdir()) == []  # not ok.ply, not f.npy, no temporary file


def test_output_paths_that_are_folders_or_read_only(
    template, tmp_path: Path, monkeypatch, capsys
) -> None:
    (tmp_path / "dir.ply").mkdir()
    refused(["render", "--preset", "torus", "-o", tmp_path / "dir.ply"], capsys, "is a folder")
    root, keys = template
    refused(["report", "-C", root, "-o", tmp_path], capsys, str(tmp_path), root)
    fail_writes(monkeypatch, "", errno.EACCES, "Permission denied")
    out = tmp_path / "export"
    refused(
        ["export", keys["sphere"], keys["torus"], "-C", root, "--format", "ply", "-o", out],
        capsys,
        "Permission denied",
        root,
    )
    assert not out.exists()
    refused(
        ["contact-sheet", "-C", root, "-o", tmp_path / "sheet.png"], capsys, "", root
    )  # no thumbnails in this catalogue: refused before writing anything
    assert not (tmp_path / "sheet.png").exists()


# ----------------------------------------------------------------------------- 5. catalogues


def foreign_database(path: Path, wal: bool = False) -> str:
    con = sqlite3.connect(path / "catalogue.sqlite")
    if wal:
        con.execute("PRAGMA journal_mode=WAL")
    con.execute("CREATE TABLE shapes (key TEXT, colour TEXT)")
    con.execute("INSERT INTO shapes VALUES ('abc', 'red')")
    con.commit()
    con.close()
    return hashlib.sha256((path / "catalogue.sqlite").read_bytes()).hexdigest()


@pytest.mark.parametrize(
    "command",
    [
        ["catalogue", "list"],
        ["catalogue", "star", "abc"],
        ["catalogue", "note", "abc", "hi"],
        ["catalogue", "check"],
        ["report"],
        ["sample", "--n", "1", "--grid", "8", "--out"],
    ],
)
@pytest.mark.parametrize("wal", [False, True], ids=["rollback", "wal"])
def test_a_foreign_sqlite_file_is_never_modified(command, wal, tmp_path: Path, capsys) -> None:
    root = tmp_path / "foreign"
    root.mkdir()
    foreign_database(root, wal)
    args = [*command, root] if command[-1] == "--out" else [*command, "-C", root]
    refused(args, capsys, "is not a surfgen catalogue", root)
    assert sorted(p.name for p in root.iterdir()) == ["catalogue.sqlite"]  # no -wal, no -shm


@pytest.mark.parametrize(
    "command",
    [
        ["catalogue", "list"],
        ["catalogue", "show", "0"],
        ["catalogue", "star", "0"],
        ["report"],
        ["export", "0", "-o", "OUT"],
        ["contact-sheet", "-o", "OUT.png"],
    ],
)
def test_a_corrupted_catalogue_says_run_check(command, cat_dir, tmp_path, capsys) -> None:
    corrupt(cat_dir)
    args = [str(tmp_path / "o" / a) if a.startswith("OUT") else a for a in command]
    refused([*args, "-C", cat_dir], capsys, "catalogue check")
    assert not (tmp_path / "o").exists()


def test_catalogue_check_and_repair(cat_dir, template, capsys) -> None:
    keys = template[1]
    assert main(["catalogue", "check", "-C", str(cat_dir)]) == 0
    assert "database: ok" in capsys.readouterr().out
    # a missing mesh, an orphan and a temporary file
    (cat_dir / "meshes" / f"{keys['torus']}.ply").unlink()
    (cat_dir / "meshes" / "0123456789abcdef.ply").write_bytes(b"orphan")
    (cat_dir / "thumbs").mkdir(exist_ok=True)
    (cat_dir / "thumbs" / ".x.png.1.tmp").write_bytes(b"half")
    assert main(["catalogue", "check", "-C", str(cat_dir)]) == 1
    out = capsys.readouterr().out
    assert "missing: 1" in out and "orphan files (no row names them): 1" in out
    assert "temporary files left by interrupted writes: 1" in out
    assert main(["catalogue", "check", "-C", str(cat_dir), "--repair"]) == 0
    capsys.readouterr()
    assert (cat_dir / "meshes" / f"{keys['torus']}.ply").is_file()  # re-made from its spec
    assert (cat_dir / "orphans" / "meshes-0123456789abcdef.ply").is_file()
    assert main(["catalogue", "check", "-C", str(cat_dir)]) == 0
    capsys.readouterr()
    assert main(["check", str(cat_dir / "meshes" / f"{keys['torus']}.ply"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["genus"] == 1


def test_repair_of_a_damaged_database_keeps_the_readable_rows(cat_dir, capsys) -> None:
    db = cat_dir / "catalogue.sqlite"
    con = sqlite3.connect(db)
    con.execute("CREATE TABLE padding (x BLOB)")  # damage lands in this table only
    con.executemany("INSERT INTO padding VALUES (?)", [(bytes(3000),)] * 20)
    con.commit()
    pages = [r[0] for r in con.execute("SELECT pageno FROM dbstat WHERE name='padding'")]
    page = con.execute("PRAGMA page_size").fetchone()[0]
    con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    con.close()
    data = bytearray(db.read_bytes())
    for p in pages[1:4]:
        data[(p - 1) * page : p * page] = b"\xff" * page
    db.write_bytes(bytes(data))
    assert main(["catalogue", "check", "-C", str(cat_dir)]) == 1
    assert "CORRUPTED" in capsys.readouterr().out
    assert main(["catalogue", "check", "-C", str(cat_dir), "--repair"]) == 0
    out = capsys.readouterr().out
    assert "database rebuilt" in out
    assert list(cat_dir.glob("catalogue.sqlite.corrupt-*"))  # the damaged file is kept
    assert main(["catalogue", "list", "-C", str(cat_dir), "--all", "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)) == 4  # every shape row survived


def test_reading_a_catalogue_changes_nothing_on_disk(template, capsys) -> None:
    root, keys = template
    before = snapshot(root)
    names = sorted(p.name for p in root.iterdir())
    for args in (["catalogue", "list"], ["catalogue", "show", keys["torus"][:6]]):
        assert main([*args, "-C", str(root)]) == 0
    capsys.readouterr()
    assert snapshot(root) == before and sorted(p.name for p in root.iterdir()) == names


# ----------------------------------------------------------------------------- 6. numbers


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--seed", "-1"], "--seed must be a whole number from 0 to 2^63-1, got -1"),
        (["--seed", str(2**63)], "--seed must be"),
        (["--seed", str(2**70)], "--seed must be"),
        (["--n", str(2**64)], "--n must be a whole number from 1"),
        (["--n", "0"], "--n must be"),
        (["--grid", "3"], "--grid must be a whole number from 4 to 2048"),
        (["--workers", "0"], "--workers must be"),
        (["--max-draws", str(2**64)], "--max-draws must be"),
    ],
)
def test_numbers_are_checked_before_anything_is_created(
    args, message, tmp_path: Path, capsys
) -> None:
    refused(["sample", "--out", tmp_path / "cat", *args], capsys, message, tmp_path)
    assert not (tmp_path / "cat").exists()


def test_huge_limits(template, tmp_path, capsys) -> None:
    root = template[0]
    refused(["catalogue", "list", "-C", root, "--limit", str(2**64)], capsys, "--limit must")
    refused(
        ["catalogue", "list", "-C", root, "--sort", ",".join(["genus"] * 20)], capsys, "at most"
    )
    refused(["contact-sheet", "-C", root, "--limit", str(2**40)], capsys, "--limit must")
    refused(["report", "-C", root, "--run", str(2**64)], capsys, "out of range", root)
    refused(["catalogue", "show", "-C", root, "f" * 100_000], capsys, "is not a shape key", root)


# ----------------------------------------------------------------------------- 7. time


@pytest.mark.parametrize(
    ("option", "message"),
    [
        (["--smooth", "100000000"], "--smooth takes at most 1000 steps"),
        (["--target-faces", str(10**12)], "--target-faces must be at most"),
        (["--target-edge", "1e-9"], "would make about"),
    ],
)
def test_iteration_counts_are_bounded(template, option, message, tmp_path, capsys) -> None:
    root, keys = template
    refused(["export", keys["sphere"], "-C", root, "-o", tmp_path / "o", *option], capsys, message)
    assert not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------- 8. nonsense


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--formula", "x^2+y^2-1", "--param", "q=1"], "parameter 'q' is not used by the formula"),
        (["--preset", "sphere", "--box", ""], "--box must be numbers separated by commas, got ''"),
        (["--preset", "sphere", "--grid", ""], "--grid must be whole numbers"),
        (["--preset", "sphere", "--grid", ","], "--grid must be whole numbers"),
        (["--preset", "eqC", "--param", "m=nan"], "must be a finite number"),
    ],
)
def test_nonsense_options_are_refused(args, message, tmp_path, capsys) -> None:
    refused(["render", *args, "-o", tmp_path / "m.ply"], capsys, message, tmp_path)


def test_obj_index_zero(tmp_path: Path, capsys) -> None:
    obj = tmp_path / "zero.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 0 1 2\nf 1 2 3\n")
    refused(["check", obj], capsys, "line 5: face index 0", tmp_path)


def test_render_from_a_rejected_or_failed_draw(template, tmp_path, capsys) -> None:
    root, keys = template
    refused(["render", "--from", root, keys["crashed"]], capsys, "was never evaluated", root)
    out = tmp_path / "blob.ply"
    assert main(["render", "--from", str(root), keys["blob"], "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "warning: shape" in err and "rejected by the filters (blob)" in err
    assert out.is_file()


# ----------------------------------------------------------------------------- 9. old catalogues


def test_a_catalogue_from_before_the_schema_row_is_recognised(tmp_path: Path, capsys) -> None:
    root = tmp_path / "old"
    root.mkdir()
    con = sqlite3.connect(root / "catalogue.sqlite")
    con.executescript(SCHEMA)  # what surfgen made before: no `surfgen` table
    con.close()
    assert main(["catalogue", "list", "-C", str(root)]) == 0
    con = sqlite3.connect(root / "catalogue.sqlite")
    assert "surfgen" not in {r[0] for r in con.execute("SELECT name FROM sqlite_master")}
    con.close()  # reading did not upgrade it; the first write does
    assert main(["sample", "--n", "1", "--max-draws", "1", "--grid", "8", "--out", str(root),
                 "--no-thumbnails", "--workers", "1"]) in (0, 1)  # fmt: skip
    capsys.readouterr()
    con = sqlite3.connect(root / "catalogue.sqlite")
    assert con.execute("SELECT value FROM surfgen WHERE key='schema'").fetchone() == ("1",)
    con.close()
