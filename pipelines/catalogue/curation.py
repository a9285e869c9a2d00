"""Curation of the catalogue: query it, star, reject, tag and annotate shapes, mark near duplicates.

- :func:`select_shapes` runs a query (``--where`` and ``--sort``, :mod:`surfgen.pipelines.catalogue.query`)
  and returns JSON-ready records (:func:`shape_record`).
- :func:`apply_action` is the one function that writes a curation change (star, reject,
  unreject, tag, untag, note): it validates, writes, logs the action in the ``curation`` table
  and commits at once. The CLI and the web gallery both go through it.
- :func:`dedupe_catalogue` computes the shape descriptors (:mod:`surfgen.filters.descriptor`)
  and marks each accepted shape that nearly copies an earlier one with that shape's key.
"""

from __future__ import annotations

import json
import logging
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from surfgen.generator.errors import MeshError
from surfgen.generator.formula.limits import MAX_COUNT, MAX_STARS
from surfgen.pipelines.catalogue.query import WhereError, parse_sort, parse_where
from surfgen.pipelines.catalogue.store import (
    Catalogue,
    CatalogueError,
    now,
)

log = logging.getLogger(__name__)

MAX_REASON = 1_000  # characters of a curator's reject reason
MAX_NOTE = 10_000  # characters of a note
MAX_TAGS = 50  # tags given in one action
_TAG = re.compile(r"^[a-z0-9][a-z0-9_.\-]{0,39}$")


class CurationError(CatalogueError):
    """A curation action that cannot be applied (bad tag, star count, empty reason...)."""


# ----------------------------------------------------------------------------- reading


def _loads(text: str | None, default: Any) -> Any:
    if not text:
        return default
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return default


def _family(model: str | None) -> str:
    """The sampler family in a model's JSON (shapes from before families are ``free``)."""
    data = _loads(model, None)
    return str(data.get("family", "free")) if isinstance(data, dict) else "free"


def shape_record(
    row: dict[str, Any], tags: Sequence[str] = (), full: bool = False
) -> dict[str, Any]:
    """A JSON-ready view of a ``shapes`` row: JSON columns decoded, file paths relative to the
    catalogue root. ``full`` adds the model, timings and error."""
    spec = _loads(row.get("spec"), {})
    rec = {
        "key": row["key"],
        "run": row["run"],
        "index": row["idx"],
        "formula": row["formula"],
        "spec": spec,
        "provenance": spec.get("provenance", {}),
        "identity": row.get("identity"),
        "d": row.get("d"),
        "verdict": row["verdict"],
        "reasons": _loads(row.get("reasons"), []),
        "metrics": _loads(row.get("metrics"), {}),
        **{
            k: row.get(k)
            for k in ("faces", "vertices", "components", "genus", "euler", "area", "volume")
        },
        "stars": row.get("stars") or 0,
        "rejected": row.get("user_rejected"),
        "note": row.get("note"),
        "duplicate_of": row.get("duplicate_of"),
        "family": _family(row.get("model")),
        "tags": list(tags),
        "mesh": row.get("mesh_path"),
        "thumb": row.get("thumb_path"),
        "turntable": row.get("turntable_path"),
    }
    if full:
        rec["model"] = _loads(row.get("model"), None)
        rec["timings"] = _loads(row.get("timings"), {})
        rec["error"] = row.get("error")
    return rec


def tags_of(cat: Catalogue, keys: Iterable[str] | None = None) -> dict[str, list[str]]:
    """Tags of every shape (or of ``keys``), sorted: ``{key: [tag, ...]}``."""
    out: dict[str, list[str]] = {}
    wanted = None if keys is None else set(keys)
    for r in cat.conn.execute("SELECT key, tag FROM tags ORDER BY key, tag"):
        if wanted is None or r["key"] in wanted:
            out.setdefault(r["key"], []).append(r["tag"])
    return out


