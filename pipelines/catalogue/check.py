"""``surfgen catalogue check``: is a catalogue sound, and repair what can be rebuilt.

The check reads only (a read-only connection): SQLite's integrity check, every file a row
names against the disk, files no row names (orphans), temporary files an interrupted write left,
and runs still marked running. ``--repair`` then changes only what can be rebuilt:

- a damaged database: every row SQLite can still read is copied into a fresh database (the
  damaged file is kept beside it as ``catalogue.sqlite.corrupt-<time>``); rows that cannot be
  read are lost and counted;
- a missing mesh of an accepted shape: re-made from its spec (evaluate, marching cubes, capped
  as its run was); missing thumbnails and turntables: re-rendered from the mesh;
- temporary files and the ``.staging`` folder of an interrupted run: removed;
- orphan files: moved into ``orphans/`` (never deleted: they may be all that is left of a row).
"""

from __future__ import annotations

import json
import logging
import shutil
import sqlite3
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from surfgen.filters.resolution import METRIC_NAMES as RESOLUTION_METRICS
from surfgen.filters.verdict import FilterConfig, unresolved
from surfgen.generator.errors import SurfgenError
from surfgen.generator.mesh.exchange import load_mesh, save_mesh
from surfgen.generator.mesh.realise import realise
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.store import (
    DB_NAME,
    META,
    SCHEMA,
    CatalogueError,
    CorruptCatalogue,
    connect_readonly,
    identify,
    in_use,
    open_catalogue,
)
from surfgen.pipelines.pictures.raster import TURNTABLE_SIZE, render_thumbnail, render_turntable

log = logging.getLogger(__name__)

FILE_COLUMNS = {"mesh_path": "meshes", "thumb_path": "thumbs", "turntable_path": "turntables"}
TABLES = ("runs", "shapes", "tags", "curation")


@dataclass
class CheckReport:
    """What :func:`check_catalogue` found (and, with ``repair``, did)."""

    root: Path
    integrity: list[str] = field(default_factory=list)  # empty: SQLite says ok
    shapes: int = 0
    missing: list[tuple[str, str, str]] = field(default_factory=list)  # key, column, path
    orphans: list[Path] = field(default_factory=list)
    temporary: list[Path] = field(default_factory=list)
    running: list[int] = field(default_factory=list)
    repaired: list[str] = field(default_factory=list)
    unrepaired: list[str] = field(default_factory=list)
    resolution: ResolutionSummary | None = None

    @property
    def problems(self) -> int:
        return len(self.integrity) + len(self.missing) + len(self.orphans) + len(self.temporary)

    def lines(self) -> list[str]:
        out = [f"catalogue {self.root}: {self.shapes} shape rows"]
        out.append(
            "database: ok" if not self.integrity else f"database: CORRUPTED ({self.integrity[0]})"
        )
        out += [f"  {p}" for p in self.integrity[1:5]]
        out.append(f"files named by rows but missing: {len(self.missing)}")
        out += [f"  {k} {c}: {p}" for k, c, p in self.missing[:20]]
        out.append(f"orphan files (no row names them): {len(self.orphans)}")
        out += [f"  {p}" for p in self.orphans[:20]]
        out.append(f"temporary files left by interrupted writes: {len(self.temporary)}")
        if self.running:
            out.append(
                f"runs marked running (interrupted, or running now): {', '.join(map(str, self.running))}"
            )
        if self.resolution is not None:
            out += self.resolution.lines()
        out += [f"repaired: {r}" for r in self.repaired]
        out += [f"not repaired: {r}" for r in self.unrepaired]
        return out


