"""The 3-D viewer: a shape's detail page with a WebGL view and explore sliders.

:func:`viewer_blueprint` adds these routes to the live gallery (``surfgen serve``):

====== ================================ =========================================================
GET    /shape/KEY                       detail page: WebGL view, statistics, sliders, curation
GET    /explore?preset=NAME|formula=F   the same page for a preset or a pasted formula
GET    /api/shape/KEY/mesh.glb          the catalogued mesh as binary glTF
POST   /api/explore                     ``{"formula", "params", "box", "grid"}`` or ``{"key",
                                        "changes"}`` (or ``{"preset", "changes"}``) →
                                        ``{"faces", "seconds", "formula", "mesh", ...}``
GET    /api/explore/mesh/TOKEN.glb      the GLB of a recent explore step
GET    /api/explore/stats/TOKEN         its topology: components, Euler characteristic, genus
POST   /api/explore/save                ``{"key", "changes"}``: catalogue the variant
====== ================================ =========================================================

:func:`export_detail_pages` writes the same pages for the static gallery (``surfgen gallery
--meshes``): ``shapes/KEY.html`` and each mesh beside it as ``shapes/KEY.glb.js``, a classic script holding
the GLB in base64, because a page opened from disk (file://) may load scripts but not fetch files.
Three.js comes from ``static/vendor/three`` (npm 0.180.0, bundled as one classic script).
"""

from __future__ import annotations

import base64
import hashlib
import json
import logging
import shutil
from collections import OrderedDict
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from threading import Lock
from typing import Any

from flask import Blueprint, Response, abort, jsonify, request

from surfgen.generator.errors import SurfgenError
from surfgen.generator.files import write_atomic
from surfgen.generator.formula.expr import VARIABLES
from surfgen.generator.formula.functions import FUNCTIONS, MACROS
from surfgen.generator.formula.parser import tokenize
from surfgen.generator.model.presets import PRESETS, get_preset
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.curation import get_shape, select_shapes
from surfgen.pipelines.catalogue.store import Catalogue, CatalogueError
from surfgen.pipelines.studies.explore import (
    Explored,
    explore,
    mesh_stats,
    save_variant,
    spec_from_request,
)
from surfgen.pipelines.studies.knobs import ExploreError, knobs_of
from surfgen.pipelines.web.pages import script_json, templates, write_page

log = logging.getLogger(__name__)

MAX_BODY = 64 * 1024  # bytes of an explore request
GLB_CACHE = 24  # recent explore meshes kept for their URL
VENDOR = ("three-viewer.min.js", "LICENSE", "VERSION")


def neighbours(cat: Catalogue, key: str) -> tuple[str | None, str | None]:
    """The previous and next shape of the gallery's default order (run, index; curator-rejected
    shapes left out), wrapping around."""
    keys = [r["key"] for r in select_shapes(cat, where="not rejected")]
    if key not in keys:
        keys.append(key)
    i = keys.index(key)
    if len(keys) < 2:
        return None, None
    return keys[i - 1], keys[(i + 1) % len(keys)]


