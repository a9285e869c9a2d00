"""The gallery as a page: its data (:func:`gallery_data`), its HTML (:func:`render_page`), and
the static, read-only copy to publish (:func:`export_gallery`, ``surfgen gallery``), which draws
the turntables it is missing first, on every core.

The page (``templates/gallery.html``, ``static/gallery.js``/``.css``) carries its data as JSON
and loads nothing from the internet.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from surfgen.generator.files import staged_folder
from surfgen.pipelines.catalogue.curation import select_shapes
from surfgen.pipelines.catalogue.query import FIELDS
from surfgen.pipelines.catalogue.store import (
    DB_NAME,
    Catalogue,
    CatalogueError,
    now,
    open_catalogue,
)
from surfgen.pipelines.pictures.pool import Job, draw_all
from surfgen.pipelines.pictures.thumbnails import GalleryError, record_picture
from surfgen.pipelines.web.pages import script_json, static_dir, templates, write_page
from surfgen.pipelines.web.viewer import export_detail_pages

log = logging.getLogger(__name__)


def gallery_data(cat: Catalogue, readonly: bool, where: str | None = None) -> dict[str, Any]:
    """Everything the page shows: the accepted shapes (``where`` selects some), runs, fields."""
    shapes = select_shapes(cat, where=where)
    for s in shapes:
        s.pop("identity", None)
    runs = {}
    for r in cat.runs():
        runs[str(r["id"])] = {
            "seed": r["seed"],
            "grid": r["grid"],
            "status": r["status"],
            "started": r["started"],
            "config_hash": r["config_hash"],
            "versions": json.loads(r["versions"] or "{}"),
        }
    return {
        "readonly": readonly,
        "catalogue": str(cat.root),
        "generated": now(),
        "meshes": not readonly,
        "runs": runs,
        "where_fields": {name: f.help for name, f in FIELDS.items()},
        "shapes": shapes,
    }


def render_page(data: dict[str, Any], title: str = "surfgen gallery") -> str:
    """The gallery HTML for ``data`` (from :func:`gallery_data`)."""
    n = len(data["shapes"])
    subtitle = f"{n} shape{'s' if n != 1 else ''} · {data['catalogue']}"
    return (
        templates()
        .get_template("gallery.html")
        .render(
            title=title, subtitle=subtitle, readonly=data["readonly"], data_json=script_json(data)
        )
    )


def export_gallery(
    root: Path,
    out: Path,
    where: str | None = None,
    meshes: bool = False,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[Path, int]:
    """Write the read-only gallery of the catalogue at ``root`` into folder ``out``:
    ``index.html``, ``static/``, ``thumbs/``, ``turntables/`` (and ``meshes/`` with ``meshes``).
    Turntables not rendered yet are rendered first, on ``workers`` processes (default: one per
    core; ``progress(done, total)`` after each), into the gallery, and cached in the catalogue
    once the gallery is written, if this user may write it: a failed export leaves the catalogue
    as it was. The catalogue is read through a read-only connection. Everything is written
    into a temporary folder beside ``out`` that replaces ``out`` at the end: an earlier gallery
    there is kept if anything fails; a folder with other files in it is refused.

    Returns the index path and the number of shapes. Raises :class:`CatalogueError` for a
    missing catalogue and :class:`GalleryError` if ``out`` cannot be written.
    """
    out = Path(out)
    if out.resolve() == Path(root).resolve():
        raise GalleryError("write the gallery to another folder than the catalogue")
    _check_gallery_target(out)
    with open_catalogue(root, must_exist=True, readonly=True) as cat:
        data = gallery_data(cat, readonly=True, where=where)
        data["catalogue"] = cat.root.name
        data["meshes"] = meshes
        missing = [
            s
            for s in data["shapes"]
            if s["mesh"] and not (s["turntable"] and (cat.root / s["turntable"]).is_file())
        ]
    # A static page cannot render on demand: make the turntables nobody asked for yet, into the
    # gallery (``fresh``: their PNG bytes by key); once the gallery is written, they are cached in
    # the catalogue too when this user may write it (so the next export copies them). A failed
    # export changes nothing in the catalogue.
    fresh: dict[str, bytes] = {}
    if missing:
        by_key = {s["key"]: s for s in missing}
        jobs = [Job(s["key"], str(Path(root) / s["mesh"]), ("turntable",)) for s in missing]
        for drawn in draw_all(jobs, workers, progress):
            shape, png = by_key[drawn.job.key], drawn.pictures.get("turntable")
            if png is None:
                log.warning("shape %s: no turntable (%s)", shape["key"], drawn.error)
                shape["turntable"] = None
            else:
                fresh[shape["key"]] = png
                shape["turntable"] = f"turntables/{shape['key']}.png"
    existed = out.exists()
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        with staged_folder(out) as work:  # all or nothing: `out` changes only at the end
            _write_gallery(Path(root), work, data, meshes, fresh)
    except OSError as exc:
        where = f" ({exc.filename})" if exc.filename and Path(exc.filename) != out else ""
        kept = "the gallery there was left as it was" if existed else "nothing was written"
        raise GalleryError(
            f"cannot write the gallery to {out}: {exc.strerror or exc}{where}; {kept}"
        ) from None
    if fresh:
        _cache_turntables(Path(root), fresh)
    return out / "index.html", len(data["shapes"])


def _cache_turntables(root: Path, fresh: Mapping[str, bytes]) -> None:
    """Record the turntables drawn for a gallery in the catalogue, when this user may write it:
    the gallery is complete either way, so a catalogue that cannot take them is only logged."""
    if not _writable_catalogue(root):
        log.warning(
            "catalogue %s is read-only: %d turntables were rendered for the gallery only",
            root,
            len(fresh),
        )
        return
    try:
        with open_catalogue(root, must_exist=True) as cat:
            cat.make_dirs()
            for key, png in fresh.items():
                record_picture(cat, key, "turntable", png)
    except (CatalogueError, OSError) as exc:
        log.warning("the gallery is written; its turntables were not cached in %s: %s", root, exc)


GALLERY_MARK = ".surfgen-gallery"  # a folder holding it is a gallery that may be replaced
GALLERY_ENTRIES = {"index.html", "static", "thumbs", "turntables", "meshes", "shapes", GALLERY_MARK}


def _check_gallery_target(out: Path) -> None:
    """Refuse a target that is not a folder surfgen may replace whole: a file, or a folder
    with anything but an earlier gallery in it (``gallery -o ~`` must not swap out a home)."""
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        raise GalleryError(f"cannot write the gallery to {out}: it is a file, not a folder")
    if not out.is_dir() or (out / GALLERY_MARK).is_file():
        return
    foreign = sorted(p.name for p in out.iterdir() if p.name not in GALLERY_ENTRIES)
    if foreign:
        shown = ", ".join(foreign[:3]) + (", ..." if len(foreign) > 3 else "")
        raise GalleryError(
            f"cannot write the gallery to {out}: the folder holds other files ({shown}) and "
            "a gallery replaces its folder whole; choose a new or empty folder"
        )


def _writable_catalogue(root: Path) -> bool:
    """Whether this user may write the catalogue's database, folder and turntables."""
    folders = [root, root / "turntables"]
    return os.access(root / DB_NAME, os.W_OK) and all(
        os.access(f, os.W_OK) for f in folders if f.exists()
    )


