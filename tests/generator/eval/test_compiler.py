"""The compiler: opcode table, folding, sharing, hoisting levels, errors (no numba needed)."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.generator.errors import FormulaError
from surfgen.generator.eval import opcodes
from surfgen.generator.eval.compiler import Program, compile_tree, describe
from surfgen.generator.eval.opcodes import M_S, OP, OPCODES, OPNAMES
from surfgen.generator.formula.parser import parse

# The opcode numbers as first released. Opcodes are a file format: this list may only grow.
RELEASED = [
    "copy", "neg", "abs", "sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh",
    "asinh", "acosh", "atanh", "exp", "log", "log10", "sqrt", "cbrt", "sign", "floor", "ceil",
    "square", "recip", "usign", "powi", "series", "segsum", "add", "sub", "mul", "div", "pow",
    "min", "max", "atan2", "ratio1", "lt", "le", "eq", "ne", "and", "or", "not", "pick", "pickn",
    "fmod", "trunc", "atantan", "asinsin", "acoscos", "acotcot", "sec", "csc", "cot",
]  # fmt: skip


def compile_text(text: str, params: dict | None = None) -> Program:
    return compile_tree(parse(text, (params or {}).keys()), params)


def ops_at(program: Program, level: int) -> list[str]:
    c0, c1 = program.blocks[level, :2]
    return [OPNAMES[int(op)] for op in program.code[c0:c1, 0]]


def test_opcode_numbers_are_append_only():
    for number, name in enumerate(RELEASED):
        assert OPCODES[name][0] == number, f"opcode {name} was renumbered"
    numbers = [num for num, _ in OPCODES.values()]
    assert sorted(numbers) == list(range(len(numbers))), "opcode numbers must be 0..n-1"


def test_interpreter_uses_the_table():
    interpreter = pytest.importorskip("surfgen.generator.eval.interpreter")
    from surfgen.generator.eval.row_calls import SLOT

    for name, number in OP.items():
        if name in SLOT:  # behind the row table: its slot by opcode
            assert interpreter._UNARY_SLOT[number] == SLOT[name], name
            assert not hasattr(opcodes, f"OP_{name.upper()}"), name
        else:  # the kernels' global of its number
            assert getattr(opcodes, f"OP_{name.upper()}") == number, name


def test_constant_formula_folds_to_one_fill():
    p = compile_text("2*pi+sin(1)^2-m", {"m": 0.5})
    expected = 2 * np.pi + np.sin(np.float64(1.0)) ** 2 - 0.5
    assert p.constant == expected
    assert len(p.code) == 1 and p.code[0, 1] == M_S


def test_constants_fold_with_numpy_semantics():
    p = compile_text("x + (1/0 + 0/0)")  # inf + nan = nan, folded once
    assert np.isnan(p.consts).any()
    assert ops_at(p, 1) == ["add"]


def test_identical_subtrees_are_computed_once():
    p = compile_text("sin(x*y*z) + sin(x*y*z)^2 + y*x*z")
    xyz = ops_at(p, 7)
    assert xyz.count("sin") == 1
    assert xyz.count("mul") == 1  # x*y is shared with y*x (products commute exactly)


def test_power_function_hoists_to_one_multiply_add_per_term():
    # eq. (8): every term costs one per-point multiply, the sum one add per term.
    p = compile_text("2*x^3*y^2*z^4 + 3*x*y^5*z - abs(x)^0.5*z^2")
    xyz = ops_at(p, 7)
    assert sorted(xyz) == ["add", "mul", "mul", "sub"]  # abs(x)^0.5*z^2 is an xz value
    assert ops_at(p, 5) == ["mul"]
    assert "pow" in ops_at(p, 1) and "pow" in ops_at(p, 4)


def test_levels_of_the_paper_equation_a():
    p = compile_text(
        "atan(tan(1-abs(x)^0.31+5.76*abs(x)^1.38/abs(abs(x)^1.3+abs(y)^1.3+abs(z)^1.3)))^3"
        "+(abs(x)^0.3/abs(cot(m*x)))^0.3",
        {"m": 0.861},
    )
    counts = p.counts()
    assert counts["x"] >= 8  # every function of x alone, Nx times
    assert set(ops_at(p, 7)) == {"add", "abs", "div", "atantan", "pow"}  # one closed form


def test_pow_follows_numpy_fast_paths():
    assert ops_at(compile_text("(x+y+z)^2"), 7)[-1] == "square"
    assert ops_at(compile_text("(x+y+z)^0.5"), 7)[-1] == "sqrt"
    assert ops_at(compile_text("(x+y+z)^(-1)"), 7)[-1] == "recip"
    assert ops_at(compile_text("(x+y+z)^1"), 7)[-1] == "add"
    assert compile_text("(x+y+z)^0").constant == 1.0
    assert ops_at(compile_text("(x+y+z)^3"), 7)[-1] == "pow"  # surfgen's pow: no powi
    assert ops_at(compile_text("(x+y+z)^(-4)"), 7)[-1] == "pow"
    assert ops_at(compile_text("(x+y+z)^2.5"), 7)[-1] == "pow"
    assert ops_at(compile_text("(x+y+z)^40"), 7)[-1] == "pow"
    assert ops_at(compile_text("2^(x+y+z)"), 7)[-1] == "pow"


def test_trigonometric_forms_are_lowered():
    # cot = 1/tan, sec = 1/cos, csc = 1/sin: one fused row each (the function, then 1/)
    assert ops_at(compile_text("cot(x*y*z)"), 7) == ["mul", "cot"]
    assert ops_at(compile_text("acot(x*y*z)"), 7) == ["mul", "atan", "sub"]
    assert ops_at(compile_text("sec(x*y*z)"), 7) == ["mul", "sec"]
    assert ops_at(compile_text("csc(x*y*z)"), 7) == ["mul", "csc"]
    assert ops_at(compile_text("cos(x*y*z)^(-1)"), 7) == ["mul", "sec"]  # numpy's x^-1 is 1/x


def test_a_reciprocal_is_fused_only_with_a_value_nothing_else_reads():
    # tan(u) is read twice: computed once, its reciprocal a recip of its own
    assert ops_at(compile_text("tan(x*y*z) + cot(x*y*z)"), 7) == ["mul", "tan", "recip", "add"]
    assert ops_at(compile_text("1/sin(x*y*z) + sin(x*y*z)"), 7) == ["mul", "sin", "div", "add"]
    assert ops_at(compile_text("1/sin(x*y*z)"), 7) == ["mul", "csc"]  # 1/u: the same division
    assert ops_at(compile_text("2/sin(x*y*z)"), 7) == ["mul", "sin", "div"]
    # a reciprocal of another function stays as it was
    assert ops_at(compile_text("1/atan(x*y*z)"), 7)[-1] == "div"
    assert ops_at(compile_text("atan(x*y*z)^(-1)"), 7)[-1] == "recip"
    # in every block: here the xy block's
    assert ops_at(compile_text("z*sec(x*y)"), 3) == ["mul", "sec"]
    assert ops_at(compile_text("z*sec(x*y)"), 7) == ["mul"]
    # nested: sec(sec(u)) fuses the inner and the outer reciprocal alike
    assert ops_at(compile_text("sec(sec(x*y*z))"), 7) == ["mul", "sec", "sec"]


def test_constituents_share_their_parts():
    # rect2 contains acot(cot(.)) twice, of different arguments; saw2 of the same argument
    # as rect2's second one reuses it.
    p = compile_text("rect2(x*y*z, 1, 0.3) + saw2(x*y*z, 1)")
    assert ops_at(p, 7).count("acotcot") == 2


def test_series_switches_to_the_reference_loop_when_r_is_huge():
    p = compile_text("saw1(x*y*z, 1e300, 3)")
    (row,) = [r for r in p.code if OPNAMES[int(r[0])] == "series"]
    assert p.consts[row[5] + 2] == 1.0
    q = compile_text("saw1(x*y*z, 0.5, 3)")
    (row,) = [r for r in q.code if OPNAMES[int(r[0])] == "series"]
    assert q.consts[row[5] + 2] == 0.0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("x + m", "parameter 'm' has no value"),
        ("rect1(x, 2)", "rect1: t must satisfy"),
        ("saw1(x, 1, 2.5)", "saw1: p must be a whole number"),
        ("fcc(x, 1, 0, 0, 1)", "strictly increasing"),
    ],
)
def test_errors_match_the_reference(text, message):
    from surfgen.generator.eval.reference import evaluate_points

    tree = parse(text, ["m"])
    with pytest.raises(FormulaError, match=message):
        compile_tree(tree, {})
    with pytest.raises(FormulaError, match=message):
        evaluate_points(tree, 0.0, 0.0, 0.0, {})


def test_an_unbound_parameter_is_the_error_whatever_else_fails():
    from surfgen.generator.formula.expr import Expr, X, call

    m = Expr("param", (), "m")
    for tree in (
        Expr("+", (Expr("nope", (X,)), m)),  # an unknown function met first
        Expr("+", (call("saw1", X, Expr("param", (), "a"), 2), m)),  # a variable saw1 period
    ):
        with pytest.raises(FormulaError, match="parameter 'a' has no value|'m' has no value"):
            compile_tree(tree, {})
    with pytest.raises(FormulaError, match="unknown function 'nope'"):
        compile_tree(Expr("+", (Expr("nope", (X,)), m)), {"m": 1.0})


def test_equal_subtrees_built_apart_compile_as_one_shared_tree():
    shared = parse("sin(x*y) + cos(z)")
    copies = parse("sin(x*y) + cos(z)"), parse("sin(x*y) + cos(z)")
    from surfgen.generator.formula.expr import Expr

    one = compile_tree(Expr("*", (shared, shared)))
    two = compile_tree(Expr("*", copies))
    assert copies[0] is not copies[1] and copies[0] == copies[1]
    for name in ("code", "consts", "blocks", "loads", "stores", "rows"):
        assert np.array_equal(getattr(one, name), getattr(two, name), equal_nan=True), name
    assert [OPNAMES[int(r[0])] for r in one.code].count("sin") == 1  # and computed once


def test_unknown_function_and_variable_parameter():
    from surfgen.generator.formula.expr import Expr, X, Y, call

    with pytest.raises(FormulaError, match="unknown function 'nope'"):
        compile_tree(Expr("nope", (X,)))
    with pytest.raises(FormulaError, match="saw1: parameters must be constant"):
        compile_tree(call("saw1", X, Y, 2))


def test_program_is_read_only_and_printable():
    p = compile_text("sin(x)*y + z")
    assert not p.code.flags.writeable and not p.consts.flags.writeable
    text = p.disassemble()
    assert "sin" in text and "out[0]" in text
    assert describe(p).startswith(f"{len(p.code)} ops")


def test_register_reuse_keeps_the_register_file_small():
    # A long chain needs a constant number of rows, not one per operation.
    text = "+".join(f"sin(x*y*z*{k})" for k in range(1, 40))
    p = compile_text(text)
    assert p.n_vector <= 6