@dataclass
class ResolutionSummary:
    """The accepted shapes' resolution figures (:mod:`surfgen.filters.resolution`): how many
    were measured, the spread of ``resolution_shift`` (cells) and ``resolution_area``, and how
    many exceed the default ``[filters]`` limits (shapes accepted before the check existed, or
    under laxer limits)."""

    accepted: int
    shifts: list[float]
    areas: list[float]
    over: list[str]  # keys above the default limits

    def lines(self) -> list[str]:
        measured = len(self.shifts)
        out = [
            f"resolution (twice-as-fine grid): {measured} of {self.accepted} accepted shapes "
            f"measured"
            + (
                f", {self.accepted - measured} not (sampled before the check)"
                if measured < self.accepted
                else ""
            )
        ]
        if measured:
            s, a = np.asarray(self.shifts), np.asarray(self.areas)
            out.append(
                f"  shift (p95 distance, cells): median {np.median(s):.2f}, "
                f"95th percentile {np.percentile(s, 95):.2f}, max {s.max():.2f}; "
                f"area ratio: median {np.median(a):.3f}, max {a.max():.3f}"
            )
            cfg = FilterConfig()
            out.append(
                f"  above the default limits (shift > {cfg.max_resolution_shift:g} or area > "
                f"{cfg.max_resolution_area:g}): {len(self.over)}"
            )
            out += [f"    {k}" for k in self.over[:20]]
        return out


def resolution_summary(shapes: list[dict]) -> ResolutionSummary:
    """:class:`ResolutionSummary` of the accepted rows of ``shapes`` (their stored metrics)."""
    cfg = FilterConfig()
    accepted = [r for r in shapes if r.get("verdict") == "accepted"]
    shifts, areas, over = [], [], []
    for row in accepted:
        try:
            m = json.loads(row.get("metrics") or "{}")
        except json.JSONDecodeError:
            continue
        if m.get("resolution_shift") is None:
            continue
        shifts.append(float(m["resolution_shift"]))
        areas.append(float(m["resolution_area"]))
        if unresolved(m, cfg):
            over.append(row["key"])
    return ResolutionSummary(len(accepted), shifts, areas, sorted(over))


def stored_resolution(mesh_file: Path) -> dict[str, float] | None:
    """The ``resolution_*`` metrics stored for a catalogue's mesh file (``ROOT/meshes/KEY.ply``
    beside ``ROOT/catalogue.sqlite``): what ``surfgen check`` shows for a catalogued shape.
    None for a file outside a catalogue, of a shape the catalogue does not know, or measured
    before the check existed."""
    mesh_file = Path(mesh_file).resolve()
    root = mesh_file.parent.parent
    if mesh_file.parent.name != FILE_COLUMNS["mesh_path"] or not (root / DB_NAME).is_file():
        return None
    try:
        conn = connect_readonly(root / DB_NAME)
        try:
            row = conn.execute(
                "SELECT metrics FROM shapes WHERE key = ?", (mesh_file.stem,)
            ).fetchone()
        finally:
            conn.close()
    except sqlite3.Error:
        return None
    if row is None:
        return None
    metrics = json.loads(row[0] or "{}")
    found = {k: metrics[k] for k in RESOLUTION_METRICS if metrics.get(k) is not None}
    return found or None


