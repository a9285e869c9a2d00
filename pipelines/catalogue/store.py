"""The catalogue: one SQLite database (WAL, one writer) plus mesh and picture files.

Layout of a catalogue folder (default ``out/catalogue``)::

    catalogue.sqlite       runs, shapes (accepted and rejected draws), tags, curation (log)
    meshes/<key>.ply       accepted meshes (binary PLY)
    thumbs/<key>.png       256x256 thumbnails
    turntables/<key>.png   12 views side by side

Rows of a run are committed in index order, each with the run's progress in the same
transaction, so the database always holds a prefix of the run: a killed run resumes exactly
where it stopped. Files are written to a temporary name and renamed before their row commits.
"""

from __future__ import annotations

import fcntl
import json
import os
import sqlite3
import threading
import urllib.parse
from collections import Counter
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from surfgen.generator.errors import SurfgenError
from surfgen.generator.model.spec import SurfaceSpec

DEFAULT_CATALOGUE = Path("out/catalogue")
DB_NAME = "catalogue.sqlite"

SCHEMA = """
CREATE TABLE IF NOT EXISTS runs (
    id INTEGER PRIMARY KEY,
    seed INTEGER NOT NULL,
    n INTEGER NOT NULL,
    grid INTEGER NOT NULL,
    config TEXT NOT NULL,
    config_hash TEXT NOT NULL,
    sampler_version INTEGER NOT NULL,
    versions TEXT NOT NULL,
    started TEXT NOT NULL,
    ended TEXT,
    status TEXT NOT NULL,
    next_index INTEGER NOT NULL DEFAULT 0,
    accepted INTEGER NOT NULL DEFAULT 0,
    counts TEXT NOT NULL DEFAULT '{}',
    UNIQUE (seed, config_hash, grid)
);
CREATE TABLE IF NOT EXISTS shapes (
    key TEXT PRIMARY KEY,
    run INTEGER NOT NULL REFERENCES runs(id),
    idx INTEGER NOT NULL,
    spec TEXT NOT NULL,
    formula TEXT NOT NULL,
    identity TEXT NOT NULL,
    d REAL,
    model TEXT,
    verdict TEXT NOT NULL,
    reasons TEXT NOT NULL,
    metrics TEXT NOT NULL,
    faces INTEGER,
    vertices INTEGER,
    components INTEGER,
    genus INTEGER,
    euler INTEGER,
    area REAL,
    volume REAL,
    mesh_path TEXT,
    thumb_path TEXT,
    turntable_path TEXT,
    timings TEXT NOT NULL DEFAULT '{}',
    error TEXT,
    stars INTEGER NOT NULL DEFAULT 0,
    user_rejected TEXT,
    note TEXT,
    duplicate_of TEXT,
    descriptor TEXT,
    UNIQUE (run, idx)
);
CREATE INDEX IF NOT EXISTS shapes_identity ON shapes (identity, verdict);
CREATE TABLE IF NOT EXISTS tags (
    key TEXT NOT NULL REFERENCES shapes(key),
    tag TEXT NOT NULL,
    PRIMARY KEY (key, tag)
);
CREATE TABLE IF NOT EXISTS curation (
    id INTEGER PRIMARY KEY,
    key TEXT NOT NULL REFERENCES shapes(key),
    at TEXT NOT NULL,
    action TEXT NOT NULL,
    value TEXT
);
CREATE INDEX IF NOT EXISTS curation_key ON curation (key);
"""


class CatalogueError(SurfgenError):
    """A catalogue that cannot be opened, or a key that is not in it."""


def now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


@dataclass
class Run:
    id: int
    seed: int
    n: int
    grid: int
    config_hash: str
    status: str
    next_index: int
    accepted: int
    counts: dict[str, int]


