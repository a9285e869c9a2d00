"""Looking at the catalogue: thumbnails, contact sheets and the browser gallery.

- :func:`render_pictures` renders missing thumbnails and turntables (``surfgen thumbnails``), on
  every core (:mod:`surfgen.pipelines.pictures.pool`), and records them;
- :func:`write_contact_sheet` composes thumbnails into one PNG (``surfgen contact-sheet``);
- :func:`create_app` is the live gallery (``surfgen serve``): a Flask app over one catalogue,
  with a JSON API whose writes all go through :func:`surfgen.pipelines.catalogue.curation.apply_action`,
  so every click is committed at once;
- :func:`export_gallery` writes the same page as static, read-only files (``surfgen gallery``),
  drawing the turntables it is missing first, on every core too.

The page (``templates/gallery.html``, ``static/gallery.js``/``.css``) carries its data as JSON
and loads nothing from the internet. JSON API of the live gallery:

====== ============================== ===================================================
GET    /api/health                    ``{"ok": true, "shapes": N}``
GET    /api/shapes?where=&sort=&limit= shape records (``keys=1``: only their keys)
GET    /api/shapes/KEY                one record with its run and curation history
POST   /api/shapes/KEY/star           ``{"stars": 0-5}``
POST   /api/shapes/KEY/reject         ``{"why": "..."}``; ``/unreject`` with ``{}``
POST   /api/shapes/KEY/tag            ``{"tags": ["a", "b"]}``; ``/untag`` likewise
POST   /api/shapes/KEY/note           ``{"note": "..."}`` (empty removes it)
POST   /api/export                    form field ``keys`` (comma-separated): a zip of meshes
                                      and specs
====== ============================== ===================================================

Writes must be ``application/json`` (a cross-site form cannot send that without a preflight the
app never grants) and, when bound to a loopback address, requests must name a loopback host.
Errors come back as ``{"error": "..."}`` with status 400 (bad value), 404 (unknown key) or 415.
"""

from __future__ import annotations

import io
import json
import logging
import os
import re
import shutil
import threading
import zipfile
from collections.abc import Callable, Mapping
from contextlib import ExitStack
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from surfgen.generator.errors import MeshError, SurfgenError
from surfgen.generator.files import renaming, stage, staged_folder
from surfgen.pipelines.catalogue.curation import (
    MAX_NOTE,
    MAX_REASON,
    MAX_STARS,
    MAX_TAGS,
    CatalogueOption,
    CurationError,
    apply_action,
    get_shape,
    select_shapes,
)
from surfgen.pipelines.catalogue.query import FIELDS, WhereError
from surfgen.pipelines.catalogue.store import (
    DB_NAME,
    DEFAULT_CATALOGUE,
    Catalogue,
    CatalogueError,
    CorruptCatalogue,
    now,
    open_catalogue,
)
from surfgen.pipelines.run.warmup import compile_notice
from surfgen.pipelines.web.api import (
    Param,
    install,
    json_body,
    key_list,
    query_flag,
    query_int,
    query_str,
)

if TYPE_CHECKING:
    from flask import Flask
    from werkzeug.serving import BaseWSGIServer

log = logging.getLogger(__name__)

LOOPBACK = ("127.0.0.1", "localhost", "::1", "[::1]")
_KEY = re.compile(r"[0-9a-f]{8,64}")  # a shape key (hex): what the turntable route renders
# The value each API action reads from the request body, and what it may be.
_ACTION_FIELD = {
    "star": "stars",
    "reject": "why",
    "unreject": None,
    "tag": "tags",
    "untag": "tags",
    "note": "note",
}
_ACTION_SCHEMA: dict[str, dict[str, Param]] = {
    "star": {"stars": Param("int", low=0, high=MAX_STARS)},
    "reject": {"why": Param("str", required=True, nullable=False, max_length=MAX_REASON)},
    "unreject": {},
    "tag": {
        "tags": Param("tags", required=True, nullable=False, max_length=40, max_items=MAX_TAGS)
    },
    "untag": {
        "tags": Param("tags", required=True, nullable=False, max_length=40, max_items=MAX_TAGS)
    },
    "note": {"note": Param("str", max_length=MAX_NOTE)},
}
MAX_LIST = 100_000  # shapes in one /api/shapes reply
MAX_SHEET = 2_000  # thumbnails on one contact sheet (256 px each: 2000 is ~130 MPixel)


