"""The catalogue's query language: ``--where`` conditions and ``--sort`` orders, turned into SQL.

- :func:`parse_where` turns the ``--where`` mini-language into an SQL condition whose values are
  bound parameters; :func:`parse_sort` does the same for ``--sort``. Both only accept the fields
  of :data:`FIELDS`, so no text from the user ever reaches SQL unchecked.

The ``--where`` language::

    expr       := term ("or" term)*
    term       := factor ("and" factor)*
    factor     := "not" factor | "(" expr ")" | comparison | FLAG
    comparison := FIELD OP VALUE          OP: = == != < <= > >= ~ (~: contains)
    VALUE      := number | word | 'quoted' | "quoted" | null

e.g. ``genus >= 2 and components < 5 and tag = nice and stars > 0 and run = 1``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from surfgen.generator.formula.limits import (
    MAX_STARS,
    MAX_WHERE_CONDITIONS,
    MAX_WHERE_LENGTH,
    MAX_WHERE_NESTING,
)
from surfgen.generator.model.families import family_list
from surfgen.pipelines.catalogue.store import CatalogueError

MAX_SORT_FIELDS = 8
_YES = {"yes", "true", "1", "y"}
_NO = {"no", "false", "0", "n"}


class WhereError(CatalogueError):
    """A ``--where`` or ``--sort`` expression that does not parse or names an unknown field."""


# ----------------------------------------------------------------------------- fields


@dataclass(frozen=True)
class Field:
    """A queryable field: its kind (number, text, key, tag, reason, flag) and SQL expression.

    ``sql`` is fixed text chosen here, never built from user input.
    """

    kind: str
    sql: str
    help: str


def _metric(name: str) -> str:
    return f"json_extract(shapes.metrics, '$.{name}')"


FIELDS: dict[str, Field] = {
    "genus": Field("number", "shapes.genus", "genus of the closed surface (null if open)"),
    "components": Field("number", "shapes.components", "connected components"),
    "faces": Field("number", "shapes.faces", "triangles"),
    "vertices": Field("number", "shapes.vertices", "vertices"),
    "euler": Field("number", "shapes.euler", "Euler characteristic"),
    "area": Field("number", "shapes.area", "surface area"),
    "volume": Field("number", "shapes.volume", "enclosed volume"),
    "stars": Field("number", "shapes.stars", f"stars given by curators (0-{MAX_STARS})"),
    "run": Field("number", "shapes.run", "run id"),
    "index": Field("number", "shapes.idx", "index of the draw in its run"),
    "seed": Field(
        "number", "(SELECT runs.seed FROM runs WHERE runs.id = shapes.run)", "seed of the run"
    ),
    "grid": Field("number", "json_extract(shapes.spec, '$.grid[0]')", "points per axis"),
    "d": Field("number", "shapes.d", "the constant d of eq. (13)"),
    "box_fraction": Field("number", _metric("box_fraction"), "area on the box faces / area"),
    "largest_component_fraction": Field(
        "number", _metric("largest_component_fraction"), "area of the largest component / area"
    ),
    "total_curvature": Field("number", _metric("total_curvature"), "total |Gauss curvature|"),
    "nonfinite": Field("number", _metric("nonfinite"), "non-finite samples of the field"),
    "solidity": Field("number", _metric("solidity"), "volume / convex hull volume"),
    "symmetry": Field(
        "number", _metric("symmetry"), "signed axis permutations the mesh maps onto itself under"
    ),
    "symmetry_permutations": Field(
        "number", _metric("symmetry_permutations"), "distinct axis permutations among them (1-6)"
    ),
    "symmetry_mirrors": Field(
        "number", _metric("symmetry_mirrors"), "mirrors x->-x, y->-y, z->-z among them (0-3)"
    ),
    "symmetries": Field("text", _metric("symmetries"), "labels of the symmetries (~ contains)"),
    "departure": Field(
        "number", _metric("departure"), "volume between a sculpture and its envelope / its volume"
    ),
    "free_standing": Field(
        "flag", f"COALESCE({_metric('free_standing')}, 0) = 1", "no area on the box's faces"
    ),
    "family": Field(
        "text",
        # shapes drawn before families were free draws (their models name no family)
        "COALESCE(json_extract(shapes.model, '$.family'), 'free')",
        f"sampler family: {family_list()}",
    ),
    "wall_fraction": Field(
        "number", _metric("wall_fraction"), "area on walls (poles, jumps) / area"
    ),
    "resolution_shift": Field(
        "number",
        _metric("resolution_shift"),
        "p95 distance between the mesh and its twice-as-fine remesh, either way, in cells",
    ),
    "resolution_to_fine": Field(
        "number", _metric("resolution_to_fine"), "p95 distance mesh -> twice-as-fine mesh (cells)"
    ),
    "resolution_to_coarse": Field(
        "number", _metric("resolution_to_coarse"), "p95 distance twice-as-fine mesh -> mesh (cells)"
    ),
    "resolution_area": Field(
        "number", _metric("resolution_area"), "area of the twice-as-fine mesh / area"
    ),
    "resolution_singular": Field(
        "number",
        _metric("resolution_singular"),
        "non-finite samples only the twice-as-fine grid has (poles on x, y, z = 0)",
    ),
    "key": Field("key", "shapes.key", "shape key or key prefix (= and != only)"),
    "verdict": Field("text", "shapes.verdict", "accepted or rejected (by the filters)"),
    "formula": Field("text", "shapes.formula", "formula text (~ for contains)"),
    "note": Field("text", "shapes.note", "curator's note (~ for contains)"),
    "tag": Field("tag", "", "has this tag (= != ~)"),
    "reason": Field("reason", "", "a rejection reason of the filters (= !=)"),
    "rejected": Field("flag", "shapes.user_rejected IS NOT NULL", "rejected by a curator"),
    "duplicate": Field("flag", "shapes.duplicate_of IS NOT NULL", "marked as a duplicate"),
    "starred": Field("flag", "shapes.stars > 0", "has at least one star"),
}
SORT_FIELDS = tuple(n for n, f in FIELDS.items() if f.kind in ("number", "key")) + ("random",)
_ORDER_BY = {n: FIELDS[n].sql for n in SORT_FIELDS if n != "random"} | {"random": "RANDOM()"}


def _fields_hint() -> str:
    return "fields: " + ", ".join(sorted(FIELDS))


# ----------------------------------------------------------------------------- --where parser

_TOKEN = re.compile(
    r"""
    (?P<space>\s+)
  | (?P<op>>=|<=|!=|==|=|<|>|~)
  | (?P<lparen>\()
  | (?P<rparen>\))
  | (?P<number>[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?(?![\w.\-]))
  | (?P<string>'[^']*'|"[^"]*")
  | (?P<word>[A-Za-z0-9_][\w.\-]*)
    """,
    re.VERBOSE,
)


@dataclass(frozen=True)
class Token:
    kind: str  # op, lparen, rparen, number, string, word, end
    text: str
    column: int  # 1-based


def tokenize(text: str) -> list[Token]:
    """Split a ``--where`` expression into tokens. Raises :class:`WhereError`."""
    tokens: list[Token] = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            what = "unterminated string" if text[pos] in "'\"" else f"unexpected '{text[pos]}'"
            raise _error(text, pos + 1, what)
        if m.lastgroup != "space":
            tokens.append(Token(m.lastgroup or "", m.group(), pos + 1))
        pos = m.end()
    tokens.append(Token("end", "", len(text) + 1))
    return tokens


def _error(text: str, column: int, what: str) -> WhereError:
    shown = text if len(text) <= 80 else text[:77] + "..."  # one readable line, whatever the input
    shown = " ".join(shown.split())
    return WhereError(f"--where: {what} at column {column} of '{shown}' ({_fields_hint()})")


class _Parser:
    """Recursive descent over the tokens, building SQL text and its parameters."""

    def __init__(self, text: str) -> None:
        self.text = text
        self.tokens = tokenize(text)
        self.pos = 0
        self.params: list[Any] = []
        self.fields: set[str] = set()
        self.depth = 0  # open parentheses: the only recursion
        self.conditions = 0

    @property
    def tok(self) -> Token:
        return self.tokens[self.pos]

    def keyword(self, word: str) -> bool:
        if self.tok.kind == "word" and self.tok.text.lower() == word:
            self.pos += 1
            return True
        return False

    def fail(self, what: str, tok: Token | None = None) -> WhereError:
        tok = tok or self.tok
        found = "the end" if tok.kind == "end" else f"'{tok.text}'"
        return _error(self.text, tok.column, f"{what}, found {found}")

    def parse(self) -> str:
        if self.tok.kind == "end":
            raise self.fail("expected a condition such as 'genus >= 2'")
        sql = self.expr()
        if self.tok.kind != "end":
            raise self.fail("expected 'and', 'or' or the end")
        return sql

    def expr(self) -> str:
        parts = [self.term()]
        while self.keyword("or"):
            parts.append(self.term())
        return parts[0] if len(parts) == 1 else "(" + " OR ".join(parts) + ")"

    def term(self) -> str:
        parts = [self.factor()]
        while self.keyword("and"):
            parts.append(self.factor())
        return parts[0] if len(parts) == 1 else "(" + " AND ".join(parts) + ")"

    def factor(self) -> str:
        negate = False
        while self.keyword("not"):  # a loop: 5,000 'not's are one NOT or none, not a tree
            negate = not negate
        sql = self.group() if self.tok.kind == "lparen" else self.comparison()
        return f"NOT ({sql})" if negate else sql

    def group(self) -> str:
        tok = self.tok
        self.depth += 1
        if self.depth > MAX_WHERE_NESTING:
            raise _error(self.text, tok.column, f"more than {MAX_WHERE_NESTING} nested '('")
        self.pos += 1
        sql = self.expr()
        if self.tok.kind != "rparen":
            raise self.fail("expected ')'")
        self.pos += 1
        self.depth -= 1
        return sql

    def comparison(self) -> str:
        name_tok = self.tok
        if name_tok.kind != "word":
            raise self.fail("expected a field name")
        self.conditions += 1
        if self.conditions > MAX_WHERE_CONDITIONS:
            raise _error(self.text, name_tok.column, f"more than {MAX_WHERE_CONDITIONS} conditions")
        name = name_tok.text.lower()
        if name not in FIELDS:
            raise _error(self.text, name_tok.column, f"unknown field '{name_tok.text}'")
        self.pos += 1
        self.fields.add(name)
        field = FIELDS[name]
        if field.kind == "flag" and self.tok.kind != "op":
            return f"({field.sql})"  # a bare flag: 'starred', 'not rejected'
        op_tok = self.tok
        if op_tok.kind != "op":
            raise self.fail(f"expected an operator (= != < <= > >= ~) after '{name_tok.text}'")
        self.pos += 1
        value_tok = self.tok
        if value_tok.kind not in ("number", "string", "word"):
            raise self.fail(f"expected a value after '{name_tok.text} {op_tok.text}'")
        self.pos += 1
        op = "=" if op_tok.text == "==" else op_tok.text
        return self.condition(name, field, op, op_tok, value_tok)

    def condition(self, name: str, field: Field, op: str, op_tok: Token, vt: Token) -> str:
        value = vt.text[1:-1] if vt.kind == "string" else vt.text
        is_null = vt.kind == "word" and value.lower() in ("null", "none")

        def allow(*ops: str) -> None:
            if op not in ops:
                raise _error(
                    self.text,
                    op_tok.column,
                    f"'{name}' takes {' '.join(ops)}, not '{op}'",
                )

        if field.kind == "number":
            if is_null:
                allow("=", "!=")
                return f"({field.sql} IS {'NOT ' if op == '!=' else ''}NULL)"
            allow("=", "!=", "<", "<=", ">", ">=")
            if vt.kind != "number":
                raise _error(self.text, vt.column, f"'{name}' needs a number, got '{value}'")
            self.params.append(float(value))
            return f"({field.sql} {op} ?)"
        if field.kind == "flag":
            allow("=", "!=")
            low = value.lower()
            if low not in _YES | _NO:
                raise _error(self.text, vt.column, f"'{name}' is yes or no, got '{value}'")
            truth = (low in _YES) == (op == "=")
            return f"({field.sql})" if truth else f"(NOT ({field.sql}))"
        if field.kind == "key":
            allow("=", "!=")
            prefix = value.lower()
            if not prefix or any(c not in "0123456789abcdef" for c in prefix):
                raise _error(self.text, vt.column, f"'{value}' is not a key (hex digits)")
            self.params.append(prefix + "%")
            return f"({'NOT ' if op == '!=' else ''}{field.sql} LIKE ?)"
        if field.kind == "tag":
            allow("=", "!=", "~")
            test = "instr(tags.tag, ?) > 0" if op == "~" else "tags.tag = ?"
            self.params.append(value.lower())
            exists = f"EXISTS (SELECT 1 FROM tags WHERE tags.key = shapes.key AND {test})"
            return f"(NOT {exists})" if op == "!=" else f"({exists})"
        if field.kind == "reason":
            allow("=", "!=")
            from surfgen.filters.verdict import REASONS

            if value not in REASONS:
                raise _error(
                    self.text,
                    vt.column,
                    f"unknown reason '{value}' (reasons: {', '.join(REASONS)})",
                )
            self.params.append(value)
            exists = "EXISTS (SELECT 1 FROM json_each(shapes.reasons) WHERE json_each.value = ?)"
            return f"(NOT {exists})" if op == "!=" else f"({exists})"
        # text
        if is_null:
            allow("=", "!=")
            return f"({field.sql} IS {'NOT ' if op == '!=' else ''}NULL)"
        allow("=", "!=", "~")
        self.params.append(value if op != "~" else value.lower())
        if op == "~":
            return f"(instr(lower({field.sql}), ?) > 0)"
        return f"({field.sql} {op} ?)"


@dataclass(frozen=True)
class Where:
    """A parsed ``--where``: SQL condition text, its bound parameters and the fields it uses."""

    sql: str
    params: tuple[Any, ...]
    fields: frozenset[str]


def parse_where(text: str | None) -> Where:
    """Parse a ``--where`` expression (see the module docstring). Empty or None: no condition.

    Raises :class:`WhereError` naming the column of the first problem and the allowed fields.
    """
    if text is None or not text.strip():
        return Where("1", (), frozenset())
    if not isinstance(text, str):
        raise WhereError(f"--where must be text, got {type(text).__name__}")
    if len(text) > MAX_WHERE_LENGTH:
        raise WhereError(
            f"--where: {len(text)} characters is too long (at most {MAX_WHERE_LENGTH})"
        )
    p = _Parser(text)
    sql = p.parse()
    return Where(sql, tuple(p.params), frozenset(p.fields))


def parse_sort(text: str | None) -> str:
    """``FIELD``, ``-FIELD`` (descending), or several separated by commas → SQL ``ORDER BY``.

    Missing values sort last; ties are broken by run and index. Raises :class:`WhereError`.
    """
    parts = (text or "").split(",")
    if len(parts) > MAX_SORT_FIELDS:
        raise WhereError(f"--sort: at most {MAX_SORT_FIELDS} fields, got {len(parts)}")
    terms = []
    for part in parts:
        part = part.strip()
        if not part:
            continue
        desc = part.startswith("-")
        name = part.lstrip("+-").strip().lower()
        if name not in _ORDER_BY:
            raise WhereError(
                f"--sort: unknown field '{name[:40]}' (sortable: {', '.join(SORT_FIELDS)};"
                " prefix with - for descending)"
            )
        sql = _ORDER_BY[name]
        terms.append(
            sql if name == "random" else f"{sql} IS NULL, {sql} {'DESC' if desc else 'ASC'}"
        )
    return ", ".join([*terms, "shapes.run", "shapes.idx"])
