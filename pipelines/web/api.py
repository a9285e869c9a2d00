"""Validation at the web API's boundary: request bodies, query parameters and error replies.

One place for every route of the live gallery (and any module that adds routes to it):

- :func:`install` caps the body size and turns every error into ``{"error": "..."}`` with a
  4xx status (a corrupted catalogue is 503): a bad request never becomes an HTTP 500;
- :func:`json_body` checks the content type, size, nesting and JSON types of a body against a
  small schema of :class:`Param` (``int``, ``str``, ``tags``...), with one message naming the
  field, the value and what is allowed;
- :func:`query_int`, :func:`query_str`, :func:`query_flag` do the same for query strings;
- :func:`key_list` de-duplicates and caps a list of shape keys (e.g. an export form).

Nothing here touches the catalogue: the library (``apply_action``, ``select_shapes``) still
validates the meaning of each value.
"""

from __future__ import annotations

import json
import logging
import math
import sqlite3
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from flask import Flask, jsonify, request
from werkzeug.exceptions import HTTPException

from surfgen.generator.errors import SurfgenError
from surfgen.generator.formula.limits import MAX_JSON_DEPTH, json_depth_ok
from surfgen.pipelines.catalogue.store import sqlite_error

log = logging.getLogger(__name__)

MAX_BODY_BYTES = 256 * 1024  # a JSON action or an export form; more is refused with 413
MAX_KEYS = 500  # shapes in one export
MAX_QUERY_TEXT = 4_000  # characters of a query-string value (where, sort, ...)


class ApiError(SurfgenError):
    """A request the API refuses: ``status`` is the HTTP status of the reply."""

    def __init__(self, message: str, status: int = 400) -> None:
        super().__init__(message)
        self.status = status


@dataclass(frozen=True)
class Param:
    """One field of a JSON body: ``kind`` is ``int``, ``number``, ``str``, ``bool``, ``tags``
    (a text or a list of texts) or ``any``; ``low``/``high`` bound an int or number,
    ``max_length`` a text (each text of ``tags``), ``max_items`` a list; ``required`` fields
    must be present; ``nullable`` allows ``null``."""

    kind: str
    required: bool = False
    nullable: bool = True
    low: float | None = None
    high: float | None = None
    max_length: int = 10_000
    max_items: int = 100


def _shown(value: Any) -> str:
    text = json.dumps(value, default=str)
    return text if len(text) <= 60 else text[:57] + "..."


def check_param(name: str, value: Any, p: Param) -> Any:
    """``value`` if it fits ``p``; :class:`ApiError` (400) naming the field otherwise."""

    def bad(allowed: str) -> ApiError:
        return ApiError(f"'{name}' must be {allowed}, got {_shown(value)}")

    if value is None:
        if p.nullable:
            return None
        raise bad(f"given ({_describe(p)})")
    if p.kind == "any":
        return value
    if p.kind == "bool":
        if not isinstance(value, bool):
            raise bad("true or false")
        return value
    if p.kind in ("int", "number"):
        whole = p.kind == "int"
        ok = isinstance(value, int) if whole else isinstance(value, int | float)
        if not ok or isinstance(value, bool) or not math.isfinite(value):
            raise bad(_describe(p))
        if (p.low is not None and value < p.low) or (p.high is not None and value > p.high):
            raise bad(_describe(p))
        return value
    if p.kind == "str":
        if not isinstance(value, str):
            raise bad(_describe(p))
        if len(value) > p.max_length:
            raise ApiError(
                f"'{name}' is too long: {len(value)} characters (at most {p.max_length})"
            )
        return value
    if p.kind == "tags":
        items = [value] if isinstance(value, str) else value
        if not isinstance(items, list) or not all(isinstance(t, str) for t in items):
            raise bad(_describe(p))
        if len(items) > p.max_items:
            raise ApiError(f"'{name}' has {len(items)} items (at most {p.max_items})")
        if any(len(t) > p.max_length for t in items):
            raise ApiError(f"'{name}': each item is at most {p.max_length} characters")
        return items
    raise ValueError(f"unknown parameter kind {p.kind!r}")  # pragma: no cover - a bug here


def _describe(p: Param) -> str:
    if p.kind in ("int", "number"):
        what = "a whole number" if p.kind == "int" else "a number"
        if p.low is not None and p.high is not None:
            what += f" from {p.low:g} to {p.high:g}"
        elif p.low is not None:
            what += f" >= {p.low:g}"
        return what
    if p.kind == "str":
        return f"text (at most {p.max_length} characters)"
    if p.kind == "tags":
        return f"a text or a list of at most {p.max_items} texts"
    return p.kind