class Catalogue:
    """A catalogue folder and its open database connection (the one writer)."""

    def __init__(self, root: Path, conn: sqlite3.Connection) -> None:
        self.root = Path(root)
        self.conn = conn

    # -- paths
    @property
    def meshes(self) -> Path:
        return self.root / "meshes"

    @property
    def thumbs(self) -> Path:
        return self.root / "thumbs"

    @property
    def turntables(self) -> Path:
        return self.root / "turntables"

    def make_dirs(self) -> None:
        for d in (self.meshes, self.thumbs, self.turntables):
            d.mkdir(parents=True, exist_ok=True)

    # -- runs
    def find_run(self, seed: int, config_hash: str, grid: int) -> Run | None:
        row = self.conn.execute(
            "SELECT * FROM runs WHERE seed=? AND config_hash=? AND grid=?",
            (seed, config_hash, grid),
        ).fetchone()
        return _run(row) if row else None

    def create_run(
        self,
        seed: int,
        n: int,
        grid: int,
        config: Mapping,
        config_hash: str,
        sampler_version: int,
        versions: Mapping,
    ) -> Run:
        with self.conn:
            cur = self.conn.execute(
                "INSERT INTO runs (seed, n, grid, config, config_hash, sampler_version, versions,"
                " started, status) VALUES (?,?,?,?,?,?,?,?,?)",
                (
                    seed,
                    n,
                    grid,
                    json.dumps(config, sort_keys=True),
                    config_hash,
                    sampler_version,
                    json.dumps(versions, sort_keys=True),
                    now(),
                    "running",
                ),
            )
        return self.get_run(int(cur.lastrowid))

    def get_run(self, run_id: int) -> Run:
        row = self.conn.execute("SELECT * FROM runs WHERE id=?", (run_id,)).fetchone()
        if row is None:
            raise CatalogueError(f"no run {run_id} in the catalogue")
        return _run(row)

    def set_run_status(self, run_id: int, status: str, n: int | None = None) -> None:
        with self.conn:
            if n is not None:
                self.conn.execute("UPDATE runs SET n=? WHERE id=?", (n, run_id))
            ended = now() if status != "running" else None
            self.conn.execute(
                "UPDATE runs SET status=?, ended=? WHERE id=?", (status, ended, run_id)
            )

    def runs(self) -> list[dict[str, Any]]:
        rows = self.conn.execute("SELECT * FROM runs ORDER BY id").fetchall()
        return [dict(r) for r in rows]

    # -- shapes
    def has_accepted_identity(self, identity: str) -> str | None:
        row = self.conn.execute(
            "SELECT key FROM shapes WHERE identity=? AND verdict='accepted' LIMIT 1", (identity,)
        ).fetchone()
        return row["key"] if row else None

    def record_shape(
        self,
        run_id: int,
        index: int,
        row: Mapping[str, Any],
        accepted: bool,
        reason_counts: Mapping[str, int],
    ) -> None:
        """Insert one shape (``row`` has its ``key`` and columns) and advance its run, atomically."""
        cols = ["run", "idx", *row.keys()]
        values = [run_id, index, *row.values()]
        marks = ",".join("?" * len(cols))
        with self.conn:
            self.conn.execute(
                f"INSERT OR REPLACE INTO shapes ({','.join(cols)}) VALUES ({marks})", values
            )
            self.conn.execute(
                "UPDATE runs SET next_index=?, accepted=accepted+?, counts=? WHERE id=?",
                (index + 1, int(accepted), json.dumps(dict(sorted(reason_counts.items()))), run_id),
            )

    def resolve(self, key_or_prefix: str) -> str:
        """The full key of a shape from its key or a unique prefix."""
        k = key_or_prefix.strip().lower()
        if not k or len(k) > 64 or any(c not in "0123456789abcdef" for c in k):
            shown = key_or_prefix if len(key_or_prefix) <= 40 else key_or_prefix[:37] + "..."
            raise CatalogueError(f"'{shown}' is not a shape key (hex digits)")
        rows = self.conn.execute(
            "SELECT key FROM shapes WHERE key LIKE ? ORDER BY key LIMIT 6", (k + "%",)
        ).fetchall()
        if not rows:
            raise CatalogueError(f"no shape with key '{key_or_prefix}' in {self.root}")
        if len(rows) > 1:
            shown = ", ".join(r["key"] for r in rows[:5])
            raise CatalogueError(
                f"key prefix '{key_or_prefix}' is ambiguous: {shown}{', ...' if len(rows) > 5 else ''}"
            )
        return rows[0]["key"]

    def shape(self, key_or_prefix: str) -> dict[str, Any]:
        key = self.resolve(key_or_prefix)
        row = dict(self.conn.execute("SELECT * FROM shapes WHERE key=?", (key,)).fetchone())
        row["tags"] = [
            r["tag"]
            for r in self.conn.execute("SELECT tag FROM tags WHERE key=? ORDER BY tag", (key,))
        ]
        return row

    def spec(self, key_or_prefix: str) -> SurfaceSpec:
        return SurfaceSpec.from_json(self.shape(key_or_prefix)["spec"])

    def shapes(self, run_id: int | None = None, verdict: str | None = None) -> list[dict[str, Any]]:
        q = "SELECT * FROM shapes WHERE 1=1"
        args: list[Any] = []
        if run_id is not None:
            q += " AND run=?"
            args.append(run_id)
        if verdict is not None:
            q += " AND verdict=?"
            args.append(verdict)
        return [dict(r) for r in self.conn.execute(q + " ORDER BY run, idx", args)]

    def close(self) -> None:
        self.conn.close()


