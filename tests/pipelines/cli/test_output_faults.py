"""Outputs under faults (issue 12): a rename that fails half-way through a command's commit,
a full disk while the static gallery is written, and read-only folders and catalogues made
real — the commands run as an unprivileged user (uid 65534) in a forked child of this test
process, so the kernel's permission checks apply (root ignores permission bits), at no cost of
a new interpreter. Each asserts exit code != 0, one `error:` line naming the path and why, no
traceback, and no partial or modified file."""

from __future__ import annotations

import errno
import hashlib
import io
import json
import os
import shutil
import signal
import sys
import tempfile
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from surfgen.pipelines.cli.main import main
from surfgen.pipelines.run.warmup import COMPILE_NOTICE
from tests.support.catalogues import SPHERE_AND_TORUS, catalogue_formulas

NOBODY = 65534


def snapshot(root: Path) -> dict[str, str | None]:
    """Every file and folder under ``root`` (files with the hash of their bytes)."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        if p.is_file()
        else None
        for p in sorted(root.rglob("*"))
    }


def one_line(rc: int, err: str, *fragments: str) -> str:
    # a command that computes says first, on a cold numba cache, that it compiles (a notice,
    # not its output); the error itself is one line
    lines = [x for x in err.strip().splitlines() if not x.startswith(COMPILE_NOTICE)]
    assert rc != 0 and len(lines) == 1 and lines[0].startswith("error: "), (rc, err)
    assert "Traceback" not in err
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    return lines[0]


def cli(capsys, *args) -> tuple[int, str, str]:
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def fail_nth_rename(monkeypatch, under: Path, nth: int = 2) -> list[str]:
    """Make the ``nth`` ``os.replace`` onto a path under ``under`` fail (as a disk that went
    away would); renames elsewhere (numba's cache) are left alone. Returns the targets."""
    real = os.replace
    seen: list[str] = []

    def replace(src, dst, *args, **kwargs):
        if str(dst).startswith(str(under)):
            seen.append(str(dst))
            if len(seen) == nth:
                raise OSError(errno.EIO, "Input/output error", str(dst))
        return real(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "replace", replace)
    return seen


@pytest.fixture(scope="module")
def template(tmp_path_factory) -> tuple[Path, dict[str, str]]:
    """Two accepted shapes with thumbnails and turntables."""
    root = tmp_path_factory.mktemp("outputs") / "cat"
    keys = catalogue_formulas(root, SPHERE_AND_TORUS, seed=5, grid=20)
    assert main(["thumbnails", "-C", str(root)]) == 0
    return root, keys


# ----------------------------------------------------------------------------- a rename fails


def test_render_rolls_back_when_the_second_rename_fails(tmp_path: Path, monkeypatch, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "ok.ply").write_bytes(b"an earlier mesh")  # overwritten, then put back
    (out / "f.npy").write_bytes(b"an earlier field")
    before = snapshot(out)
    seen = fail_nth_rename(monkeypatch, out)
    rc, _, err = cli(capsys, "render", "--preset", "torus", "--grid", "16", "--save-field",
                     out / "f.npy", "-o", out / "ok.ply", "--png", out / "x.png")  # fmt: skip
    one_line(rc, err, str(out / "ok.ply"), "Input/output error")
    assert seen[:2] == [str(out / "f.npy"), str(out / "ok.ply")]  # the field was in already
    assert snapshot(out) == before  # the old field is back, no picture, no temporary file


def test_export_rolls_back_when_the_second_rename_fails(
    template, tmp_path: Path, monkeypatch, capsys
) -> None:
    root, keys = template
    out = tmp_path / "export"
    rc, _, _ = cli(capsys, "export", keys["sphere"], keys["torus"], "-C", root, "--format",
                   "stl", "-o", out)  # fmt: skip
    assert rc == 0 and len(list(out.iterdir())) == 4  # two meshes, two sidecars
    for p in out.iterdir():
        p.write_bytes(b"an earlier export of " + p.name.encode())
    before = snapshot(out)
    fail_nth_rename(monkeypatch, out)
    rc, _, err = cli(capsys, "export", keys["sphere"], keys["torus"], "-C", root, "--format",
                     "stl", "-o", out)  # fmt: skip
    one_line(rc, err, str(out), "Input/output error")
    assert snapshot(out) == before


def test_mathmod_render_and_import_roll_back(tmp_path: Path, monkeypatch, capsys) -> None:
    ball = {
        "Iso3D": {
            "Name": ["Ball"], "Component": ["S"], "Fxyz": ["x^2+y^2+z^2-1"], "Grid": ["16"],
            **{f"{a}{m}": [v] for a in "XYZ" for m, v in (("min", "-1.5"), ("max", "1.5"))},
        }
    }  # fmt: skip
    script = tmp_path / "script.json"
    script.write_text(
        json.dumps({"MathModels": [ball, {"Iso3D": {**ball["Iso3D"], "Name": ["Cube"]}}]})
    )
    out = tmp_path / "out"
    out.mkdir()
    (out / "ball.ply").write_bytes(b"an earlier mesh")
    (out / "Ball.json").write_bytes(b"an earlier spec")
    before = snapshot(out)
    fail_nth_rename(monkeypatch, out)
    rc, _, err = cli(capsys, "render", "--mathmod", script, "--name", "Ball", "-o",
                     out / "ball.ply", "--png", out / "ball.png")  # fmt: skip
    one_line(rc, err, str(out / "ball.png"), "Input/output error")
    assert snapshot(out) == before  # the earlier mesh is back
    monkeypatch.undo()
    fail_nth_rename(monkeypatch, out)  # Ball.json replaced, Cube.json fails
    rc, _, err = cli(capsys, "import", "mathmod", script, "-o", out)
    one_line(rc, err, str(out / "Cube.json"), "Input/output error")
    assert snapshot(out) == before


# ----------------------------------------------------------------------------- the gallery


def test_gallery_is_replaced_whole_or_not_at_all(
    template, tmp_path: Path, monkeypatch, capsys
) -> None:
    root, keys = template
    site = tmp_path / "site"
    rc, _, _ = cli(capsys, "gallery", "-C", root, "-o", site, "--where", "genus = 0")
    assert rc == 0 and len(list((site / "thumbs").iterdir())) == 1
    before = snapshot(site)
    real_copy = shutil.copy2
    copies: list[str] = []

    def full_disk(src, dst, **kwargs):  # the disk fills up at the third file copied
        copies.append(str(dst))
        if len(copies) == 3:
            raise OSError(errno.ENOSPC, "No space left on device", str(dst))
        return real_copy(src, dst, **kwargs)

    monkeypatch.setattr(shutil, "copy2", full_disk)
    rc, _, err = cli(capsys, "gallery", "-C", root, "-o", site)
    line = one_line(rc, err, str(site), "No space left on device", "was left as it was")
    assert ".tmp" not in line  # names the gallery's own path, not the temporary folder
    assert snapshot(site) == before and [p.name for p in tmp_path.iterdir()] == ["site"]
    monkeypatch.undo()
    rc, _, _ = cli(capsys, "gallery", "-C", root, "-o", site)  # now it is replaced
    assert rc == 0 and len(list((site / "thumbs").iterdir())) == 2
    assert [p.name for p in tmp_path.iterdir()] == ["site"]


def test_gallery_never_replaces_a_folder_with_other_files(template, tmp_path: Path, capsys):
    root, _ = template
    (tmp_path / "notes.txt").write_text("mine")
    before = snapshot(tmp_path)
    rc, _, err = cli(capsys, "gallery", "-C", root, "-o", tmp_path)
    one_line(rc, err, str(tmp_path), "notes.txt", "new or empty folder")
    assert snapshot(tmp_path) == before
    (tmp_path / "notes.txt").unlink()
    (tmp_path / "file").write_text("x")
    rc, _, err = cli(capsys, "gallery", "-C", root, "-o", tmp_path / "file")
    one_line(rc, err, str(tmp_path / "file"), "is a file")


# ----------------------------------------------------------------------------- read-only, really


def import_everything() -> None:
    """Import what the commands import lazily, while still root: the interpreter's standard
    library may live where the other user cannot read (here ``/root/.pyenv``, ``/root`` is
    0700), and a module imported after the switch would not be found."""
    import importlib
    import pkgutil

    for package in ("generator", "filters", "pipelines"):
        path = importlib.import_module(f"surfgen.{package}").__path__
        for mod in pkgutil.walk_packages(path, f"surfgen.{package}."):
            importlib.import_module(mod.name)
    for name in ("matplotlib.pyplot", "matplotlib.font_manager", "jinja2", "plistlib"):
        importlib.import_module(name)


def as_user(uid: int, run: Callable[[], object]) -> object:
    """``run()`` in a forked child that became user ``uid`` (no groups); its return value,
    or the traceback text of what it raised. The child shares this process's compiled code
    and imported modules (see :func:`import_everything`)."""
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        os.close(read)
        signal.alarm(120)  # a child stuck on a lock another thread held at the fork dies
        try:
            os.setgroups([])
            os.setresgid(uid, uid, uid)
            os.setresuid(uid, uid, uid)
            result: object = run()
        except BaseException:
            result = {"traceback": traceback.format_exc()}
        with os.fdopen(write, "w") as pipe:
            json.dump(result, pipe)
        os._exit(0)
    os.close(write)
    with os.fdopen(read) as pipe:
        text = pipe.read()
    _, status = os.waitpid(pid, 0)
    assert text, f"the child died without an answer (wait status {status})"
    return json.loads(text)


def can_drop_privileges() -> bool:
    if os.geteuid() != 0:
        return False
    try:
        return as_user(NOBODY, lambda: os.geteuid()) == NOBODY
    except OSError:
        return False


def run_commands(commands: list[list[str]]) -> list[tuple[int, str]]:
    """Each command through the CLI's ``main``, with its exit code and what it printed on
    stderr (in the child: ``sys.stderr`` is a buffer)."""
    results = []
    for args in commands:
        real, sys.stderr = sys.stderr, io.StringIO()
        try:
            rc = main(args)
            err = sys.stderr.getvalue()
        finally:
            sys.stderr = real
        results.append((rc, err))
    return results


@pytest.fixture
def base() -> Iterator[Path]:
    """A folder others can reach (pytest's own tmp folders are private to root)."""
    path = Path(tempfile.mkdtemp(prefix="surfgen-ro-"))
    path.chmod(0o755)
    try:
        yield path
    finally:
        for p in [path, *path.rglob("*")]:
            if not p.is_symlink():
                p.chmod(0o755 if p.is_dir() else 0o644)
        shutil.rmtree(path)


def read_only(root: Path) -> None:
    for p in [root, *root.rglob("*")]:
        p.chmod(0o555 if p.is_dir() else 0o444)


@pytest.mark.skipif(
    not can_drop_privileges(), reason="needs root and setuid to act as an unprivileged user"
)
def test_read_only_folders_and_catalogue_for_real(template, base: Path, capsys) -> None:
    root, keys = template
    cat = base / "cat"
    shutil.copytree(root, cat)
    ro = base / "ro"  # a folder the user cannot write in
    old = ro / "old-site"  # an earlier gallery in it
    assert main(["gallery", "-C", str(cat), "-o", str(old)]) == 0
    capsys.readouterr()
    ok = base / "ok"
    ok.mkdir()
    ok.chmod(0o777)
    read_only(cat)
    read_only(ro)
    before = snapshot(base)
    sphere = keys["sphere"]
    commands = {
        "export": ["export", sphere, "-C", cat, "--format", "ply", "-o", ro / "exp"],
        "export-into": ["export", sphere, "-C", cat, "--format", "ply", "-o", ro],
        "render": ["render", "--preset", "torus", "--grid", "16", "-o", ro / "x.ply"],
        "report": ["report", "-C", cat, "-o", ro / "report.html"],
        "contact-sheet": ["contact-sheet", "-C", cat, "-o", ro / "sheet.png"],
        "gallery": ["gallery", "-C", cat, "-o", ro / "site"],
        "gallery-old": ["gallery", "-C", cat, "-o", old],
        "star": ["catalogue", "star", sphere, "3", "-C", cat],
        "list": ["catalogue", "list", "-C", cat, "--json"],
        "show": ["catalogue", "show", sphere, "-C", cat, "--json"],
        "gallery-ok": ["gallery", "-C", cat, "-o", ok / "site"],
        "export-ok": ["export", sphere, "-C", cat, "--format", "ply", "-o", ok / "exp"],
    }
    argv = [[str(a) for a in args] for args in commands.values()]
    import_everything()
    results = as_user(NOBODY, lambda: run_commands(argv))
    assert isinstance(results, list), results["traceback"]  # not the child's traceback
    got = dict(zip(commands, results, strict=True))
    denied = "Permission denied"
    one_line(*got["export"], str(ro / "exp"), denied)
    one_line(*got["export-into"], str(ro / f"{sphere}.ply"), denied)
    one_line(*got["render"], str(ro / "x.ply"), "not writable")
    one_line(*got["report"], str(ro / "report.html"), denied)
    one_line(*got["contact-sheet"], str(ro / "sheet.png"), denied)
    one_line(*got["gallery"], str(ro / "site"), denied)
    one_line(*got["gallery-old"], str(old), denied, "left as it was")
    one_line(*got["star"], str(cat), "read-only")
    for name in ("list", "show", "gallery-ok", "export-ok"):  # reading a read-only catalogue
        assert got[name][0] == 0, (name, got[name])
    after = snapshot(base)
    written = {k for k in after if k.startswith("ok/")}
    assert {k: v for k, v in after.items() if k not in written} == before  # nothing else
    assert "ok/site/index.html" in written and "ok/exp" in written
    assert not any(p.name.endswith(("-wal", "-shm")) for p in cat.iterdir())


def test_a_saved_variant_is_files_and_row_or_nothing(template, tmp_path: Path, monkeypatch):
    """Explore's "save variant" writes a mesh, a thumbnail and a turntable with a row: when
    the row cannot be written (SQLite's disk full), the files go too."""
    import sqlite3

    import surfgen.pipelines.catalogue.curation as curation
    from surfgen.pipelines.catalogue.store import open_catalogue
    from surfgen.pipelines.studies.explore import save_variant

    root, keys = template
    cat_dir = tmp_path / "cat"
    shutil.copytree(root, cat_dir)
    before = snapshot(cat_dir)

    def disk_full(*args, **kwargs):
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr(curation, "apply_action", disk_full)
    with open_catalogue(cat_dir) as cat, pytest.raises(Exception, match="disk is full"):
        save_variant(cat, keys["torus"], {"d": 0.09})
    assert snapshot(cat_dir) == before  # no mesh, thumbnail, turntable or temporary folder
    monkeypatch.undo()
    with open_catalogue(cat_dir) as cat:
        rec = save_variant(cat, keys["torus"], {"d": 0.09})
    assert (cat_dir / "meshes" / f"{rec['key']}.ply").is_file()