class GalleryError(SurfgenError):
    """A gallery, sheet or picture that cannot be made (no thumbnails, unwritable folder...)."""


# ----------------------------------------------------------------------------- pictures


@dataclass(frozen=True)
class PictureResult:
    rendered: int
    skipped: int
    failed: list[tuple[str, str]]


# One lock per key: the live gallery is threaded, and two hovers of one card must not render
# its turntable twice (the atomic write would make that harmless, only wasteful).
_RENDERING: dict[str, threading.Lock] = {}
_RENDERING_GUARD = threading.Lock()


def turntable_url(rec: dict[str, Any]) -> dict[str, Any]:
    """``rec`` (a :func:`~surfgen.pipelines.catalogue.curation.shape_record`) with ``turntable`` set to
    where the live gallery serves it, rendered or not: an accepted shape with a mesh always
    has one (the image route renders it on first request, :func:`ensure_turntable`)."""
    if rec.get("mesh") and not rec.get("turntable") and rec.get("verdict") == "accepted":
        rec["turntable"] = f"turntables/{rec['key']}.png"
    return rec


def ensure_turntable(cat: Catalogue, key: str, force: bool = False) -> Path | None:
    """The turntable strip of accepted shape ``key``: the cached file if it is recorded and
    there, else rendered from the mesh now (atomic write into ``turntables/KEY.png``) and
    recorded (the file and its row as one), so later requests and later servers serve the file.

    Returns None for a shape that is not accepted or has no mesh. Raises
    :class:`CatalogueError` for an unknown key and :class:`SurfgenError` (a ``MeshError``)
    if the mesh cannot be read or drawn.
    """
    from surfgen.pipelines.pictures.pool import Job, draw

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
            return _record_picture(cat, key, "turntable", drawn.pictures["turntable"])
        rel = str(target.relative_to(cat.root))
        if recorded != rel:
            with cat.conn:
                cat.conn.execute("UPDATE shapes SET turntable_path=? WHERE key=?", (rel, key))
        return target


_PICTURE_COLUMNS = {"thumb": "thumb_path", "turntable": "turntable_path"}


def _record_picture(cat: Catalogue, key: str, kind: str, data: bytes) -> Path:
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
    from surfgen.pipelines.pictures.pool import Job, draw_all

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
            log.warning("shape %s: no pictures (%s)", drawn.job.key, drawn.error)
            failed.append((drawn.job.key, drawn.error))
            continue
        for kind, data in drawn.pictures.items():
            _record_picture(cat, drawn.job.key, kind, data)
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


# ----------------------------------------------------------------------------- the page


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