def _run(row: sqlite3.Row) -> Run:
    return Run(
        id=row["id"],
        seed=row["seed"],
        n=row["n"],
        grid=row["grid"],
        config_hash=row["config_hash"],
        status=row["status"],
        next_index=row["next_index"],
        accepted=row["accepted"],
        counts=json.loads(row["counts"]),
    )


SCHEMA_VERSION = 1
# The row that says "this SQLite file is a surfgen catalogue" (and which schema it follows).
META = """
CREATE TABLE IF NOT EXISTS surfgen (key TEXT PRIMARY KEY, value TEXT NOT NULL);
INSERT OR IGNORE INTO surfgen (key, value) VALUES ('application', 'surfgen catalogue');
INSERT OR IGNORE INTO surfgen (key, value) VALUES ('schema', '1');
"""
# A catalogue made before the schema row existed has exactly these tables and columns.
_LEGACY = {
    "runs": {"seed", "config_hash", "next_index", "counts"},
    "shapes": {"key", "run", "idx", "spec", "identity", "verdict", "reasons", "metrics"},
    "tags": {"key", "tag"},
    "curation": {"key", "at", "action", "value"},
}
BUSY_TIMEOUT = 30.0  # seconds a writer waits for another one (sample, serve, curation)


class CorruptCatalogue(CatalogueError):
    """A catalogue database that SQLite cannot read (damaged pages, truncated file)."""


def check_hint(root: Path | str) -> str:
    return f"run `surfgen catalogue check -C {root}`"


def sqlite_error(exc: sqlite3.Error, db: Path | str) -> CatalogueError:
    """One line for an SQLite error: disk full, read-only, busy, or corrupted (the rest)."""
    text = str(exc)
    root = Path(db).parent
    if "disk is full" in text or "disk I/O error" in text:
        return CatalogueError(
            f"cannot write catalogue {db}: {text} (free some space; a sampling run continues "
            "with --resume)"
        )
    if "readonly" in text or "read-only" in text:
        return CatalogueError(f"catalogue {db} is read-only: {text}")
    if "locked" in text or "busy" in text:
        return CatalogueError(
            f"catalogue {db} is busy: another process held it for more than {BUSY_TIMEOUT:g} s"
        )
    if "unable to open" in text:
        return CatalogueError(f"cannot open catalogue {db}: {text}")
    return CorruptCatalogue(f"catalogue {db} is corrupted ({text}): {check_hint(root)}")


