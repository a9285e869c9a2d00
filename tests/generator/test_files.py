"""Tests for surfgen.generator.files: results of several files are written all or nothing,
even when a rename fails half-way (the files it replaced come back)."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest

from surfgen.generator import files
from surfgen.generator.files import (
    renaming,
    stage,
    staged_folder,
    staged_into,
    write_all_atomic,
)


def fail_rename(monkeypatch, nth: int) -> list[tuple[str, str]]:
    """Make the ``nth`` call of ``os.replace`` fail (a full or vanished disk); returns the log."""
    real = os.replace
    calls: list[tuple[str, str]] = []

    def replace(src, dst, *args, **kwargs):
        calls.append((str(src), str(dst)))
        if len(calls) == nth:
            raise OSError(errno.EIO, "Input/output error", str(dst))
        return real(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "replace", replace)
    return calls


def tree(root: Path) -> dict[str, bytes | None]:
    return {
        str(p.relative_to(root)): p.read_bytes() if p.is_file() else None
        for p in sorted(root.rglob("*"))
    }


def test_a_failed_second_rename_puts_back_the_first(tmp_path: Path, monkeypatch) -> None:
    (tmp_path / "a.ply").write_bytes(b"old a")  # replaced, then restored
    inode = (tmp_path / "a.ply").stat().st_ino
    (tmp_path / "c.json").write_bytes(b"old c")  # never reached
    before = tree(tmp_path)
    calls = fail_rename(monkeypatch, 2)
    items = [(tmp_path / "a.ply", b"new a"), (tmp_path / "b.png", b"new b")]
    items.append((tmp_path / "c.json", b"new c"))
    with pytest.raises(OSError) as info:
        write_all_atomic(items)
    assert info.value.filename == str(tmp_path / "b.png") and info.value.errno == errno.EIO
    assert tree(tmp_path) == before  # a.ply is the old one, b.png absent, no temporary file
    assert (tmp_path / "a.ply").stat().st_ino == inode  # the same file, not a copy
    assert len(calls) == 4  # a in, b fails, a back to its temporary name, old a back


def test_a_new_file_is_removed_when_a_later_rename_fails(tmp_path: Path, monkeypatch) -> None:
    fail_rename(monkeypatch, 3)
    items = [(tmp_path / f"{n}.txt", n.encode()) for n in "abc"]
    with pytest.raises(OSError):
        write_all_atomic(items)
    assert list(tmp_path.iterdir()) == []


def test_all_renames_succeed_and_keep_no_copies(tmp_path: Path) -> None:
    (tmp_path / "a").write_bytes(b"old")
    write_all_atomic([(tmp_path / "a", b"new"), (tmp_path / "b", b"b")], mode=0o640)
    assert tree(tmp_path) == {"a": b"new", "b": b"b"}
    assert (tmp_path / "a").stat().st_mode & 0o777 == 0o640


def test_rollback_when_the_caller_commit_fails(tmp_path: Path) -> None:
    """A database row committed with the files: if it fails, the moves are undone and the
    staged files are back under their temporary names."""
    (tmp_path / "mesh.ply").write_bytes(b"old mesh")
    staged = [stage(tmp_path / "mesh.ply", b"new mesh"), stage(tmp_path / "t.png", b"png")]
    with pytest.raises(RuntimeError), renaming() as tx:
        tx.move(staged[0], tmp_path / "mesh.ply")
        tx.move(staged[1], tmp_path / "t.png")
        raise RuntimeError("database or disk is full")
    assert (tmp_path / "mesh.ply").read_bytes() == b"old mesh"
    assert not (tmp_path / "t.png").exists()
    assert [p.read_bytes() for p in staged] == [b"new mesh", b"png"]


def test_without_hard_links_the_old_file_is_renamed_aside(tmp_path: Path, monkeypatch) -> None:
    def no_link(*args, **kwargs):
        raise OSError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(os, "link", no_link)
    (tmp_path / "a").write_bytes(b"old a")
    fail_rename(monkeypatch, 4)  # a aside, a in, b aside... fails on b in
    (tmp_path / "b").write_bytes(b"old b")
    with pytest.raises(OSError):
        write_all_atomic([(tmp_path / "a", b"new a"), (tmp_path / "b", b"new b")])
    assert tree(tmp_path) == {"a": b"old a", "b": b"old b"}


def test_a_staged_folder_replaces_the_old_one_only_at_the_end(tmp_path: Path) -> None:
    out = tmp_path / "site"
    (out / "thumbs").mkdir(parents=True)
    (out / "index.html").write_text("old")
    with pytest.raises(OSError), staged_folder(out) as work:
        (work / "index.html").write_text("new")
        raise OSError(errno.ENOSPC, "No space left on device", str(work / "thumbs" / "k.png"))
    assert tree(tmp_path) == {"site": None, "site/index.html": b"old", "site/thumbs": None}
    with staged_folder(out) as work:
        (work / "index.html").write_text("new")
    assert tree(tmp_path) == {"site": None, "site/index.html": b"new"}


def test_a_staged_folder_names_the_final_path(tmp_path: Path) -> None:
    out = tmp_path / "site"
    with pytest.raises(OSError) as info, staged_folder(out) as work:
        raise OSError(errno.ENOSPC, "No space left on device", str(work / "thumbs" / "k.png"))
    assert info.value.filename == str(out / "thumbs" / "k.png")


def test_staged_into_keeps_other_files_and_replaces_whole_entries(
    tmp_path: Path, monkeypatch
) -> None:
    out = tmp_path / "out"
    (out / "meshes").mkdir(parents=True)
    (out / "meshes" / "step-009.ply").write_bytes(b"old step 9")
    (out / "notes.txt").write_text("mine")
    (out / "sweep.json").write_text("old")
    before = tree(out)
    calls = fail_rename(monkeypatch, 3)  # meshes aside, meshes in, sweep.json in: fails
    with pytest.raises(OSError), staged_into(out) as work:
        (work / "meshes").mkdir()
        (work / "meshes" / "step-000.ply").write_bytes(b"new step 0")
        (work / "sweep.json").write_text("new")
    assert tree(out) == before and len(calls) == 5
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # no temporary folder
    monkeypatch.undo()
    with staged_into(out) as work:
        (work / "meshes").mkdir()
        (work / "meshes" / "step-000.ply").write_bytes(b"new step 0")
        (work / "sweep.json").write_text("new")
    assert tree(out) == {
        "meshes": None,
        "meshes/step-000.ply": b"new step 0",  # the old sweep's step 9 went with its folder
        "notes.txt": b"mine",
        "sweep.json": b"new",
    }
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_leftovers_of_a_killed_process_are_cleared(tmp_path: Path) -> None:
    import subprocess

    dead = subprocess.Popen(["true"])
    dead.wait()  # its pid names the leftovers of a process that is gone
    out = tmp_path / "site"
    (tmp_path / f".site.{dead.pid}.0123abcd.tmp").mkdir()  # a half-written gallery
    (tmp_path / f".site.{dead.pid}.0123abcd.tmp" / "index.html").write_text("half")
    old = tmp_path / f".site.{dead.pid}.4567cdef.old.tmp"  # killed between the two renames
    old.mkdir()
    (old / "index.html").write_text("the earlier gallery")
    mine = tmp_path / f".site.{os.getpid()}.89abcdef.tmp"  # a live process's: kept
    mine.mkdir()
    other = tmp_path / f".site.v2.{dead.pid}.0123abcd.tmp"  # another target's: kept
    other.mkdir()
    files.clear_leftovers(out)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([mine.name, other.name, "site"])
    assert (out / "index.html").read_text() == "the earlier gallery"
    with staged_folder(out) as work:
        (work / "index.html").write_text("new")
    assert (out / "index.html").read_text() == "new"