def select_shapes(
    cat: Catalogue,
    where: str | None = None,
    sort: str | None = None,
    limit: int | None = None,
    everything: bool = False,
    full: bool = False,
) -> list[dict[str, Any]]:
    """Records of the shapes matching ``where``, ordered by ``sort``, at most ``limit``.

    Only shapes the filters accepted, unless ``everything`` or ``where`` mentions ``verdict`` or
    ``reason``. Raises :class:`WhereError` for a bad expression.
    """
    cond = parse_where(where)
    order = parse_sort(sort)
    if limit is not None and not 0 <= limit <= MAX_COUNT:
        raise WhereError(f"--limit must be a whole number from 0 to 2^63-1, got {limit}")
    scope = "1" if everything or cond.fields & {"verdict", "reason"} else "verdict = 'accepted'"
    q = f"SELECT shapes.* FROM shapes WHERE {scope} AND {cond.sql} ORDER BY {order}"
    params = list(cond.params)
    if limit is not None:
        q += " LIMIT ?"
        params.append(limit)
    rows = [dict(r) for r in cat.conn.execute(q, params)]
    tags = tags_of(cat, (r["key"] for r in rows)) if rows else {}
    return [shape_record(r, tags.get(r["key"], []), full=full) for r in rows]


def get_shape(cat: Catalogue, key_or_prefix: str, full: bool = True) -> dict[str, Any]:
    """The record of one shape, with its run and curation history. Raises :class:`CatalogueError`."""
    row = cat.shape(key_or_prefix)
    rec = shape_record(row, row["tags"], full=full)
    if full:
        run = cat.conn.execute("SELECT * FROM runs WHERE id=?", (row["run"],)).fetchone()
        if run is not None:
            rec["run_info"] = {
                "seed": run["seed"],
                "grid": run["grid"],
                "config_hash": run["config_hash"],
                "sampler_version": run["sampler_version"],
                "versions": _loads(run["versions"], {}),
                "started": run["started"],
                "status": run["status"],
            }
        rec["history"] = [
            dict(r)
            for r in cat.conn.execute(
                "SELECT at, action, value FROM curation WHERE key=? ORDER BY id", (rec["key"],)
            )
        ]
    return rec


# ----------------------------------------------------------------------------- writing

ACTIONS = ("star", "reject", "unreject", "tag", "untag", "note", "derive")


def normalise_tags(tags: Iterable[str]) -> list[str]:
    """Lower-cased, stripped, de-duplicated tags. Raises :class:`CurationError` for a bad one."""
    out: list[str] = []
    for t in tags:
        tag = str(t).strip().lower()
        if not _TAG.match(tag):
            raise CurationError(
                f"bad tag '{str(t)[:40]}': 1-40 characters a-z 0-9 _ . -, starting with a letter or digit"
            )
        if tag not in out:
            out.append(tag)
    if not out:
        raise CurationError("give at least one tag")
    return out


def apply_action(
    cat: Catalogue, key_or_prefix: str, action: str, value: Any = None
) -> dict[str, Any]:
    """Apply one curation ``action`` to a shape and commit at once; returns its new record.

    ``star``: value 0-5 (None: 1); ``reject``: value is the reason (required); ``unreject``;
    ``tag``/``untag``: value is a list of tags; ``note``: value is the text ('' clears);
    ``derive``: value is the catalogue row of a variant of the shape, inserted as a new shape.
    Raises :class:`CatalogueError` for an unknown key and :class:`CurationError` for a bad value.
    """
    key = cat.resolve(key_or_prefix)
    sql, params, logged = _action_sql(key, action, value)
    with cat.conn:  # one transaction: the change and its log line
        for statement, args in zip(sql, params, strict=True):
            cat.conn.execute(statement, args)
        cat.conn.execute(
            "INSERT INTO curation (key, at, action, value) VALUES (?,?,?,?)",
            (key, now(), action, logged),
        )
    log.info("%s %s %s", action, key, logged)
    return get_shape(cat, key, full=False)