def connect_readonly(db: Path) -> sqlite3.Connection:
    """A read-only connection (``mode=ro``): reading never creates or changes a file.

    In a read-only folder a WAL database cannot get its shared-memory file: it is then opened
    ``immutable`` (nobody can be writing it there either)."""
    uri = "file:" + urllib.parse.quote(str(Path(db).resolve())) + "?mode=ro"
    try:
        conn = sqlite3.connect(uri, uri=True, timeout=BUSY_TIMEOUT)
        conn.execute("SELECT count(*) FROM sqlite_master").fetchone()
    except sqlite3.OperationalError:
        if os.access(Path(db).parent, os.W_OK):
            raise
        conn = sqlite3.connect(uri + "&immutable=1", uri=True, timeout=BUSY_TIMEOUT)
    conn.row_factory = sqlite3.Row
    return conn


def identify(db: Path) -> int | None:
    """The schema version of the surfgen catalogue in ``db`` (0: made before versions were
    recorded), or None for an empty database. Reads only, through a read-only connection.

    Raises :class:`CatalogueError` for a foreign SQLite file or something else, and
    :class:`CorruptCatalogue` when SQLite cannot read it."""
    had_wal = Path(f"{db}-wal").exists()
    try:
        return _identify(db)
    except CatalogueError:
        with _OPEN_LOCK:  # e.g. a foreign WAL database: leave no files of ours beside it
            if not had_wal and _OPEN[str(Path(db).resolve())] == 0:
                _tidy_after_reading(Path(db))
        raise


def _identify(db: Path) -> int | None:
    try:
        conn = connect_readonly(db)
    except sqlite3.Error as exc:
        raise sqlite_error(exc, db) from None
    try:
        tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if "surfgen" in tables:
            row = conn.execute("SELECT value FROM surfgen WHERE key='schema'").fetchone()
            app = conn.execute("SELECT value FROM surfgen WHERE key='application'").fetchone()
            if row is None or app is None or app[0] != "surfgen catalogue":
                raise CatalogueError(f"{db} is not a surfgen catalogue (no schema row)")
            try:
                return int(row[0])
            except ValueError:
                raise CatalogueError(f"{db}: unreadable schema version '{row[0]}'") from None
        if not tables:
            return None
        for table, columns in _LEGACY.items():
            have = {r[1] for r in conn.execute(f"PRAGMA table_info({table})")}
            if not columns <= have:
                shown = ", ".join(sorted(tables)[:5])
                raise CatalogueError(
                    f"{db} is not a surfgen catalogue (its tables: {shown}); "
                    "surfgen left it unchanged"
                )
        return 0
    except sqlite3.DatabaseError as exc:
        if "not a database" in str(exc) or "encrypted" in str(exc):
            raise CatalogueError(
                f"{db} is not a surfgen catalogue (not an SQLite database); surfgen left it "
                "unchanged"
            ) from None
        raise sqlite_error(exc, db) from None
    finally:
        conn.close()