def check_catalogue(
    root: Path, repair: bool = False, progress: Callable[[str], None] | None = None
) -> CheckReport:
    """Check (and with ``repair`` mend) the catalogue at ``root``; see the module docstring.

    Raises :class:`CatalogueError` when ``root`` holds no catalogue or a foreign file (which is
    never changed)."""
    root = Path(root)
    db = root / DB_NAME
    if not db.is_file():
        raise CatalogueError(f"no catalogue at {root} (expected {db})")
    report = CheckReport(root)
    if repair and in_use(db):
        raise CatalogueError(
            f"catalogue {root} is open in another process (a `sample` or `serve`?): stop it "
            "before --repair"
        )
    empty = False
    try:
        # a foreign file raises here, before anything is written; an empty database (a 0-byte
        # file is one to SQLite) is an empty catalogue, which `sample` fills
        empty = identify(db) is None
        conn = connect_readonly(db)
        rows = conn.execute("PRAGMA integrity_check(20)").fetchall()
        problems = [r[0] for r in rows if r[0] != "ok"]
        conn.close()
    except CorruptCatalogue as exc:
        problems = [str(exc)]
    except sqlite3.DatabaseError as exc:
        problems = [str(exc)]
    report.integrity = problems
    if problems and repair:
        _salvage(db, report)
    shapes = [] if empty else _read_shapes(db, report)
    report.shapes = len(shapes)
    report.resolution = resolution_summary(shapes)
    referenced: set[str] = set()
    for row in shapes:
        for column in FILE_COLUMNS:
            rel = row.get(column)
            if rel:
                referenced.add(str(rel))
                if not (root / rel).is_file():
                    report.missing.append((row["key"], column, str(rel)))
            elif column == "mesh_path" and row.get("verdict") == "accepted":
                report.missing.append((row["key"], column, "(none recorded)"))
    for folder in FILE_COLUMNS.values():
        d = root / folder
        if not d.is_dir():
            continue
        for f in sorted(d.iterdir()):
            rel = f"{folder}/{f.name}"
            if f.name.startswith(".") and f.name.endswith(".tmp"):
                report.temporary.append(f)
            elif rel not in referenced:
                report.orphans.append(f)
    report.temporary += sorted(root.glob(".*.tmp"))
    if (root / ".staging").exists():
        report.temporary.append(root / ".staging")
    report.running = _running_runs(db)
    if repair:
        _repair_files(root, report, shapes, progress)
    return report


def _read_rows(conn: sqlite3.Connection, table: str) -> tuple[list[dict], int]:
    """Every readable row of ``table`` and how many could not be read: the whole table at
    once when it is sound, else row by row (a damaged page loses only its own rows)."""
    try:
        return [dict(r) for r in conn.execute(f"SELECT rowid AS _rowid_, * FROM {table}")], 0
    except sqlite3.DatabaseError:
        pass
    rows, lost = [], 0
    try:
        top = conn.execute(f"SELECT max(rowid) FROM {table}").fetchone()[0] or 0
    except sqlite3.DatabaseError:
        return [], -1
    for rowid in range(1, top + 1):
        try:
            r = conn.execute(f"SELECT rowid AS _rowid_, * FROM {table} WHERE rowid=?", (rowid,))
            row = r.fetchone()
        except sqlite3.DatabaseError:
            lost += 1
            continue
        if row is not None:
            rows.append(dict(row))
    return rows, lost


def _read_shapes(db: Path, report: CheckReport) -> list[dict]:
    try:
        conn = connect_readonly(db)
    except sqlite3.Error as exc:
        report.unrepaired.append(f"cannot read the database at all ({exc})")
        return []
    try:
        rows, lost = _read_rows(conn, "shapes")
    finally:
        conn.close()
    if lost:
        report.unrepaired.append(
            f"{lost if lost > 0 else 'some'} shape rows cannot be read"
            + ("" if report.repaired else " (--repair copies the readable rows)")
        )
    return rows


def _salvage(db: Path, report: CheckReport) -> None:
    """Copy every readable row into a fresh database and put it in place of the damaged one."""
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S")
    fresh = db.with_name(f".{db.name}.{stamp}.new")
    kept = db.with_name(f"{db.name}.corrupt-{stamp}")
    try:
        old = connect_readonly(db)
    except sqlite3.Error as exc:
        report.unrepaired.append(f"the database cannot be opened ({exc}): nothing to salvage")
        return
    new = sqlite3.connect(fresh)
    copied: dict[str, int] = {}
    lost_total = 0
    try:
        new.executescript(SCHEMA + META)
        for table in TABLES:
            rows, lost = _read_rows(old, table)
            lost_total += max(lost, 0)
            have = {r[1] for r in new.execute(f"PRAGMA table_info({table})")}
            for row in rows:
                row.pop("_rowid_", None)
                cols = [c for c in row if c in have]
                marks = ",".join("?" * len(cols))
                try:
                    new.execute(
                        f"INSERT OR IGNORE INTO {table} ({','.join(cols)}) VALUES ({marks})",
                        [row[c] for c in cols],
                    )
                except sqlite3.Error:
                    lost_total += 1
            copied[table] = len(rows)
        new.commit()
    finally:
        old.close()
        new.close()
    for suffix in ("", "-wal", "-shm"):
        src = Path(str(db) + suffix)
        if src.exists():
            src.replace(Path(str(kept) + suffix))
    fresh.replace(db)
    report.repaired.append(
        "database rebuilt from its readable rows ("
        + ", ".join(f"{n} {t}" for t, n in copied.items())
        + f"; the damaged file is kept as {kept.name})"
    )
    if lost_total:
        report.unrepaired.append(
            f"{lost_total} rows could not be read and are lost (their files become orphans)"
        )
    report.integrity = []