def _action_sql(key: str, action: str, value: Any) -> tuple[list[str], list[tuple], str | None]:
    """Validated SQL statements for one action, their parameters and the value to log."""
    if action == "star":
        stars = 1 if value is None else value
        if isinstance(stars, bool) or not isinstance(stars, int | str):
            raise CurationError(f"stars must be a whole number 0-{MAX_STARS}, got {value!r}")
        try:
            stars = int(stars)
        except ValueError:
            raise CurationError(
                f"stars must be a whole number 0-{MAX_STARS}, got {value!r}"
            ) from None
        if not 0 <= stars <= MAX_STARS:
            raise CurationError(f"stars must be from 0 to {MAX_STARS}, got {stars}")
        return ["UPDATE shapes SET stars=? WHERE key=?"], [(stars, key)], str(stars)
    if action == "reject":
        if value is not None and not isinstance(value, str):
            raise CurationError(f"the reason must be text, got {type(value).__name__}")
        why = (value or "").strip()
        if not why:
            raise CurationError("say why the shape is rejected (--why TEXT)")
        if len(why) > MAX_REASON:
            raise CurationError(f"the reason is {len(why)} characters (at most {MAX_REASON})")
        return ["UPDATE shapes SET user_rejected=? WHERE key=?"], [(why, key)], why
    if action == "unreject":
        return ["UPDATE shapes SET user_rejected=NULL WHERE key=?"], [(key,)], None
    if action in ("tag", "untag"):
        items = [value] if isinstance(value, str) else value
        if not isinstance(items, list | tuple) or not all(isinstance(t, str) for t in items):
            raise CurationError(f"tags must be a text or a list of texts, got {value!r:.60}")
        if len(items) > MAX_TAGS:
            raise CurationError(f"at most {MAX_TAGS} tags at once, got {len(items)}")
        tags = normalise_tags(items)
        stmt = (
            "INSERT OR IGNORE INTO tags (key, tag) VALUES (?, ?)"
            if action == "tag"
            else "DELETE FROM tags WHERE key=? AND tag=?"
        )
        return [stmt] * len(tags), [(key, t) for t in tags], " ".join(tags)
    if action == "note":
        if value is not None and not isinstance(value, str):
            raise CurationError(f"the note must be text, got {type(value).__name__}")
        text = (value or "").strip()
        if len(text) > MAX_NOTE:
            raise CurationError(f"the note is {len(text)} characters (at most {MAX_NOTE})")
        return ["UPDATE shapes SET note=? WHERE key=?"], [(text or None, key)], text
    if action == "derive":  # value: the row of a variant of `key` (studies/explore.py)
        return derive_sql(value, now())
    raise CurationError(f"unknown action '{action}' (actions: {', '.join(ACTIONS)})")


DERIVED_RUN = "derived"  # config_hash of the catalogue's run that holds saved variants
_DERIVED_RUN_SQL = (
    "INSERT OR IGNORE INTO runs (seed, n, grid, config, config_hash, sampler_version, versions,"
    " started, status) VALUES (0, 0, 0, '{}', ?, 0, '{}', ?, 'derived')"
)
_ROW_COLUMNS = (
    "key", "spec", "formula", "identity", "d", "verdict", "reasons", "metrics", "faces",
    "vertices", "components", "genus", "euler", "area", "volume", "mesh_path", "thumb_path",
    "turntable_path",
)  # fmt: skip


def derive_sql(row: Any, at: str) -> tuple[list[str], list[tuple], str]:
    """SQL for the ``derive`` action (a variant saved by :mod:`surfgen.pipelines.studies.explore`):
    make sure the catalogue has its run of saved variants (config_hash :data:`DERIVED_RUN`),
    insert ``row`` as its next shape and count it. Returns statements, their parameters and the
    value to log (the new key). Raises :class:`CurationError` for an incomplete row."""
    if not isinstance(row, dict) or set(row) != set(_ROW_COLUMNS):
        raise CurationError("derive: the new shape's row is incomplete")
    run = "(SELECT id FROM runs WHERE config_hash=? AND status='derived')"
    cols = ["run", "idx", *_ROW_COLUMNS]
    marks = ",".join(["?"] * len(_ROW_COLUMNS))
    insert = (
        f"INSERT INTO shapes ({','.join(cols)}) VALUES ({run}, "
        f"(SELECT next_index FROM runs WHERE id={run}), {marks})"
    )
    bump = f"UPDATE runs SET next_index=next_index+1, accepted=accepted+1, n=n+1 WHERE id={run}"
    values = tuple(row[c] for c in _ROW_COLUMNS)
    return (
        [_DERIVED_RUN_SQL, insert, bump],
        [(DERIVED_RUN, at), (DERIVED_RUN, DERIVED_RUN, *values), (DERIVED_RUN,)],
        str(row["key"]),
    )