def json_body(schema: Mapping[str, Param], allow_unknown: bool = False) -> dict[str, Any]:
    """The current request's JSON object body, checked against ``schema``.

    Raises :class:`ApiError`: 415 if it is not ``application/json``, 413 if larger than
    :data:`MAX_BODY_BYTES`, 400 for bad JSON, nesting deeper than :data:`MAX_JSON_DEPTH`,
    a body that is not an object, an unknown field (unless ``allow_unknown``) or a bad value.
    """
    if not request.is_json:
        raise ApiError("send the action as application/json", 415)
    length = request.content_length
    if length is not None and length > MAX_BODY_BYTES:
        raise ApiError(f"the body is larger than {MAX_BODY_BYTES} bytes", 413)
    raw = request.get_data(cache=True)
    if len(raw) > MAX_BODY_BYTES:
        raise ApiError(f"the body is larger than {MAX_BODY_BYTES} bytes", 413)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ApiError("the body is not UTF-8") from None
    if not json_depth_ok(text):
        raise ApiError(f"the body nests more than {MAX_JSON_DEPTH} levels")
    try:
        body = json.loads(text, parse_constant=_no_constant) if text.strip() else None
    except (json.JSONDecodeError, ValueError):
        raise ApiError("the body is not valid JSON") from None
    if not isinstance(body, dict):
        raise ApiError("the body must be a JSON object")
    unknown = sorted(set(body) - set(schema))
    if unknown and not allow_unknown:
        allowed = ", ".join(schema) or "none"
        raise ApiError(f"unknown field '{unknown[0][:40]}' (allowed: {allowed})")
    out: dict[str, Any] = {}
    for name, p in schema.items():
        if name not in body:
            if p.required:
                raise ApiError(f"'{name}' is missing")
            continue
        out[name] = check_param(name, body[name], p)
    return out


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not JSON")


def query_str(name: str, max_length: int = MAX_QUERY_TEXT) -> str | None:
    """A query-string value (None if absent); :class:`ApiError` when longer than allowed."""
    value = request.args.get(name)
    if value is not None and len(value) > max_length:
        raise ApiError(f"'{name}' is too long: {len(value)} characters (at most {max_length})")
    return value


def query_int(name: str, low: int, high: int) -> int | None:
    """A whole-number query parameter in [low, high] (None if absent or empty)."""
    value = query_str(name)
    if value is None or value == "":
        return None
    try:
        number = int(value) if len(value) <= 30 else None
    except ValueError:
        number = None
    if number is None or not low <= number <= high:
        raise ApiError(f"'{name}' must be a whole number from {low} to {high}, got {value[:30]!r}")
    return number


def query_flag(name: str) -> bool:
    """``1``/``true``/``yes`` → True; absent, ``0``... → False; anything else is refused."""
    value = query_str(name, 10)
    if value is None or value.lower() in ("", "0", "false", "no"):
        return False
    if value.lower() in ("1", "true", "yes"):
        return True
    raise ApiError(f"'{name}' must be 1 or 0, got {value!r}")


def key_list(values: list[str], max_keys: int = MAX_KEYS) -> list[str]:
    """Comma-separated shape keys from one or more form values: stripped, de-duplicated in
    order, each hex digits of at most 16, at most ``max_keys``. Raises :class:`ApiError`."""
    keys: dict[str, None] = {}
    for value in values:
        for part in value.split(","):
            k = part.strip().lower()
            if not k:
                continue
            if len(k) > 16 or any(c not in "0123456789abcdef" for c in k):
                raise ApiError(f"'{k[:20]}' is not a shape key (1-16 hex digits)")
            keys[k] = None
            if len(keys) > max_keys:
                raise ApiError(f"at most {max_keys} shapes per export")
    return list(keys)


def install(app: Flask) -> None:
    """Cap request bodies and reply to every error with ``{"error": ...}`` and a 4xx/503
    status: validation errors are 400 (or the status they carry), a corrupted or busy
    catalogue 503, anything unforeseen is logged with its traceback and answered 500 JSON."""
    app.config["MAX_CONTENT_LENGTH"] = MAX_BODY_BYTES
    app.config["MAX_FORM_MEMORY_SIZE"] = MAX_BODY_BYTES
    app.config["MAX_FORM_PARTS"] = 100

    @app.errorhandler(ApiError)
    def _api_error(exc: ApiError):
        return jsonify(error=str(exc)), exc.status

    @app.errorhandler(HTTPException)
    def _http_error(exc: HTTPException):
        return jsonify(error=exc.description or exc.name), exc.code or 500

    @app.errorhandler(sqlite3.Error)
    def _database_error(exc: sqlite3.Error):
        return jsonify(error=str(sqlite_error(exc, "the catalogue database"))), 503
