"""A hypothesis fuzzer over the --where language: any text gives a WhereError or SQL that
SQLite accepts (values bound as parameters), within the documented limits."""

from __future__ import annotations

import sqlite3

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from surfgen.pipelines.catalogue.query import WhereError, parse_sort, parse_where
from surfgen.pipelines.catalogue.store import SCHEMA

WORDS = [
    "genus", "components", "faces", "stars", "key", "verdict", "formula", "note", "tag",
    "reason", "rejected", "starred", "duplicate", "seed", "box_fraction", "and", "or", "not",
    "AND", "Not", "=", "==", "!=", "<", "<=", ">", ">=", "~", "(", ")", "2", "-1.5", "1e3",
    "null", "yes", "no", "nice", "'a b'", '"q"', "'", "speckle", "3f2a", "drop", ";", "--",
    "' OR 1=1 --", "x'); DROP TABLE shapes; --",
]  # fmt: skip
FUZZ = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def database() -> sqlite3.Connection:
    con = sqlite3.connect(":memory:")
    con.executescript(SCHEMA)
    return con


CON = database()


def check(text: str) -> None:
    try:
        where = parse_where(text)
    except WhereError as exc:
        assert "\n" not in str(exc) and len(str(exc)) < 1000
        return
    query = f"SELECT shapes.* FROM shapes WHERE {where.sql} ORDER BY {parse_sort('-genus')}"
    CON.execute(query, where.params).fetchall()  # SQLite accepts it: no error of any kind
    assert CON.execute("SELECT count(*) FROM sqlite_master WHERE name='shapes'").fetchone()[0]


@FUZZ
@given(st.lists(st.sampled_from(WORDS), max_size=30))
def test_word_soup(words: list[str]) -> None:
    check(" ".join(words))


@FUZZ
@given(st.text(max_size=80))
def test_any_text(text: str) -> None:
    check(text)


def conditions() -> st.SearchStrategy[str]:
    atom = st.sampled_from(
        ["genus >= 2", "tag = nice", "not rejected", "starred", "formula ~ sin", "key = 3f",
         "reason = speckle", "note = null", "stars != 0"]
    )  # fmt: skip

    def grow(inner: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
        return st.one_of(
            st.tuples(inner, st.sampled_from([" and ", " or "]), inner).map("".join),
            inner.map(lambda s: f"not {s}"),
            inner.map(lambda s: f"({s})"),
        )

    return st.recursive(atom, grow, max_leaves=40)


@FUZZ
@given(conditions())
def test_grammatical_conditions(text: str) -> None:
    check(text)


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(["or", "not", "paren"]), st.integers(min_value=0, max_value=3000))
def test_long_chains_parse_or_hit_a_documented_limit(kind: str, n: int) -> None:
    text = {
        "or": " or ".join(["genus = 1"] * (n + 1)),
        "not": "not " * n + "genus = 1",
        "paren": "(" * n + "genus = 1" + ")" * n,
    }[kind]
    try:
        check_ok = parse_where(text)
    except WhereError as exc:
        assert any(w in str(exc) for w in ("too long", "conditions", "nested")), exc
        return
    CON.execute(f"SELECT 1 FROM shapes WHERE {check_ok.sql}", check_ok.params).fetchall()