def _write_gallery(
    root: Path,
    work: Path,
    data: dict[str, Any],
    meshes: bool,
    fresh: Mapping[str, bytes] | None = None,
) -> None:
    """Every file of the static gallery, into the (new, empty) folder ``work``; ``fresh``
    turntables (PNG bytes by key, drawn for a read-only catalogue) go straight into it."""
    (work / "turntables").mkdir()
    for key, png in (fresh or {}).items():
        (work / "turntables" / f"{key}.png").write_bytes(png)
    for sub in ("static", "thumbs", *(["meshes"] if meshes else [])):
        (work / sub).mkdir(parents=True, exist_ok=True)
    for f in static_dir().iterdir():
        if f.is_file():
            shutil.copy2(f, work / "static" / f.name)
    for s in data["shapes"]:
        for kind in ("thumb", "turntable", *(["mesh"] if meshes else [])):
            rel = s[kind]
            if kind == "turntable" and rel and (work / rel).is_file():
                continue  # rendered just now
            if rel and (root / rel).is_file():
                (work / rel).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(root / rel, work / rel)
            else:
                s[kind] = None
        if not meshes:
            s["mesh"] = None
    if meshes:  # 3-D detail pages need the meshes
        export_detail_pages(root, work, data["shapes"])
    write_page(work / "index.html", render_page(data))
    (work / GALLERY_MARK).write_text(
        json.dumps({"surfgen": "gallery", "catalogue": data["catalogue"]}) + "\n"
    )
