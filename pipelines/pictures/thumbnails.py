"""The catalogue's pictures: thumbnails and turntables rendered on every core and recorded,
and contact sheets.

- :func:`render_pictures` renders missing thumbnails and turntables (``surfgen thumbnails``), on
  every core (:mod:`surfgen.pipelines.pictures.pool`), and records them;
- :func:`ensure_turntable` renders one turntable on demand (the live gallery's image route);
- :func:`write_contact_sheet` composes thumbnails into one PNG (``surfgen contact-sheet``).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from surfgen.generator.errors import MeshError, SurfgenError
from surfgen.generator.files import renaming, stage
from surfgen.pipelines.catalogue.curation import select_shapes
from surfgen.pipelines.catalogue.store import Catalogue, CatalogueError
from surfgen.pipelines.pictures.pool import Job, draw, draw_all

log = logging.getLogger(__name__)

MAX_SHEET = 2_000  # thumbnails on one contact sheet (256 px each: 2000 is ~130 MPixel)


class GalleryError(SurfgenError):
    """A gallery, sheet or picture that cannot be made (no thumbnails, unwritable folder...)."""


@dataclass(frozen=True)
class PictureResult:
    rendered: int
    skipped: int
    failed: list[tuple[str, str]]


# One lock per key: the live gallery is threaded, and two hovers of one card must not render
# its turntable twice (the atomic write would make that harmless, only wasteful).
_RENDERING: dict[str, threading.Lock] = {}
_RENDERING_GUARD = threading.Lock()


def ensure_turntable(cat: Catalogue, key: str, force: bool = False) -> Path | None:
    """The turntable strip of accepted shape ``key``: the cached file if it is recorded and
    there, else rendered from the mesh now (atomic write into ``turntables/KEY.png``) and
    recorded (the file and its row as one), so later requests and later servers serve the file.

    Returns None for a shape that is not accepted or has no mesh. Raises
    :class:`CatalogueError` for an unknown key and :class:`SurfgenError` (a ``MeshError``)
    if the mesh cannot be read or drawn.
    """
    with _RENDERING_GUARD:
        lock = _RENDERING.setdefault(key, threading.Lock())
    with lock:
        row = cat.conn.execute(
            "SELECT verdict, mesh_path, turntable_path FROM shapes WHERE key=?", (key,)
        ).fetchone()
        if row is None:
            raise CatalogueError(f"no shape with key '{key}' in {cat.root}")
        target = cat.turntables / f"{key}.png"
        recorded = row["turntable_path"]
        if not force and recorded and (cat.root / recorded).is_file():
            return cat.root / recorded
        if row["verdict"] != "accepted" or not row["mesh_path"]:
            log.info("shape %s: no turntable (not accepted or no mesh)", key)
            return None
        if force or not target.is_file():  # else a file written by a process killed before
            # it could record it: keep it
            drawn = draw(Job(key, str(cat.root / row["mesh_path"]), ("turntable",)))
            if drawn.error is not None:
                raise MeshError(drawn.error)
            log.info("rendered the turntable of %s", key)
            return record_picture(cat, key, "turntable", drawn.pictures["turntable"])
        rel = str(target.relative_to(cat.root))
        if recorded != rel:
            with cat.conn:
                cat.conn.execute("UPDATE shapes SET turntable_path=? WHERE key=?", (rel, key))
        return target


_PICTURE_COLUMNS = {"thumb": "thumb_path", "turntable": "turntable_path"}


def record_picture(cat: Catalogue, key: str, kind: str, data: bytes) -> Path:
    """Write the ``kind`` picture of ``key`` (``thumbs/KEY.png`` or ``turntables/KEY.png``) and
    record it: the file and its row as one (a row that cannot be written, e.g. on a full disk,
    takes the new file back)."""
    folder = cat.thumbs if kind == "thumb" else cat.turntables
    target = folder / f"{key}.png"
    staged = stage(target, data)
    try:
        with renaming() as tx:
            tx.move(staged, target)
            with cat.conn:
                cat.conn.execute(
                    f"UPDATE shapes SET {_PICTURE_COLUMNS[kind]}=? WHERE key=?",
                    (str(target.relative_to(cat.root)), key),
                )
    finally:
        staged.unlink(missing_ok=True)
    return target


def render_pictures(
    cat: Catalogue,
    force: bool = False,
    where: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    turntables: bool = True,
    workers: int | None = None,
) -> PictureResult:
    """Render the missing thumbnails (256², ``thumbs/KEY.png``) and, with ``turntables``, the
    missing 12-view turntables (``turntables/KEY.png``) of the accepted shapes (all of them
    with ``force``) from their meshes, on ``workers`` processes (default: one per core,
    :mod:`surfgen.pipelines.pictures.pool`), and record their paths. Shapes whose mesh cannot be
    read are listed in ``failed``, the others still rendered. Raises :class:`WhereError` for a
    bad ``where``."""
    cat.make_dirs()
    shapes = select_shapes(cat, where=where)
    failed: list[tuple[str, str]] = []

    def have(rel: str | None) -> bool:
        return bool(rel) and (cat.root / rel).is_file() and not force  # type: ignore[operator]

    jobs = []
    for s in shapes:
        kinds = ("thumb",) * (not have(s["thumb"]))
        kinds += ("turntable",) * (turntables and not have(s["turntable"]))
        if kinds and not s["mesh"]:
            failed.append((s["key"], "no mesh recorded"))
        elif kinds:
            jobs.append(Job(s["key"], str(cat.root / s["mesh"]), kinds))
    skipped = len(shapes) - len(jobs) - len(failed)
    before = len(shapes) - len(jobs)

    def advance(done: int, total: int) -> None:
        if progress is not None:
            progress(before + done, len(shapes))

    if progress is not None and not jobs:
        progress(len(shapes), len(shapes))
    rendered = 0
    for drawn in draw_all(jobs, workers, advance):
        if drawn.error is not None:
            log.info("shape %s: no pictures (%s)", drawn.job.key, drawn.error)  # counted below
            failed.append((drawn.job.key, drawn.error))
            continue
        for kind, data in drawn.pictures.items():
            record_picture(cat, drawn.job.key, kind, data)
        rendered += 1
    return PictureResult(rendered, skipped, failed)


def write_contact_sheet(
    cat: Catalogue,
    path: Path,
    where: str | None = None,
    sort: str | None = None,
    limit: int | None = None,
    columns: int = 6,
) -> tuple[Path, int]:
    """A grid of the thumbnails of the selected shapes, each labelled with its short key.

    Returns the path and the number of thumbnails. Raises :class:`GalleryError` when no
    selected shape has a thumbnail, :class:`WhereError` for a bad ``where``/``sort``.
    """
    # Deferred on purpose: the rasteriser loads numba and trimesh, which the live gallery
    # (importing this module) does not need to start.
    from surfgen.pipelines.pictures.raster import contact_sheet

    if not 1 <= columns <= 100:
        raise GalleryError(f"--columns must be from 1 to 100, got {columns}")
    if limit is not None and not 0 <= limit <= MAX_SHEET:
        raise GalleryError(f"--limit must be from 0 to {MAX_SHEET}, got {limit}")
    if path.suffix.lower() != ".png":
        raise GalleryError(f"the contact sheet is a PNG: '{path}' should end in .png")
    shapes = select_shapes(cat, where=where, sort=sort)
    items = [
        (cat.root / s["thumb"], s["key"][:8])
        for s in shapes
        if s["thumb"] and (cat.root / s["thumb"]).is_file()
    ]
    if limit is not None:
        items = items[: max(limit, 0)]
    if not items:
        raise GalleryError(
            f"none of the {len(shapes)} selected shapes has a thumbnail"
            + (" (run `surfgen thumbnails` first)" if shapes else "")
        )
    return contact_sheet(items, path, columns=columns), len(items)
