"""MathMod's comparisons, logic, if and %: semantics, printing, and fast == reference bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.reference import evaluate_points, evaluate_reference
from surfgen.generator.eval.tape import evaluate_fast
from surfgen.generator.formula.logic import EPS
from surfgen.generator.formula.parser import parse


def value(text: str, x: float = 0.0, y: float = 0.0, z: float = 0.0) -> float:
    return float(evaluate_points(parse(text), x, y, z))


@pytest.mark.parametrize(
    ("text", "want"),
    [
        ("1<2", 1.0),
        ("2<1", 0.0),
        ("1<1", 0.0),
        (f"1-{EPS / 2}<1", 0.0),  # within fparser's tolerance: not less
        (f"1-{EPS * 4}<1", 1.0),
        ("1<=1", 1.0),
        (f"1+{EPS / 2}<=1", 1.0),
        ("2>1", 1.0),
        ("1>=2", 0.0),
        ("1=1", 1.0),
        (f"1={1 + EPS / 2}", 1.0),
        ("1!=2", 1.0),
        ("1!=1", 0.0),
        ("0.5&1", 1.0),
        ("0.49&1", 0.0),
        ("0|-0.7", 1.0),
        ("!0.2", 1.0),
        ("!(-3)", 0.0),
        ("7%3", 1.0),
        ("-7%3", -1.0),
        ("int(2.5)", 3.0),
        ("int(-2.5)", -2.0),
        ("trunc(-2.7)", -2.0),
        ("pow(2,10)", 1024.0),
        ("if(1, 5, 6)", 5.0),
        ("if(0.2, 5, 6)", 6.0),
        ("1+2<4&3>2|0", 1.0),  # precedence: ((1+2)<4 & 3>2) | 0
    ],
)
def test_values(text: str, want: float) -> None:
    assert value(text) == want


def test_nan_compares_false_and_is_not_true() -> None:
    assert value("0/0<1") == 0.0
    assert value("0/0=0/0") == 0.0
    assert value("0/0!=1") == 0.0
    assert value("if(0/0, 1, 2)") == 2.0
    assert value("!(0/0)") == 1.0


def test_if_does_not_leak_the_branch_not_taken() -> None:
    # 1/x is a pole at 0, but the condition chooses the other branch there
    got = evaluate_points(parse("if(abs(x)<0.5, 7, 1/x)"), np.array([-1.0, 0.0, 2.0]), 0, 0)
    assert got.tolist() == [-1.0, 7.0, 0.5]


@pytest.mark.parametrize(
    "text",
    [
        "x<y & !(z>=1) | x%2 = 1",
        "-x^2 != 3",
        "if(x<0, 1, 2)*!y",
        "(x<y)<z",
        "x%y%z",
        "x^2 % 3 <= y | z",
        "-(x<y)",
        "!!x",
    ],
)
def test_printing_parses_back(text: str) -> None:
    tree = parse(text)
    assert parse(str(tree)) == tree


def test_grammar_follows_fparser_precedence() -> None:
    assert parse("a<b&c|d", ["a", "b", "c", "d"]) == parse("((a<b)&c)|d", ["a", "b", "c", "d"])
    assert parse("x+1<y*2") == parse("(x+1)<(y*2)")
    assert parse("x*y%z") == parse("(x*y)%z")
    assert parse("!x^2") == parse("!(x^2)")


FORMULAS = [
    "if(x<0, 1/x, y)",
    "x<y & !(z>=1) | x%0.7 = 0.1",
    "(x<=y)+(x>y)*2+(x!=z)*4+(y=0)*8",
    "int(3*x)+trunc(2*y)-z%0.3",
    "if(x^2+y^2+z^2<1 & z>0, x*y*z, 1/(x-0.5))",
    "if(1<2, x, y)+if(x, y, z)",
    "!(x)+(0.25<0.5)*z",
]


@pytest.mark.parametrize("text", FORMULAS)
def test_fast_equals_reference_bit_for_bit(text: str) -> None:
    grid = Grid(Box.cube(2.0), (13, 15, 17))
    tree = parse(text)
    fast = evaluate_fast(tree, grid, threads=1).values
    ref = evaluate_reference(tree, grid).values
    assert np.array_equal(fast.view(np.int64), ref.view(np.int64))