def _script_json(data: Any) -> str:
    """JSON safe inside ``<script>``: no ``</script>`` or HTML comment can close it."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False, default=str)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def render_page(data: dict[str, Any], title: str = "surfgen gallery") -> str:
    """The gallery HTML for ``data`` (from :func:`gallery_data`)."""
    import jinja2

    env = jinja2.Environment(
        loader=jinja2.PackageLoader("surfgen.pipelines.web", "templates"),
        autoescape=jinja2.select_autoescape(["html"]),
    )
    n = len(data["shapes"])
    subtitle = f"{n} shape{'s' if n != 1 else ''} · {data['catalogue']}"
    return env.get_template("gallery.html").render(
        title=title, subtitle=subtitle, readonly=data["readonly"], data_json=_script_json(data)
    )


def _static_dir() -> Path:
    return Path(str(resources.files("surfgen.pipelines.web").joinpath("static")))


# ----------------------------------------------------------------------------- static export


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
    core; ``progress(done, total)`` after each), and cached in the catalogue if this user may
    write it. The catalogue is read through a read-only connection. Everything is written
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
    # A static page cannot render on demand: make the turntables nobody asked for yet, cached
    # in the catalogue (so the next export copies them) — or, for a catalogue this user cannot
    # write, in the gallery only (``fresh``: their PNG bytes by key).
    fresh: dict[str, bytes] = {}
    if missing:
        from surfgen.pipelines.pictures.pool import Job, draw_all

        writable = _writable_catalogue(Path(root))
        if not writable:
            log.warning(
                "catalogue %s is read-only: %d turntables are rendered for the gallery only",
                root,
                len(missing),
            )
        by_key = {s["key"]: s for s in missing}
        jobs = [Job(s["key"], str(Path(root) / s["mesh"]), ("turntable",)) for s in missing]
        with ExitStack() as stack:
            cat = stack.enter_context(open_catalogue(root, must_exist=True)) if writable else None
            if cat is not None:
                cat.make_dirs()
            for drawn in draw_all(jobs, workers, progress):
                shape, png = by_key[drawn.job.key], drawn.pictures.get("turntable")
                if png is None:
                    log.warning("shape %s: no turntable (%s)", shape["key"], drawn.error)
                    shape["turntable"] = None
                elif cat is None:
                    fresh[shape["key"]] = png
                    shape["turntable"] = f"turntables/{shape['key']}.png"
                else:
                    made = _record_picture(cat, shape["key"], "turntable", png)
                    shape["turntable"] = str(made.relative_to(cat.root))
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
    return out / "index.html", len(data["shapes"])


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
    for f in _static_dir().iterdir():
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
        from surfgen.pipelines.web.viewer import export_detail_pages

        export_detail_pages(root, work, data["shapes"])
    write_page(work / "index.html", render_page(data))
    (work / GALLERY_MARK).write_text(
        json.dumps({"surfgen": "gallery", "catalogue": data["catalogue"]}) + "\n"
    )


def write_page(path: Path, text: str) -> Path:
    """Write an HTML page atomically, readable by all (it is meant to be published)."""
    from surfgen.generator.files import write_atomic

    write_atomic(path, text.encode("utf-8"))
    path.chmod(0o644)
    return path


# ----------------------------------------------------------------------------- live app


def create_app(root: Path, host: str = "127.0.0.1") -> Flask:
    """The live gallery over the catalogue at ``root`` (which must exist).

    Each request opens its own connection (SQLite connections are per thread). Raises
    :class:`CatalogueError` if there is no catalogue at ``root``.
    """
    from flask import Flask, Response, abort, g, jsonify, request, send_from_directory

    root = Path(root).resolve()
    with open_catalogue(root, readonly=True) as first:  # identify it, and refuse a damaged one
        problem = first.conn.execute("PRAGMA quick_check").fetchone()[0]
    if problem != "ok":
        raise CorruptCatalogue(
            f"catalogue {root} is corrupted ({problem}): run `surfgen catalogue check -C {root}`"
        )
    app = Flask(__name__, static_folder=str(_static_dir()), static_url_path="/static")
    app.json.sort_keys = False  # type: ignore[attr-defined]
    install(app)
    if host in LOOPBACK:
        app.config["TRUSTED_HOSTS"] = list(LOOPBACK)

    def cat(write: bool | None = None) -> Catalogue:
        """This request's catalogue connection: read-only for GET requests (and whenever
        ``write`` is False), read-write for requests that may write (POST...)."""
        if write is None:
            write = request.method not in ("GET", "HEAD", "OPTIONS")
        if "cat" not in g or (write and not g.cat_writes):
            if "stack" in g:
                g.stack.close()
            g.stack = ExitStack()
            g.cat = g.stack.enter_context(open_catalogue(root, must_exist=True, readonly=not write))
            g.cat_writes = write
        return g.cat

    @app.teardown_appcontext
    def _close(_exc: BaseException | None) -> None:
        stack = g.pop("stack", None)
        if stack is not None:
            stack.close()

    @app.errorhandler(CatalogueError)
    def _catalogue_error(exc: CatalogueError):
        status = 400 if isinstance(exc, CurationError | WhereError) else 404
        return jsonify(error=str(exc)), status

    @app.get("/")
    def index() -> Response:
        data = gallery_data(cat(), readonly=False)
        data["shapes"] = [turntable_url(s) for s in data["shapes"]]
        return Response(render_page(data), mimetype="text/html")

    @app.get("/turntables/<path:name>")
    def turntable(name: str) -> Response:
        # Rendered on first request and cached in the catalogue (ensure_turntable).
        key = name.removesuffix(".png")
        if not (root / "turntables" / name).is_file() and _KEY.fullmatch(key):
            try:
                ensure_turntable(cat(write=True), key)
            except CatalogueError:
                abort(404)
            except SurfgenError as exc:
                log.warning("shape %s: no turntable (%s)", key, exc)
                abort(404)
        return send_from_directory(root / "turntables", name, max_age=0)

    for folder in ("thumbs", "meshes"):

        def send(name: str, _folder: str = folder) -> Response:
            return send_from_directory(root / _folder, name, max_age=0)

        app.add_url_rule(f"/{folder}/<path:name>", f"file_{folder}", send)

    from surfgen.pipelines.web.viewer import viewer_blueprint

    app.register_blueprint(viewer_blueprint(root, cat))  # /shape/KEY, /api/explore, ...

    @app.get("/api/health")
    def health():
        n = cat().conn.execute("SELECT count(*) FROM shapes WHERE verdict='accepted'").fetchone()[0]
        return jsonify(ok=True, shapes=n)

    @app.get("/api/shapes")
    def shapes():
        recs = select_shapes(
            cat(),
            where=query_str("where"),
            sort=query_str("sort", 200),
            limit=query_int("limit", 0, MAX_LIST),
            everything=query_flag("all"),
        )
        if query_flag("keys"):
            return jsonify(keys=[r["key"] for r in recs])
        return jsonify(count=len(recs), shapes=[turntable_url(r) for r in recs])

    @app.get("/api/shapes/<key>")
    def shape(key: str):
        return jsonify(shape=turntable_url(get_shape(cat(), key)))

    @app.post("/api/shapes/<key>/<action>")
    def curate(key: str, action: str):
        if action not in _ACTION_FIELD:
            abort(404)
        body = json_body(_ACTION_SCHEMA[action])
        field = _ACTION_FIELD[action]
        value = body.get(field) if field else None
        return jsonify(shape=turntable_url(apply_action(cat(write=True), key, action, value)))

    @app.post("/api/export")
    def export():
        keys = key_list(request.form.getlist("keys"))
        if not keys:
            return jsonify(error="no shapes to export"), 400
        data = _export_zip(cat(), keys)
        stamp = now().replace(":", "").replace("-", "")[:15]
        return Response(
            data,
            mimetype="application/zip",
            headers={"Content-Disposition": f'attachment; filename="surfgen-{stamp}.zip"'},
        )

    return app


def _export_zip(cat: Catalogue, keys: list[str]) -> bytes:
    """A zip of ``meshes/KEY.ply``, ``specs/KEY.json`` and ``shapes.json`` for ``keys``."""
    buf = io.BytesIO()
    records = []
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for key in keys:
            rec = get_shape(cat, key, full=False)
            records.append(rec)
            z.writestr(f"specs/{rec['key']}.json", json.dumps(rec["spec"], indent=2))
            if rec["mesh"] and (cat.root / rec["mesh"]).is_file():
                z.write(cat.root / rec["mesh"], f"meshes/{rec['key']}.ply")
        z.writestr("shapes.json", json.dumps(records, indent=1))
    return buf.getvalue()


def make_server(root: Path, host: str = "127.0.0.1", port: int = 8000) -> BaseWSGIServer:
    """A threaded HTTP server of the live gallery (``port`` 0: any free port); call its
    ``serve_forever()``. Raises :class:`GalleryError` if the address cannot be bound."""
    from threading import Thread

    from werkzeug.serving import make_server as werkzeug_server

    from surfgen.pipelines.studies.explore import warm_up

    app = create_app(root, host)
    Thread(target=warm_up, name="explore-warm-up", daemon=True).start()  # first slider step
    try:
        return werkzeug_server(host, port, app, threaded=True)
    except (OSError, SystemExit) as exc:  # werkzeug exits when the port is taken
        raise GalleryError(f"cannot listen on {host}:{port}: {exc}") from None


def server_url(server: BaseWSGIServer) -> str:
    host = server.host
    return f"http://{f'[{host}]' if ':' in host else host}:{server.server_port}/"


# ----------------------------------------------------------------------------- CLI


WorkersOption = Annotated[
    int | None,
    typer.Option(help="Processes drawing the missing pictures (default: all cores)."),
]


def check_workers(workers: int | None) -> int | None:
    """``--workers``: 1 to 256, as for ``sample``. Raises :class:`LimitError`."""
    from surfgen.generator.formula.limits import check_count

    return None if workers is None else check_count(workers, "--workers", 1, 256)


def thumbnails_cmd(
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    force: Annotated[bool, typer.Option(help="Render again even where pictures exist.")] = False,
    where: Annotated[
        str | None, typer.Option(help="Only these shapes (see `catalogue list`).")
    ] = None,
    workers: WorkersOption = None,
) -> None:
    """Render missing thumbnails and turntables of the accepted shapes."""
    import sys

    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    with (
        open_catalogue(catalogue, must_exist=True) as cat,
        Progress(
            BarColumn(),
            MofNCompleteColumn(),
            TimeRemainingColumn(),
            disable=not sys.stderr.isatty(),
        ) as bar,
    ):
        task = bar.add_task("pictures", total=None)
        res = render_pictures(
            cat,
            force=force,
            where=where,
            progress=lambda i, n: bar.update(task, completed=i, total=n),
            workers=check_workers(workers),
        )
    for key, why in res.failed:
        typer.echo(f"{key}: {why}", err=True)
    typer.echo(
        f"rendered {res.rendered}, already there {res.skipped}, failed {len(res.failed)} "
        f"(thumbnails in {Path(catalogue) / 'thumbs'})"
    )
    if res.failed and not res.rendered and not res.skipped:
        raise GalleryError(f"no pictures could be rendered ({len(res.failed)} failed)")


def contact_sheet_cmd(
    output: Annotated[Path, typer.Option("-o", "--output", help="The sheet (PNG).")] = Path(
        "out/contact-sheet.png"
    ),
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    where: Annotated[str | None, typer.Option(help="Which shapes (see `catalogue list`).")] = None,
    sort: Annotated[str | None, typer.Option(help="FIELD or -FIELD.")] = None,
    limit: Annotated[int | None, typer.Option(help="At most this many.")] = 48,
    columns: Annotated[int, typer.Option(help="Thumbnails per row.")] = 6,
) -> None:
    """A grid of thumbnails with short keys, for a quick look or a figure."""
    with open_catalogue(catalogue, readonly=True) as cat:
        path, n = write_contact_sheet(cat, output, where, sort, limit, columns)
    typer.echo(f"wrote {path} ({n} shapes)")


def serve_cmd(
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    port: Annotated[int, typer.Option(help="Port (0: any free one).")] = 8000,
    host: Annotated[
        str, typer.Option(help="Address to bind; anything but loopback exposes the catalogue.")
    ] = "127.0.0.1",
) -> None:
    """Browse and curate the catalogue in a web browser (writes at once)."""
    from surfgen.pipelines.cli.main import echo_err

    if not 0 <= port <= 65535:
        raise GalleryError(f"--port must be 0-65535, got {port}")
    if host not in LOOPBACK:
        log.warning("serving on %s: anyone who can reach it can edit the catalogue", host)
    server = make_server(catalogue, host, port)
    compile_notice(echo_err, background=True)  # the explorer compiles in a thread
    typer.echo(f"gallery of {catalogue} at {server_url(server)} (Ctrl+C to stop)")
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        typer.echo("stopped")
    finally:
        server.server_close()


def gallery_cmd(
    output: Annotated[Path, typer.Option("-o", "--output", help="Folder to write.")],
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    where: Annotated[
        str | None, typer.Option(help="Only these shapes (see `catalogue list`).")
    ] = None,
    meshes: Annotated[bool, typer.Option(help="Copy the meshes too, for download.")] = False,
    workers: WorkersOption = None,
) -> None:
    """Write the gallery as static, read-only files to publish or share."""
    import sys

    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeRemainingColumn,
    )

    columns = (TextColumn("turntables"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
    with Progress(*columns, disable=not sys.stderr.isatty(), transient=True) as bar:
        task = bar.add_task("turntables", total=None)
        index, n = export_gallery(
            catalogue,
            output,
            where=where,
            meshes=meshes,
            workers=check_workers(workers),
            progress=lambda i, total: bar.update(task, completed=i, total=total),
        )
    typer.echo(f"wrote {index} ({n} shapes); open it in a browser")


def register(app: typer.Typer) -> None:
    """Add ``thumbnails``, ``contact-sheet``, ``serve`` and ``gallery`` to the CLI."""
    app.command("thumbnails")(thumbnails_cmd)
    app.command("contact-sheet")(contact_sheet_cmd)
    app.command("serve")(serve_cmd)
    app.command("gallery")(gallery_cmd)