# ----------------------------------------------------------------------------- de-duplication


@dataclass(frozen=True)
class DedupeResult:
    """What :func:`dedupe_catalogue` found: ``marked`` is ``(key, duplicate_of, distance)``."""

    checked: int
    computed: int
    marked: list[tuple[str, str, float]]
    missing: list[str]


def ensure_descriptors(
    cat: Catalogue, progress: Callable[[int, int], None] | None = None
) -> tuple[dict[str, np.ndarray], int, list[str]]:
    """Descriptors of every accepted shape in (run, index) order, computing and storing the
    missing ones from their meshes. Returns ``({key: descriptor}, computed, keys without mesh)``."""
    from surfgen.filters.descriptor import descriptor, descriptor_from_text, descriptor_to_text
    from surfgen.generator.mesh.exchange import load_mesh

    rows = cat.conn.execute(
        "SELECT key, mesh_path, descriptor FROM shapes WHERE verdict='accepted' ORDER BY run, idx"
    ).fetchall()
    out: dict[str, np.ndarray] = {}
    computed, missing = 0, []
    for i, r in enumerate(rows):
        d = descriptor_from_text(r["descriptor"])
        if d is None:
            try:
                if not r["mesh_path"]:
                    raise MeshError("no mesh file recorded")
                d = descriptor(load_mesh(cat.root / r["mesh_path"]))
            except MeshError as exc:
                log.warning("shape %s: no descriptor (%s)", r["key"], exc)
                missing.append(r["key"])
                continue
            with cat.conn:
                cat.conn.execute(
                    "UPDATE shapes SET descriptor=? WHERE key=?", (descriptor_to_text(d), r["key"])
                )
            computed += 1
        out[r["key"]] = d
        if progress is not None:
            progress(i + 1, len(rows))
    return out, computed, missing


def find_near_duplicates(
    descriptors: dict[str, np.ndarray], threshold: float
) -> list[tuple[str, str, float]]:
    """Greedy, in the dict's order: each shape closer than ``threshold`` to an earlier original
    is a duplicate of the nearest one. Returns ``(key, original key, distance)``."""
    from surfgen.filters.descriptor import DescriptorSet

    originals = DescriptorSet()  # the distances of descriptor_distances, split once per shape
    marked = []
    for key, d in descriptors.items():
        nearest, dist = originals.nearest(d)
        if nearest is not None and dist < threshold:
            marked.append((key, nearest, dist))
            continue
        originals.add(key, d)
    return marked


def dedupe_catalogue(
    cat: Catalogue,
    threshold: float | None = None,
    dry_run: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> DedupeResult:
    """Mark near duplicates among the accepted shapes: each gets ``duplicate_of`` = the key of the
    earliest (by run, index) shape it copies. Earlier marks on accepted shapes are recomputed, so
    a new threshold takes effect; exact duplicates rejected while sampling are left alone.
    Raises :class:`CurationError` for a threshold outside (0, 100] (the distance is in units of
    the descriptor's calibrated scales: 1 is the default)."""
    from surfgen.filters.descriptor import DEFAULT_THRESHOLD

    threshold = DEFAULT_THRESHOLD if threshold is None else float(threshold)
    if not 0.0 < threshold <= 100.0:
        raise CurationError(f"--threshold must be in (0, 100], got {threshold}")
    descriptors, computed, missing = ensure_descriptors(cat, progress)
    marked = find_near_duplicates(descriptors, threshold)
    if not dry_run:
        with cat.conn:
            cat.conn.execute("UPDATE shapes SET duplicate_of=NULL WHERE verdict='accepted'")
            cat.conn.executemany(
                "UPDATE shapes SET duplicate_of=? WHERE key=?", [(of, k) for k, of, _ in marked]
            )
    log.info(
        "dedupe: %d shapes, %d near duplicates (threshold %g)",
        len(descriptors),
        len(marked),
        threshold,
    )
    return DedupeResult(len(descriptors), computed, marked, missing)
