"""MkDocs hook: the configuration reference, generated from the settings dataclasses.

A page holding the marker ``<!-- surfgen:config-keys -->`` gets, in its place, one table per
TOML table of the sampling config: every field of the settings dataclasses with its type, its
default and what it means. The walk is generic: it starts from the default config
(``load_config()``) and descends into every field whose value is a dataclass (or a mapping of
dataclasses), so a new table or key appears here without a change to this file. The meaning of
a key is its comment in ``default_config.toml``, else the comment beside the field in the
dataclass's source.
"""

from __future__ import annotations

import inspect
import json
import re
from collections.abc import Iterator, Mapping
from dataclasses import fields, is_dataclass
from typing import Any, get_type_hints

from surfgen.generator.model.settings import describe_type
from surfgen.pipelines.run.config import default_config_text, load_config

MARKER = "<!-- surfgen:config-keys -->"

_HEADER = re.compile(r"^\s*\[([^\[\]]+)\]\s*(#.*)?$")
_KEY = re.compile(r"^\s*([A-Za-z0-9_-]+)\s*=")
_FIELD_COMMENT = re.compile(r"^\s+(\w+)\s*:[^#]*#\s*(.+)$")


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    """MkDocs event: put the generated tables where the marker is."""
    if MARKER not in markdown:
        return markdown
    return markdown.replace(MARKER, render_config_reference())


def config_tables(obj: Any = None, path: tuple[str, ...] = ()) -> Iterator[tuple[str, Any]]:
    """``(dotted table name, settings dataclass instance)`` for every table, parents first."""
    if obj is None:
        obj = load_config()
    leaves = [f for f in fields(obj) if not _is_table(getattr(obj, f.name))]
    if path and leaves:
        yield ".".join(path), obj
    for f in fields(obj):
        value = getattr(obj, f.name)
        if is_dataclass(value):
            yield from config_tables(value, (*path, f.name))
        elif _named_tables(value):  # ((name, settings), ...): the tables [path.name]
            for name, sub in value:
                yield from config_tables(sub, (*path, str(name)))
        elif _is_table(value):
            for name, sub in value.items():
                yield from config_tables(sub, (*path, f.name, str(name)))


def config_keys(table_obj: Any) -> list[str]:
    """The keys of one table: its fields that are values, not tables."""
    return [
        f.name
        for f in fields(table_obj)
        if not _is_table(getattr(table_obj, f.name)) and f.metadata.get("config_key", True)
    ]


def render_config_reference() -> str:
    """The markdown of every table: a heading, the settings class, and a row per key."""
    comments, notes, order = _toml_comments(default_config_text())
    out: list[str] = []
    for table, obj in config_tables():
        cls = type(obj)
        out.append(f"## `[{table}]` {{ #{_anchor(table)} }}\n")
        out.append(f"Read into `{cls.__module__}.{cls.__qualname__}`.\n")
        out.append("| key | type | default | meaning |")
        out.append("| --- | --- | --- | --- |")
        hints = _hints(cls)
        source = _source_comments(cls)
        keys = config_keys(obj)
        toml_order = [k for k in order.get(table, []) if k in keys]
        for key in toml_order + [k for k in keys if k not in toml_order]:
            note = notes.get((table, key))
            if note:
                out.append(f"| **{_cell(note)}** | | | |")
            meaning = (
                comments.get((table, key))
                or source.get(key)
                or _paired_meaning(key, keys, comments, table)
            )
            kind = describe_type(hints[key]) if key in hints else ""
            default = json.dumps(_plain(getattr(obj, key)))
            out.append(
                f'| <span id="{table}.{key}"></span>`{key}` | {_cell(kind)} | '
                f"`{_cell(default)}` | {_cell(meaning)} |"
            )
        out.append("")
    return "\n".join(out)