@contextmanager
def open_catalogue(
    root: Path | str = DEFAULT_CATALOGUE, must_exist: bool = False, readonly: bool = False
) -> Iterator[Catalogue]:
    """Open (or create) the catalogue in ``root``; ``must_exist`` refuses to create one.

    ``readonly`` opens it with a read-only connection (for commands that only read: nothing on
    disk changes, a read-only catalogue can be listed). An existing database is identified by
    its schema row *before* anything is written, so a foreign SQLite file is never modified.
    Raises :class:`CatalogueError` (:class:`CorruptCatalogue` for a damaged database).
    """
    root = Path(root)
    db = root / DB_NAME
    exists = db.exists()
    had_wal = Path(f"{db}-wal").exists()  # before identify(), whose reading may create it
    if (must_exist or readonly) and not db.is_file():
        raise CatalogueError(f"no catalogue at {root} (expected {db}; run `surfgen sample` first)")
    if exists and not db.is_file():
        raise CatalogueError(f"{db} is not a file")
    version = identify(db) if exists else None
    if version is not None and version > SCHEMA_VERSION:
        raise CatalogueError(
            f"{db} has schema version {version}; this surfgen reads up to {SCHEMA_VERSION} "
            "(upgrade surfgen)"
        )
    if readonly and version is None:
        # an empty database (a 0-byte file is one, to SQLite): an empty catalogue, read from a
        # schema in memory so that the file stays as it is
        conn = sqlite3.connect(":memory:")
        conn.row_factory = sqlite3.Row
        conn.executescript(SCHEMA + META)
    elif readonly:
        try:
            conn = connect_readonly(db)
        except sqlite3.Error as exc:
            raise sqlite_error(exc, db) from None
    else:
        conn = _open_for_writing(root, db, exists)
    key = str(db.resolve())
    with _OPEN_LOCK:
        _OPEN[key] += 1
    cat = Catalogue(root, conn)
    try:
        yield cat
    except sqlite3.Error as exc:
        raise sqlite_error(exc, db) from None
    except OverflowError:  # a number bound to a query beyond SQLite's INTEGER
        raise CatalogueError(
            "a number is out of range: the catalogue holds whole numbers up to 2^63-1"
        ) from None
    finally:
        cat.close()
        with _OPEN_LOCK:
            _OPEN[key] -= 1
            if readonly and not had_wal and _OPEN[key] == 0:
                _tidy_after_reading(db)


# Connections this process has open per database: a reader tidies up SQLite's shared-memory
# files only when it was the last one here (POSIX locks do not tell a process about itself).
_OPEN: Counter[str] = Counter()
_OPEN_LOCK = threading.Lock()
_WAL_DMS_BYTE = 128  # the -shm byte every connection to a WAL database holds a shared lock on


def in_use(db: Path) -> bool:
    """True when another process has the WAL database ``db`` open (it holds a lock on the
    shared-memory file's DMS byte)."""
    shm = Path(f"{db}-shm")
    try:
        fd = os.open(shm, os.O_RDWR)
    except OSError:
        return False
    try:
        fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB, 1, _WAL_DMS_BYTE, os.SEEK_SET)
    except OSError:
        return True
    finally:
        os.close(fd)
    return False


def _tidy_after_reading(db: Path) -> None:
    """Remove the empty ``-wal`` and the ``-shm`` a read-only connection had to create, when no
    other process is attached (the exclusive lock on the DMS byte is free), as SQLite's last
    writer would: reading a catalogue leaves the folder as it was."""
    shm, wal = Path(f"{db}-shm"), Path(f"{db}-wal")
    if not shm.exists() or (wal.exists() and wal.stat().st_size > 0):
        return
    try:
        fd = os.open(shm, os.O_RDWR)
    except OSError:
        return
    try:
        fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB, 1, _WAL_DMS_BYTE, os.SEEK_SET)
    except OSError:  # another process has the database open: its files stay
        os.close(fd)
        return
    try:
        wal.unlink(missing_ok=True)
        shm.unlink(missing_ok=True)
    finally:
        os.close(fd)  # closing releases the lock


def _open_for_writing(root: Path, db: Path, exists: bool) -> sqlite3.Connection:
    if exists and not os.access(db, os.W_OK):
        raise CatalogueError(f"catalogue {db} is read-only: this command needs to write it")
    if exists and not os.access(root, os.W_OK):
        raise CatalogueError(
            f"catalogue folder {root} is read-only: SQLite needs to write its journal there"
        )
    try:
        root.mkdir(parents=True, exist_ok=True)
        conn = sqlite3.connect(db, timeout=BUSY_TIMEOUT)
    except OSError as exc:
        raise CatalogueError(f"cannot open catalogue {db}: {exc.strerror}") from None
    except sqlite3.Error as exc:
        raise sqlite_error(exc, db) from None
    conn.row_factory = sqlite3.Row
    try:
        conn.execute("PRAGMA journal_mode=WAL")
        conn.execute("PRAGMA synchronous=NORMAL")
        conn.executescript(SCHEMA + META)
    except sqlite3.Error as exc:
        conn.close()
        raise sqlite_error(exc, db) from None
    return conn
