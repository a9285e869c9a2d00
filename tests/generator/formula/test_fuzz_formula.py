"""Hypothesis fuzzers over the formula grammar: any text either parses (within the documented
limits, and then prints back to itself and evaluates) or raises FormulaSyntaxError."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from surfgen.generator.errors import FormulaSyntaxError, SurfgenError
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.expr import printed_nesting, to_string
from surfgen.generator.formula.limits import MAX_FORMULA_NESTING, MAX_FORMULA_NODES
from surfgen.generator.formula.parser import parse

TOKENS = [
    "x", "y", "z", "pi", "m", "2", "0.5", "1e-3", ".5", "1e400", "0", "+", "-", "*", "/", "^",
    "(", ")", ",", "sin", "cos", "atan2", "min", "max", "abs", "sqrt", "saw1", "fcc", "powf",
    "rect1", " ", "  ", "é", "$", "sinn", "__import__", "'", "\\n", "1.2.3", "!", "%", "<",
    "<=", "=", "!=", "&", "|", "if", "pow",
]  # fmt: skip
GRID = Grid(Box.cube(1.0), (4, 4, 4))
FUZZ = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def check(text: str) -> None:
    """The property: parse, print, parse again, evaluate; only documented errors."""
    try:
        tree = parse(text, ["m"])
    except FormulaSyntaxError as exc:
        assert "\n" not in str(exc)
        return
    assert printed_nesting(tree) <= MAX_FORMULA_NESTING
    printed = to_string(tree)
    assert parse(printed, ["m"]) == tree
    try:
        values = evaluate_reference(tree, GRID, {"m": 0.7}).values
    except SurfgenError:  # e.g. a constituent function with a bad constant parameter
        return
    assert values.shape == GRID.shape and values.dtype == np.float64


@FUZZ
@given(st.lists(st.sampled_from(TOKENS), max_size=40))
def test_token_soup(tokens: list[str]) -> None:
    check("".join(tokens))


@FUZZ
@given(st.text(max_size=60))
def test_any_text(text: str) -> None:
    check(text)


def formulas() -> st.SearchStrategy[str]:
    """Grammatical formulas, nested at random (sometimes past the limits)."""
    leaf = st.sampled_from(["x", "y", "z", "pi", "m", "1.5", "2", "0"])

    def grow(inner: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
        return st.one_of(
            st.tuples(
                inner, st.sampled_from(["+", "-", "*", "/", "^", "%", "<", "&", "|"]), inner
            ).map(lambda t: "".join(t)),
            inner.map(lambda s: f"!{s}"),
            inner.map(lambda s: f"-{s}"),
            inner.map(lambda s: f"({s})"),
            st.tuples(st.sampled_from(["sin", "cos", "abs", "sqrt", "exp"]), inner).map(
                lambda t: f"{t[0]}({t[1]})"
            ),
            st.tuples(inner, inner).map(lambda t: f"atan2({t[0]},{t[1]})"),
        )

    return st.recursive(leaf, grow, max_leaves=60)


@FUZZ
@given(formulas())
def test_grammatical_formulas(text: str) -> None:
    check(text)


@settings(max_examples=20, deadline=None)
@given(
    st.sampled_from(["paren", "neg", "tower", "negtower", "sin", "flat"]),
    st.integers(min_value=0, max_value=400),
)
def test_deep_chains_parse_or_hit_a_documented_limit(kind: str, depth: int) -> None:
    text = {
        "paren": "(" * depth + "x" + ")" * depth,
        "neg": "-" * depth + "x",
        "tower": "x" + "^x" * depth,
        "negtower": "x" + "^-x" * depth,
        "sin": "sin(" * depth + "x" + ")" * depth,
        "flat": "x" + "+x" * (depth * 10),
    }[kind]
    try:
        tree = parse(text)
    except FormulaSyntaxError as exc:
        assert "nested too deeply" in str(exc) or "too large" in str(exc), exc
        assert depth > MAX_FORMULA_NESTING or kind == "flat" and depth * 20 > MAX_FORMULA_NODES
        return
    assert parse(to_string(tree)) == tree
    evaluate_reference(tree, GRID)