def _paired_meaning(
    key: str, keys: list[str], comments: dict[tuple[str, str], str], table: str
) -> str:
    """Words for an uncommented key from its partner: ``X_weights`` weighs the choices ``X``
    (``Xs``, ``X_choices``), and ``max_X`` bounds what ``min_X`` does from above."""
    if key.endswith("_weights"):
        stem = key.removesuffix("_weights")
        for partner in (stem, stem + "s", stem + "_choices"):
            if partner in keys:
                return f"how often each of `{partner}` is drawn"
    for partner in (key + "_weights", key.removesuffix("s") + "_weights"):
        if partner in keys and partner != key:
            note = comments.get((table, partner), "")
            return f"the choices, drawn with `{partner}`" + (f" ({note})" if note else "")
    if key.removesuffix("_choices") + "_weights" in keys:
        return f"the choices, drawn with `{key.removesuffix('_choices')}_weights`"
    for low, high in (("max_", "min_"), ("min_", "max_")):
        partner = high + key.removeprefix(low)
        if key.startswith(low) and partner in keys and comments.get((table, partner)):
            bound = "upper" if low == "max_" else "lower"
            return f"the {bound} bound beside `{partner}` ({comments[(table, partner)]})"
    return "—"


def _named_tables(value: Any) -> bool:
    """A tuple of ``(name, settings dataclass)`` pairs (the families' own tables)."""
    return (
        isinstance(value, tuple)
        and bool(value)
        and all(
            isinstance(v, tuple)
            and len(v) == 2
            and isinstance(v[0], str)
            and is_dataclass(v[1])
            and not isinstance(v[1], type)
            for v in value
        )
    )


def _is_table(value: Any) -> bool:
    if _named_tables(value):
        return True
    if is_dataclass(value) and not isinstance(value, type):
        return True
    return (
        isinstance(value, Mapping)
        and bool(value)
        and all(is_dataclass(v) and not isinstance(v, type) for v in value.values())
    )


def _hints(cls: type) -> dict[str, Any]:
    try:
        return get_type_hints(cls)
    except (NameError, TypeError):  # an annotation imported only for type checkers
        return {}


def _source_comments(cls: type) -> dict[str, str]:
    """``field: type = default  # comment`` lines of the class body."""
    try:
        lines = inspect.getsource(cls).splitlines()
    except (OSError, TypeError):
        return {}
    return {m[1]: m[2].strip() for m in map(_FIELD_COMMENT.match, lines) if m}


def _toml_comments(
    text: str,
) -> tuple[dict[tuple[str, str], str], dict[tuple[str, str], str], dict[str, list[str]]]:
    """From the commented default TOML: each key's trailing comment, the ``# --`` group
    notes that precede keys, and the keys of each table in file order."""
    comments: dict[tuple[str, str], str] = {}
    notes: dict[tuple[str, str], str] = {}
    order: dict[str, list[str]] = {}
    table, pending = "", ""
    for line in text.splitlines():
        stripped = line.strip()
        header = _HEADER.match(line)
        if header:
            table, pending = header[1].strip(), ""
            continue
        if stripped.startswith("# --"):
            pending = stripped[4:].strip()
            continue
        if stripped.startswith("#") and pending:  # a note continued on the next line
            pending += " " + stripped.lstrip("#").strip()
            continue
        key = _KEY.match(line)
        if key and table:
            order.setdefault(table, []).append(key[1])
            comment = _trailing_comment(line)
            if comment:
                comments[(table, key[1])] = comment
            if pending:
                notes[(table, key[1])], pending = pending, ""
    return comments, notes, order


def _trailing_comment(line: str) -> str:
    """The text after a ``#`` that is not inside a TOML string."""
    quote = ""
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = ""
        elif ch in "\"'":
            quote = ch
        elif ch == "#":
            return line[i + 1 :].strip()
    return ""


def _plain(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


def _anchor(table: str) -> str:
    return "table-" + table.replace(".", "-").replace("_", "-")


def _cell(text: str) -> str:
    return text.replace("|", "\\|")
