"""Writing result files so that a reader never sees half of one, and a result made of several
files (a mesh and its sidecar, a picture, a folder) appears whole or not at all.

Two steps, as in a database: every file is first *staged* under a temporary name in its own
folder (where a full disk or a read-only folder shows, before anything visible changed), then
all are *renamed* into place by a :class:`Renames` transaction, which keeps what each rename
replaced and, if a later rename fails (or the caller's own commit, such as a catalogue row,
fails), puts every earlier one back: files that were overwritten come back, files that were new
go back to their temporary names and are removed.
"""

from __future__ import annotations

import errno
import logging
import os
import re
import shutil
import uuid
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

log = logging.getLogger(__name__)


KEPT = "old.tmp"  # what a rename replaced, until the transaction ends (ends in .tmp, like
# every temporary name here, so `catalogue check` counts a leftover as a temporary file)


def _temp_name(path: Path, tag: str = "tmp") -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.{tag}")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def clear_leftovers(target: Path) -> None:
    """Remove the temporary files and folders beside ``target`` that a killed process left
    (their names carry its pid); if ``target`` itself is missing because the process was
    killed between moving the old version aside and the new one in, put the old one back."""
    pattern = re.compile(rf"\.{re.escape(target.name)}\.(\d+)\.[0-9a-f]{{8}}\.(old\.)?tmp")
    try:
        entries = list(target.parent.iterdir())
    except OSError:
        return
    for entry in sorted(entries):
        m = pattern.fullmatch(entry.name)
        if m is None or int(m.group(1)) == os.getpid() or _alive(int(m.group(1))):
            continue
        try:
            if m.group(2) and not (target.exists() or target.is_symlink()):
                os.replace(entry, target)
                log.warning("put back %s, left aside by a process that was killed", target)
            else:
                _remove(entry)
        except OSError as exc:  # not ours to remove (another user's folder): leave it
            log.debug("could not clear %s (%s)", entry, exc)


def _reraise(exc: OSError, path: Path) -> OSError:
    """The same error naming the file the user asked for, not its temporary name."""
    return type(exc)(exc.errno, exc.strerror or str(exc), str(path))


def _in_target(exc: OSError, work: Path, target: Path) -> OSError:
    """``exc`` naming the file under ``target`` rather than under its temporary folder."""
    name = exc.filename
    if not isinstance(name, str) or not (name == str(work) or name.startswith(f"{work}/")):
        return exc
    return type(exc)(exc.errno, exc.strerror or str(exc), str(target) + name[len(str(work)) :])


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


class Renames:
    """An all-or-nothing group of renames (use :func:`renaming`).

    :meth:`move` renames a staged file or folder onto its target. A target that exists is
    kept first: a file through a hard link (so the target never disappears, not even for an
    instant), a folder (or a file on a file system without hard links) by renaming it aside.
    :meth:`rollback` undoes every move in reverse order; :meth:`finish` drops the kept copies.
    """

    def __init__(self) -> None:
        self._done: list[tuple[Path, Path, Path | None]] = []  # (src, dst, kept copy of dst)

    @property
    def targets(self) -> list[Path]:
        return [dst for _, dst, _ in self._done]

    def move(self, src: str | os.PathLike, dst: str | os.PathLike) -> Path:
        """Rename ``src`` onto ``dst``. Raises ``OSError`` naming ``dst`` (nothing moved then)."""
        src, dst = Path(src), Path(dst)
        kept: Path | None = None
        aside = False
        try:
            if dst.is_dir() and not dst.is_symlink():
                if not src.is_dir():
                    raise IsADirectoryError(errno.EISDIR, "it is a folder, not a file name")
                kept, aside = _temp_name(dst, KEPT), True
                os.replace(dst, kept)
            elif dst.exists() or dst.is_symlink():
                kept = _temp_name(dst, KEPT)
                try:
                    os.link(dst, kept, follow_symlinks=False)
                except OSError:  # no hard links here (FAT, some network file systems)
                    os.replace(dst, kept)
                    aside = True
            try:
                os.replace(src, dst)
            except OSError:
                if kept is not None and aside:
                    os.replace(kept, dst)
                elif kept is not None:
                    kept.unlink(missing_ok=True)
                raise
        except OSError as exc:
            raise _reraise(exc, dst) from None
        self._done.append((src, dst, kept))
        return dst

    def rollback(self) -> None:
        """Put back everything :meth:`move` changed, newest first (best effort: what cannot
        be put back is logged, with where its old version is)."""
        while self._done:
            src, dst, kept = self._done.pop()
            try:
                os.replace(dst, src)  # the new version back to its temporary name
                if kept is not None:
                    os.replace(kept, dst)  # a hard link or the renamed-aside original
            except OSError as exc:
                log.error("could not restore %s (%s); its old version is %s", dst, exc, kept)

    def finish(self) -> None:
        """Keep every move: drop the copies of what they replaced."""
        for _, _, kept in self._done:
            if kept is not None:
                _remove(kept)
        self._done.clear()