def _running_runs(db: Path) -> list[int]:
    try:
        conn = connect_readonly(db)
        try:
            return [r[0] for r in conn.execute("SELECT id FROM runs WHERE status='running'")]
        finally:
            conn.close()
    except sqlite3.Error:
        return []


def _repair_files(
    root: Path, report: CheckReport, shapes: list[dict], progress: Callable[[str], None] | None
) -> None:
    for path in report.temporary:
        if path.is_dir():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)
    if report.temporary:
        report.repaired.append(f"removed {len(report.temporary)} temporary files")
        report.temporary = []
    if report.orphans:
        (root / "orphans").mkdir(exist_ok=True)
        for f in report.orphans:
            f.replace(root / "orphans" / f"{f.parent.name}-{f.name}")
        report.repaired.append(f"moved {len(report.orphans)} orphan files into {root / 'orphans'}")
        report.orphans = []
    missing_keys = {k for k, _, _ in report.missing}
    if not missing_keys:
        return
    by_key = {r["key"]: r for r in shapes}
    fixed: list[str] = []
    with open_catalogue(root, must_exist=True) as cat:
        cat.make_dirs()
        for key in sorted(missing_keys):
            row = by_key[key]
            if progress is not None:
                progress(key)
            try:
                _rebuild_files(cat, row)
            except SurfgenError as exc:
                report.unrepaired.append(f"{key}: {exc}")
                continue
            fixed.append(key)
    if fixed:
        report.repaired.append(f"re-made the files of {len(fixed)} shapes from their specs")
    report.missing = [m for m in report.missing if m[0] not in fixed]


def _rebuild_files(cat, row: dict) -> None:
    """Re-make an accepted shape's mesh from its spec (capped as its run was) and its pictures
    from the mesh, then record their paths."""

    key = row["key"]
    if row.get("verdict") != "accepted":
        return  # rejected draws have no files to rebuild
    spec = SurfaceSpec.from_json(row["spec"])
    mesh_file = cat.meshes / f"{key}.ply"
    if mesh_file.is_file():
        mesh = load_mesh(mesh_file)
    else:
        run = cat.conn.execute("SELECT config FROM runs WHERE id=?", (row["run"],)).fetchone()
        config = json.loads(run["config"]) if run is not None else {}
        cap = bool(config.get("run", {}).get("cap", True))
        mesh = realise(spec, cap=cap).mesh
        save_mesh(mesh, mesh_file)
    thumb, turn = cat.thumbs / f"{key}.png", cat.turntables / f"{key}.png"
    if not thumb.is_file():
        render_thumbnail(mesh, thumb, size=256)
    if not turn.is_file():
        render_turntable(mesh, turn, views=12, size=TURNTABLE_SIZE)
    with cat.conn:
        cat.conn.execute(
            "UPDATE shapes SET mesh_path=?, thumb_path=?, turntable_path=? WHERE key=?",
            (f"meshes/{key}.ply", f"thumbs/{key}.png", f"turntables/{key}.png", key),
        )