def page_data(
    rec: dict[str, Any] | None,
    spec: SurfaceSpec,
    *,
    mode: str,
    cap: bool = True,
    prev: str | None = None,
    next_: str | None = None,
    source: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """What the detail page script reads: the shape record (None for a preset or formula), the
    spec, its sliders, neighbours, and ``mode`` (``live`` or ``static``)."""
    return {
        "mode": mode,
        "shape": rec,
        "spec": spec.to_dict(),
        "cap": cap,
        "knobs": [k.to_dict() for k in knobs_of(spec)],
        "prev": prev,
        "next": next_,
        "source": source or ({"key": rec["key"]} if rec else {}),
        "presets": sorted(PRESETS) if mode == "live" else [],
    }


def render_shape_page(data: dict[str, Any], title: str) -> str:
    """The detail page's HTML for ``data`` (from :func:`page_data`)."""
    return (
        templates()
        .get_template("shape.html")
        .render(title=title, live=data["mode"] == "live", data_json=script_json(data), data=data)
    )


def free_names(formula: str) -> list[str]:
    """Names in a pasted formula that are neither x, y, z, pi nor functions: its parameters
    (the explore page binds them to 1 and gives each a slider, as MathMod's ``Sliders``)."""
    tokens = tokenize(formula)
    out: list[str] = []
    for t, after in zip(tokens, [*tokens[1:], None], strict=True):
        called = after is not None and after.text == "("
        known = t.text in VARIABLES or t.text == "pi" or t.text in FUNCTIONS or t.text in MACROS
        if t.kind == "name" and not called and not known and t.text not in out:
            out.append(t.text)
    return out[:16]


class StepCache:
    """The last :data:`GLB_CACHE` explore steps (:class:`Explored`: GLB and mesh), by token
    (thread-safe)."""

    def __init__(self, size: int = GLB_CACHE) -> None:
        self.size = size
        self.items: OrderedDict[str, Explored] = OrderedDict()
        self.lock = Lock()

    def put(self, token: str, data: Explored) -> None:
        with self.lock:
            self.items[token] = data
            self.items.move_to_end(token)
            while len(self.items) > self.size:
                self.items.popitem(last=False)

    def get(self, token: str) -> Explored | None:
        with self.lock:
            return self.items.get(token)


def viewer_blueprint(root: Path, cat: Callable[[], Catalogue]) -> Blueprint:
    """The viewer's routes over the catalogue at ``root``; ``cat()`` gives the request's
    catalogue connection (the gallery app's)."""
    bp = Blueprint("viewer", __name__)
    cache = StepCache()

    def glb_response(data: bytes) -> Response:
        return Response(data, mimetype="model/gltf-binary", headers={"Cache-Control": "no-store"})

    @bp.get("/shape/<key>")
    def shape_page(key: str) -> Response:
        c = cat()
        rec = get_shape(c, key)
        spec = SurfaceSpec.from_dict(rec["spec"])
        prev, nxt = neighbours(c, rec["key"])
        data = page_data(rec, spec, mode="live", prev=prev, next_=nxt)
        return Response(render_shape_page(data, f"surfgen {rec['key'][:8]}"), mimetype="text/html")

    @bp.get("/explore")
    def explore_page() -> Response:
        formula = request.args.get("formula")
        name = request.args.get("preset") or ("eqC" if not formula else None)
        try:
            if formula:
                params = {name: 1.0 for name in free_names(formula)}
                spec, cap, _ = spec_from_request({"formula": formula, "params": params})
                source: dict[str, Any] = {
                    "formula": spec.formula,
                    "params": dict(spec.params),
                    "box": list(spec.box),
                    "grid": list(spec.grid),
                }
            else:
                preset = get_preset(str(name))
                spec, cap, source = preset.spec(), preset.cap, {"preset": preset.name}
        except SurfgenError as exc:
            return jsonify(error=str(exc)), 400  # type: ignore[return-value]
        data = page_data(None, spec, mode="live", cap=cap, source=source)
        return Response(render_shape_page(data, "surfgen explore"), mimetype="text/html")

    @bp.get("/api/shape/<key>/mesh.glb")
    def shape_mesh(key: str) -> Response:
        # deferred: see export_detail_pages
        from surfgen.generator.mesh.exchange import glb_bytes, load_mesh

        rec = get_shape(cat(), key, full=False)
        if not rec["mesh"]:
            abort(404)
        try:
            mesh = load_mesh(root / rec["mesh"])
        except SurfgenError as exc:
            return jsonify(error=str(exc)), 404  # type: ignore[return-value]
        return glb_response(glb_bytes(mesh, web=True))

    def body_json() -> Any:
        if not request.is_json:
            return None
        if (request.content_length or 0) > MAX_BODY:
            raise ExploreError(f"the request body is over {MAX_BODY} bytes")
        data = request.stream.read(MAX_BODY + 1)  # never more, whatever the headers say
        if len(data) > MAX_BODY:
            raise ExploreError(f"the request body is over {MAX_BODY} bytes")
        try:
            return json.loads(data)
        except (ValueError, UnicodeDecodeError):
            raise ExploreError("the body is not valid JSON") from None

    def catalogue_spec(key: str) -> tuple[str, SurfaceSpec]:
        c = cat()
        full = c.resolve(key)
        return full, c.spec(full)

    @bp.post("/api/explore")
    def explore_api():
        body = body_json()
        if body is None:
            return jsonify(error="send the request as application/json"), 415
        spec, cap, _ = spec_from_request(body, catalogue_spec)
        step = explore(spec, cap=cap, topology=False)  # topology: GET .../stats/TOKEN
        token = hashlib.sha256(f"{spec.to_json()}|{cap}".encode()).hexdigest()[:20]
        cache.put(token, step)
        seconds = sum(step.seconds[k] for k in ("evaluate", "mesh", "glb"))
        return jsonify(
            faces=step.faces,
            seconds=round(seconds, 4),
            formula=spec.formula,
            mesh=f"api/explore/mesh/{token}.glb",
            topology=f"api/explore/stats/{token}",
            params=dict(spec.params),
            box=list(spec.box),
            grid=list(spec.grid),
            level=spec.level,
            stats=step.stats,
            empty=step.empty,
            timings={k: round(v, 4) for k, v in step.seconds.items()},
        )

    @bp.get("/api/explore/mesh/<token>.glb")
    def explore_mesh(token: str) -> Response:
        step = cache.get(token)
        if step is None:
            abort(404)
        return glb_response(step.glb)

    @bp.get("/api/explore/stats/<token>")
    def explore_stats(token: str):
        step = cache.get(token)
        if step is None:
            abort(404)
        return jsonify(stats=mesh_stats(step.mesh) | {"nonfinite": step.stats["nonfinite"]})

    @bp.post("/api/explore/save")
    def save_api():
        body = body_json()
        if body is None:
            return jsonify(error="send the request as application/json"), 415
        if not isinstance(body, dict) or set(body) - {"key", "changes"} or "key" not in body:
            raise ExploreError('the body must be {"key": KEY, "changes": {...}}')
        if not isinstance(body["key"], str) or len(body["key"]) > 64:
            raise ExploreError("'key' must be a shape key (hex digits)")
        rec = save_variant(cat(), body["key"], body.get("changes", {}))
        return jsonify(shape=rec, url=f"shape/{rec['key']}")

    @bp.errorhandler(SurfgenError)
    def _error(exc: SurfgenError):
        # Unknown keys are 404 as in the gallery's API; every other known error is the client's.
        status = 404 if type(exc) is CatalogueError else 400
        return jsonify(error=str(exc)), status

    return bp


# ----------------------------------------------------------------------------- static export


def vendor_dir() -> Path:
    """The vendored three.js (``static/vendor/three``)."""
    return Path(str(resources.files("surfgen.pipelines.web").joinpath("static", "vendor", "three")))


def export_detail_pages(root: Path, out: Path, shapes: list[dict[str, Any]]) -> int:
    """Write ``shapes/KEY.html`` and ``shapes/KEY.glb.js`` for every shape of the static gallery
    that has a mesh, and the vendored three.js; returns how many pages. ``shapes`` are the
    gallery's records (their ``mesh`` paths relative to ``root``). Raises ``OSError``."""
    # Deferred on purpose: the mesh modules load trimesh and numba, which the live gallery
    # does not need to start (its warm-up thread loads them in the background).
    from surfgen.generator.mesh.exchange import glb_bytes, load_mesh

    with_mesh = [s for s in shapes if s.get("mesh")]
    if not with_mesh:
        return 0
    (out / "shapes").mkdir(parents=True, exist_ok=True)
    (out / "static" / "vendor" / "three").mkdir(parents=True, exist_ok=True)
    for name in VENDOR:
        shutil.copy2(vendor_dir() / name, out / "static" / "vendor" / "three" / name)
    keys = [s["key"] for s in with_mesh]
    for i, s in enumerate(with_mesh):
        key = s["key"]
        try:
            glb = glb_bytes(load_mesh(Path(root) / s["mesh"]), web=True)
        except SurfgenError as exc:
            log.warning("shape %s: no 3-D page (%s)", key, exc)
            continue
        script = (
            "window.SURFGEN_MESH_LOADED("
            + json.dumps(key)
            + ',"'
            + base64.b64encode(glb).decode("ascii")
            + '");\n'
        )
        write_atomic(out / "shapes" / f"{key}.glb.js", script.encode("ascii"))
        spec = SurfaceSpec.from_dict(s["spec"])
        prev, nxt = (keys[i - 1], keys[(i + 1) % len(keys)]) if len(keys) > 1 else (None, None)
        data = page_data(s, spec, mode="static", prev=prev, next_=nxt)
        write_page(out / "shapes" / f"{key}.html", render_shape_page(data, f"surfgen {key[:8]}"))
    return len(with_mesh)


__all__ = ["export_detail_pages", "viewer_blueprint", "neighbours", "page_data"]
