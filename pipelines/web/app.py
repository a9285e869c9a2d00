"""The live gallery (``surfgen serve``): a Flask app over one catalogue, with a JSON API whose
writes all go through :func:`surfgen.pipelines.catalogue.curation.apply_action`, so every click
is committed at once. The viewer's routes come from :mod:`surfgen.pipelines.web.viewer`.

JSON API of the live gallery:

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
import re
import zipfile
from contextlib import ExitStack
from pathlib import Path
from threading import Thread
from typing import Any

from flask import Flask, Response, abort, g, jsonify, request, send_from_directory
from werkzeug.serving import BaseWSGIServer
from werkzeug.serving import make_server as werkzeug_server

from surfgen.generator.errors import SurfgenError
from surfgen.pipelines.catalogue.curation import (
    MAX_NOTE,
    MAX_REASON,
    MAX_STARS,
    MAX_TAGS,
    CurationError,
    apply_action,
    get_shape,
    select_shapes,
)
from surfgen.pipelines.catalogue.query import WhereError
from surfgen.pipelines.catalogue.store import (
    Catalogue,
    CatalogueError,
    CorruptCatalogue,
    now,
    open_catalogue,
)
from surfgen.pipelines.pictures.thumbnails import GalleryError, ensure_turntable
from surfgen.pipelines.studies.explore import warm_up
from surfgen.pipelines.web.api import (
    Param,
    install,
    json_body,
    key_list,
    query_flag,
    query_int,
    query_str,
)
from surfgen.pipelines.web.pages import static_dir
from surfgen.pipelines.web.site import gallery_data, render_page
from surfgen.pipelines.web.viewer import viewer_blueprint

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


def turntable_url(rec: dict[str, Any]) -> dict[str, Any]:
    """``rec`` (a :func:`~surfgen.pipelines.catalogue.curation.shape_record`) with ``turntable`` set to
    where the live gallery serves it, rendered or not: an accepted shape with a mesh always
    has one (the image route renders it on first request, :func:`ensure_turntable`)."""
    if rec.get("mesh") and not rec.get("turntable") and rec.get("verdict") == "accepted":
        rec["turntable"] = f"turntables/{rec['key']}.png"
    return rec


def create_app(root: Path, host: str = "127.0.0.1") -> Flask:
    """The live gallery over the catalogue at ``root`` (which must exist).

    Each request opens its own connection (SQLite connections are per thread). Raises
    :class:`CatalogueError` if there is no catalogue at ``root``.
    """
    root = Path(root).resolve()
    with open_catalogue(root, readonly=True) as first:  # identify it, and refuse a damaged one
        problem = first.conn.execute("PRAGMA quick_check").fetchone()[0]
    if problem != "ok":
        raise CorruptCatalogue(
            f"catalogue {root} is corrupted ({problem}): run `surfgen catalogue check -C {root}`"
        )
    app = Flask(__name__, static_folder=str(static_dir()), static_url_path="/static")
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
    app = create_app(root, host)
    Thread(target=warm_up, name="explore-warm-up", daemon=True).start()  # first slider step
    try:
        return werkzeug_server(host, port, app, threaded=True)
    except (OSError, SystemExit) as exc:  # werkzeug exits when the port is taken
        raise GalleryError(f"cannot listen on {host}:{port}: {exc}") from None


def server_url(server: BaseWSGIServer) -> str:
    """``http://HOST:PORT/`` of a running server (an IPv6 host in brackets)."""
    host = server.host
    return f"http://{f'[{host}]' if ':' in host else host}:{server.server_port}/"