@contextmanager
def renaming() -> Iterator[Renames]:
    """A :class:`Renames` transaction: kept if the block ends normally, undone if it raises
    (a failed rename, or whatever else the block commits with them, e.g. a database row)."""
    tx = Renames()
    try:
        yield tx
    except BaseException:
        tx.rollback()
        raise
    tx.finish()


def write_atomic(path: str | os.PathLike, data: bytes, mode: int | None = None) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder and ``os.replace``.

    The file appears complete or not at all, with the usual permissions (``open`` keeps the
    umask; ``tempfile.mkstemp`` would make it 0600) or ``mode``. Raises ``OSError`` naming
    ``path`` (disk full, read-only folder, a folder in the way); leaves no temporary file.
    """
    return write_all_atomic([(path, data)], mode=mode)[0]


def stage(path: str | os.PathLike, data: bytes, mode: int | None = None) -> Path:
    """Write ``data`` to a new temporary file beside ``path`` and return its name. Raises
    ``OSError`` naming ``path``; then no temporary file is left."""
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, "it is a folder, not a file name", str(path))
    tmp = _temp_name(path)
    try:
        with open(tmp, "xb") as out:
            out.write(data)
        if mode is not None:
            tmp.chmod(mode)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise _reraise(exc, path) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


def write_all_atomic(
    items: Sequence[tuple[str | os.PathLike, bytes]], mode: int | None = None
) -> list[Path]:
    """Write several files all or nothing: every temporary file is written first (where a full
    disk or a read-only folder shows), then all are renamed into place in one :class:`Renames`
    transaction, so a rename that fails half-way puts back the files already replaced.

    Raises ``OSError`` naming the path that failed; then no file changed and none is left over.
    """
    paths = [Path(p) for p, _ in items]
    for path in paths:
        if path.is_dir():
            raise IsADirectoryError(errno.EISDIR, "it is a folder, not a file name", str(path))
    temps: list[Path] = []
    try:
        for path, (_, data) in zip(paths, items, strict=True):
            temps.append(stage(path, data, mode))
        with renaming() as tx:
            for path, tmp in zip(paths, temps, strict=True):
                tx.move(tmp, path)
    finally:
        for tmp in temps:  # after a rollback the new versions are back here
            tmp.unlink(missing_ok=True)
    return paths


@contextmanager
def staged_folder(target: str | os.PathLike) -> Iterator[Path]:
    """A new temporary folder beside ``target`` to write a whole result into; when the block
    ends normally it replaces ``target`` (a previous version is removed only then), and if the
    block raises it is removed and ``target`` is left as it was.

    Raises ``OSError`` naming ``target``'s folder when the temporary folder cannot be made
    (a read-only or missing parent).
    """
    target = Path(os.path.abspath(target))  # `-o .` has a name to put a sibling beside
    clear_leftovers(target)
    work = _temp_name(target)
    try:
        work.mkdir()
    except OSError as exc:
        raise _reraise(exc, target.parent if str(target.parent) else Path(".")) from None
    try:
        try:
            yield work
        except OSError as exc:
            raise _in_target(exc, work, target) from None
        with renaming() as tx:
            tx.move(work, target)
    finally:
        if work.exists():
            shutil.rmtree(work, ignore_errors=True)


@contextmanager
def staged_into(target: str | os.PathLike) -> Iterator[Path]:
    """Like :func:`staged_folder`, but ``target`` keeps what the result does not name: each
    file or folder the block writes at the top of the temporary folder replaces the one of
    the same name in ``target`` (a folder whole), all in one :class:`Renames` transaction.

    For results written into a folder the user may share with other things (a sweep's or
    the paper's figures). ``target``'s parent folders are made if missing.
    """
    target = Path(os.path.abspath(target))
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _reraise(exc, target.parent) from None
    if target.exists() and not target.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, "it is a file, not a folder", str(target))
    clear_leftovers(target)
    work = _temp_name(target)
    try:
        work.mkdir()
    except OSError as exc:
        raise _reraise(exc, target.parent) from None
    try:
        try:
            yield work
        except OSError as exc:
            raise _in_target(exc, work, target) from None
        with renaming() as tx:
            if not target.exists():
                tx.move(work, target)
            else:
                for entry in sorted(work.iterdir()):
                    tx.move(entry, target / entry.name)
    finally:
        if work.exists():
            shutil.rmtree(work, ignore_errors=True)
