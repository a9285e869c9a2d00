"""Tests for surfgen.pipelines.catalogue.query: the --where and --sort languages, parsed into SQL text and
bound values (run against a catalogue: test_curation.py; fuzzed: test_fuzz_where.py)."""

from __future__ import annotations

import pytest

from surfgen.pipelines.catalogue.query import (
    FIELDS,
    SORT_FIELDS,
    WhereError,
    parse_sort,
    parse_where,
)


def test_values_are_bound_not_spliced() -> None:
    w = parse_where("genus >= 2 and tag = nice")
    assert "nice" not in w.sql and w.params == (2.0, "nice")
    assert w.fields == {"genus", "tag"}
    assert parse_where("  ").sql == "1" and parse_where(None).params == ()


@pytest.mark.parametrize(
    ("expr", "column", "fragment"),
    [
        ("genus >= 2 and", 15, "expected a field name"),
        ("genu > 1", 1, "unknown field 'genu'"),
        ("genus 2", 7, "expected an operator"),
        ("genus > abc", 9, "needs a number"),
        ("(genus > 1", 11, "expected ')'"),
        ("genus > 1 components < 2", 11, "expected 'and', 'or'"),
        ("genus > 1; drop table shapes", 10, "unexpected ';'"),
        ("tag < nice", 5, "'tag' takes = != ~"),
        ("reason = bogus", 10, "unknown reason 'bogus'"),
        ("key = xyz", 7, "not a key"),
        ("note = 'abc", 8, "unterminated string"),
        ("rejected = maybe", 12, "yes or no"),
        ("and", 1, "unknown field 'and'"),
    ],
)
def test_malformed_where_names_column_and_fields(expr: str, column: int, fragment: str) -> None:
    with pytest.raises(WhereError) as info:
        parse_where(expr)
    msg = str(info.value)
    assert f"at column {column} " in msg
    assert fragment in msg
    assert "fields: area, box_fraction, components" in msg
    assert "\n" not in msg


def test_sort() -> None:
    assert parse_sort(None).endswith("shapes.run, shapes.idx")
    assert parse_sort("-faces").startswith("shapes.faces IS NULL, shapes.faces DESC")
    with pytest.raises(WhereError, match="unknown field 'bogus'.*sortable: genus"):
        parse_sort("-bogus")
    with pytest.raises(WhereError, match="sortable"):
        parse_sort("tag")
    with pytest.raises(WhereError, match="at most 8 fields"):
        parse_sort(",".join(["genus"] * 9))
    assert set(SORT_FIELDS) - {"random"} <= set(FIELDS)
