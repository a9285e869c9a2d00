"""Writing result files so that a reader never sees half of one."""

from __future__ import annotations

import os
import uuid
from collections.abc import Sequence
from pathlib import Path


def _temp_name(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")


def _reraise(exc: OSError, path: Path) -> OSError:
    """The same error naming the file the user asked for, not its temporary name."""
    return type(exc)(exc.errno, exc.strerror or str(exc), str(path))


def write_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder and ``os.replace``.

    The file appears complete or not at all, with the usual permissions (``open`` keeps the
    umask; ``tempfile.mkstemp`` would make it 0600). Raises ``OSError`` naming ``path`` (disk
    full, read-only folder, a folder in the way); leaves no temporary file.
    """
    return write_all_atomic([(path, data)])[0]


def write_all_atomic(items: Sequence[tuple[str | os.PathLike, bytes]]) -> list[Path]:
    """Write several files all or nothing: every temporary file is written first (where a full
    disk or a read-only folder shows), and only then are they renamed into place.

    Raises ``OSError`` naming the path that failed; then none of the files was written.
    """
    paths = [Path(p) for p, _ in items]
    for path in paths:
        if path.is_dir():
            raise IsADirectoryError(21, "it is a folder, not a file name", str(path))
    temps: list[Path] = []
    try:
        for path, (_, data) in zip(paths, items, strict=True):
            tmp = _temp_name(path)
            try:
                with open(tmp, "xb") as out:
                    temps.append(tmp)
                    out.write(data)
            except OSError as exc:
                raise _reraise(exc, path) from None
        for path, tmp in zip(paths, temps, strict=True):
            try:
                os.replace(tmp, path)
            except OSError as exc:
                raise _reraise(exc, path) from None
    except BaseException:
        for tmp in temps:
            tmp.unlink(missing_ok=True)
        raise
    return paths
