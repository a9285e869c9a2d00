"""The formula parser and printer: round trip, grammar, error messages, reference numerics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from surfgen.generator.errors import FormulaSyntaxError
from surfgen.generator.eval.reference import evaluate_points
from surfgen.generator.formula.expr import PI, Expr, X, Y, Z, call, num, param, to_string
from surfgen.generator.formula.functions import FUNCTIONS, FunctionDef
from surfgen.generator.formula.parser import parse

PARAMS = ("a", "m", "t2")

# ----------------------------------------------------------------------------- tree strategy

# Numbers that stress the printer: 0, integers at the 1e15 switch, tiny, huge, subnormal.
SPECIAL_NUMBERS = [0.0, 1.0, 2.0, 0.5, 0.1, 1e-300, 5e-324, 1.5e20, 1e15, 1e16, 999999999999999.0]
numbers = st.one_of(
    st.sampled_from(SPECIAL_NUMBERS),
    st.floats(min_value=0.0, allow_nan=False, allow_infinity=False),
    st.integers(min_value=0, max_value=10**6).map(float),
).map(num)
const_leaves = st.one_of(numbers, st.just(PI), st.sampled_from(PARAMS).map(param))
leaves = st.one_of(const_leaves, st.sampled_from([X, Y, Z]))


def _grow(children: st.SearchStrategy[Expr], consts: st.SearchStrategy[Expr]):
    """One level of tree: neg, a binary operator, or a call of any function of FUNCTIONS."""
    binary = st.builds(
        lambda op, a, b: Expr(op, (a, b)), st.sampled_from("+-*/^"), children, children
    )
    calls = [_calls_of(fdef, children, consts) for fdef in FUNCTIONS.values()]
    return st.one_of(children.map(lambda a: Expr("neg", (a,))), binary, *calls)


def _calls_of(fdef: FunctionDef, children, consts) -> st.SearchStrategy[Expr]:
    """Calls of ``fdef`` with a valid arity and constants where ``const_from`` requires them."""
    hi = fdef.max_args if fdef.max_args is not None else fdef.min_args + 4
    counts = st.integers(fdef.min_args, hi)
    if fdef.name == "fcc":  # x then (x_i, y_i) pairs
        counts = counts.filter(lambda n: (n - 1) % 2 == 0)

    def args_for(n: int) -> st.SearchStrategy[tuple[Expr, ...]]:
        k = n if fdef.const_from is None else fdef.const_from
        return st.tuples(*([children] * k + [consts] * (n - k)))

    return counts.flatmap(args_for).map(lambda args: Expr(fdef.name, args))


constants = st.recursive(const_leaves, lambda c: _grow(c, c), max_leaves=4)
trees = st.recursive(leaves, lambda c: _grow(c, constants), max_leaves=12)


def check_round_trip(tree: Expr) -> None:
    text = to_string(tree)
    assert "\n" not in text
    again = parse(text, PARAMS)
    assert again == tree
    assert to_string(again) == text  # printing is idempotent


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(trees)
def test_parse_inverts_to_string(tree: Expr) -> None:
    check_round_trip(tree)


# Every function of the table at the root, so none is left to chance in the big strategy.
small_trees = st.recursive(leaves, lambda c: _grow(c, constants), max_leaves=3)
every_call = st.one_of(*[_calls_of(f, small_trees, constants) for f in FUNCTIONS.values()])


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(every_call)
def test_parse_inverts_to_string_for_every_function(tree: Expr) -> None:
    check_round_trip(tree)


@pytest.mark.parametrize("value", SPECIAL_NUMBERS + [1.7976931348623157e308, 2.5e-308, 1 / 3])
def test_numbers_round_trip_exactly(value: float) -> None:
    tree = parse(to_string(num(value)))
    assert tree.op == "num" and tree.value == value


# ----------------------------------------------------------------------------- grammar facts


def neg(a: Expr) -> Expr:
    return Expr("neg", (a,))


@pytest.mark.parametrize(
    ("text", "tree"),
    [
        ("-x^2", neg(X**2)),
        ("(-x)^2", neg(X) ** 2),
        ("2^3^2", num(2) ** (num(3) ** 2)),
        ("(2^3)^2", (num(2) ** 3) ** 2),
        ("x-y-z", (X - Y) - Z),
        ("x-(y-z)", X - (Y - Z)),
        ("x/y/z", (X / Y) / Z),
        ("x/(y*z)", X / (Y * Z)),
        ("2^-x", num(2) ** neg(X)),
        ("2^-x^2", num(2) ** neg(X**2)),
        ("-x*y", neg(X) * Y),
        ("x*-y", X * neg(Y)),
        ("x+y*z^2", X + Y * Z**2),
        ("--x", neg(neg(X))),
        ("+x", X),
        (".5", num(0.5)),
        ("5.", num(5.0)),
        ("1e-3", num(1e-3)),
        ("1E+3", num(1000.0)),
        ("2.5e2", num(250.0)),
        ("pi", PI),
        ("  sin ( x )\t*\n2  ", call("sin", X) * 2),
        ("atan2(y, x)", call("atan2", Y, X)),
    ],
)
def test_grammar(text: str, tree: Expr) -> None:
    assert parse(text) == tree


def test_printer_uses_k3dsurf_precedence() -> None:
    assert to_string(neg(X**2)) == "-x^2"
    assert to_string(neg(X) ** 2) == "(-x)^2"
    assert to_string(num(2) ** (num(3) ** 2)) == "2^3^2"
    assert to_string((num(2) ** 3) ** 2) == "(2^3)^2"
    assert to_string(X - (Y - Z)) == "x-(y-z)"
    assert to_string(X - neg(Y)) == "x-(-y)"
    assert to_string(num(1e-300) + num(1.5e20)) == "1e-300+1.5e+20"


def test_powf_expands_to_the_power_function_of_eq_8() -> None:
    one = parse("powf(2, 1, 0, 3)")
    assert one == num(2) * X**1 * Y**0 * Z**3
    two = parse("powf(a,b,1,1, 0.5,2,2,-1)", ["a", "b"])
    first = param("a") * X ** param("b") * Y**1 * Z**1
    second = num(0.5) * X**2 * Y**2 * Z ** neg(num(1))
    assert two == first + second
    x, y, z = np.array([0.5, 2.0]), np.array([1.5, 3.0]), np.array([2.0, 0.25])
    got = evaluate_points(two, x, y, z, {"a": 3.0, "b": 2.0})
    np.testing.assert_allclose(got, 3 * x**2 * y * z + 0.5 * x**2 * y**2 / z, rtol=1e-14)


def test_named_parameters() -> None:
    assert parse("m*x + t2", ["m", "t2"]) == param("m") * X + param("t2")
    assert parse("saw1(x, r, p)", ["r", "p"]) == call("saw1", X, param("r"), param("p"))
    got = evaluate_points(parse("m*x", ["m"]), np.array([1.0, 2.0]), 0.0, 0.0, {"m": 3.0})
    np.testing.assert_array_equal(got, [3.0, 6.0])


@pytest.mark.parametrize("name", ["x", "pi", "sin", "powf", "saw1"])
def test_reserved_parameter_names(name: str) -> None:
    with pytest.raises(FormulaSyntaxError, match=f"parameter name '{name}' is reserved"):
        parse("x", [name])


# ----------------------------------------------------------------------------- errors


EXACT_MESSAGES = [
    ("sinn(x)", "unknown function 'sinn' at column 1 (did you mean sin?)"),
    ("x + sinn(y)", "unknown function 'sinn' at column 5 (did you mean sin?)"),
    ("(x", "unbalanced parentheses: '(' is never closed at column 1"),
    ("x + sin(y", "unbalanced parentheses: '(' is never closed at column 8"),
    ("x)", "unbalanced parentheses: ')' has no matching '(' at column 2"),
    ("(x))", "unbalanced parentheses: ')' has no matching '(' at column 4"),
    ("sin(x, y)", "sin takes 1 argument, got 2 at column 1"),
    ("", "empty formula at column 1"),
    ("w", "unknown variable 'w' at column 1 (allowed: x, y, z, pi)"),
    ("x $ y", "unexpected character '$' at column 3"),
    ("x +", "formula ends too early at column 4"),
    ("sin + x", "function 'sin' needs arguments in parentheses at column 1"),
    ("powf(1,2,3)", "powf takes groups of 4 arguments a,b,c,d (one per term), got 3 at column 1"),
    ("saw1(x, y, 2)", "saw1: argument 2 must be constant (numbers, pi, parameters) at column 1"),
    ("1e400", "number 1e400 is out of range at column 1"),
]


@pytest.mark.parametrize(("text", "message"), EXACT_MESSAGES)
def test_exact_error_messages(text: str, message: str) -> None:
    with pytest.raises(FormulaSyntaxError) as info:
        parse(text)
    assert str(info.value) == message


ERROR_COLUMNS = [
    # (formula, params, column, fragment of the message)
    ("sinn(x)", (), 1, "did you mean sin?"),
    ("2*coss(x)", (), 3, "did you mean cos?"),
    ("SIN(x)", (), 1, "did you mean sin?"),
    ("((x+y)", (), 1, "'(' is never closed"),
    ("x*(y+sin(z)", (), 3, "'(' is never closed"),
    ("x+y)", (), 4, "')' has no matching '('"),
    ("(x+)", (), 4, "unexpected ')'"),  # a missing operand, not an unbalanced ')'
    ("()", (), 2, "unexpected ')'"),
    ("sin(x,)", (), 7, "unexpected ')'"),
    ("x + atan2(y)", (), 5, "atan2 takes 2 arguments, got 1"),
    ("cos()", (), 1, "cos takes 1 argument, got 0"),
    ("saw1(x, 1)", (), 1, "saw1 takes 3 arguments, got 2"),
    ("fcc(x, 0,0, 1)", (), 1, "fcc takes at least 5 arguments, got 4"),
    ("fcc(x, 0,0, 1,1, 2)", (), 1, "fcc takes x then pairs"),
    ("   ", (), 1, "empty formula"),
    ("\t\n", (), 1, "empty formula"),
    ("x + q", ("a", "b"), 5, "unknown variable 'q' at column 5 (allowed: x, y, z, pi, a, b)"),
    ("xx", (), 1, "unknown variable 'xx' at column 1 (did you mean x?)"),
    ("x # y", (), 3, "unexpected character '#'"),
    ("x ? 1", (), 3, "unexpected character '?'"),
    ("x  ;", (), 4, "unexpected character ';'"),
    ("2x", (), 2, "unexpected 'x'"),
    ("x y", (), 3, "unexpected 'y'"),
    ("sin(x y)", (), 7, "expected ')' but found 'y'"),
    ("x * tri2(x, y)", (), 5, "tri2: argument 2 must be constant"),
    ("rect2(x, 1, z*a)", ("a",), 1, "rect2: argument 3 must be constant"),
    ("x*", (), 3, "formula ends too early"),
    ("x^", (), 3, "formula ends too early"),
    ("x - ", (), 5, "formula ends too early"),
    ("x*/y", (), 3, "unexpected '/'"),
    ("cos * x", (), 1, "function 'cos' needs arguments in parentheses"),
    ("x + powf", (), 5, "function 'powf' needs arguments in parentheses"),
    ("powf(1,2,3,4,5)", (), 1, "powf takes groups of 4 arguments a,b,c,d (one per term), got 5"),
    ("powf()", (), 1, "got 0"),
    ("x + 1e999", (), 5, "number 1e999 is out of range"),
]


@pytest.mark.parametrize(("text", "params", "column", "fragment"), ERROR_COLUMNS)
def test_errors_name_their_column(
    text: str, params: tuple[str, ...], column: int, fragment: str
) -> None:
    with pytest.raises(FormulaSyntaxError) as info:
        parse(text, params)
    message = str(info.value)
    assert info.value.column == column
    assert f"at column {column}" in message
    assert fragment in message
    assert "\n" not in message


def test_syntax_error_is_a_surfgen_error() -> None:
    from surfgen.generator.errors import SurfgenError

    with pytest.raises(SurfgenError):
        parse("sin(")


# ----------------------------------------------------------------------------- numerics


def ev(text: str, x=0.0, y=0.0, z=0.0, **params: float) -> np.ndarray:
    return evaluate_points(parse(text, params), x, y, z, params)


def test_basic_operations() -> None:
    x = np.array([-2.0, -0.5, 0.0, 1.0, 3.0])
    y = np.array([1.0, 2.0, 3.0, -4.0, 0.5])
    np.testing.assert_array_equal(ev("x+y", x, y), x + y)
    np.testing.assert_array_equal(ev("x-y-z", x, y, 1.0), x - y - 1.0)
    np.testing.assert_array_equal(ev("x*y/2", x, y), x * y / 2)
    np.testing.assert_array_equal(ev("-x^2", x), -(x**2))
    assert ev("2^3^2") == 512.0
    assert ev("x/y/z", 8.0, 2.0, 2.0) == 2.0
    assert ev("2^-x", 3.0) == 0.125
    np.testing.assert_allclose(ev("sin(pi/6) + cos(0)*exp(log(2))"), 2.5, rtol=1e-15)
    np.testing.assert_allclose(ev("sqrt(16) + cbrt(-8) + abs(-3)"), 5.0)
    np.testing.assert_allclose(ev("atan2(1, -1)"), 3 * np.pi / 4)


def test_broadcasting_shape() -> None:
    x = np.linspace(0, 1, 3)[:, None, None]
    y = np.linspace(0, 1, 4)[None, :, None]
    z = np.linspace(0, 1, 5)[None, None, :]
    assert ev("x+y*z", x, y, z).shape == (3, 4, 5)
    assert ev("1", x, y, z).shape == (3, 4, 5)  # constants are broadcast to the point shape


def test_ieee_division_and_poles() -> None:
    assert ev("1/0") == np.inf
    assert ev("-1/0") == -np.inf
    assert np.isnan(ev("0/0"))
    assert ev("cot(0)") == np.inf
    assert ev("csc(0)") == np.inf
    assert ev("sec(0)") == 1.0
    np.testing.assert_allclose(ev("cot(pi/4)"), 1.0)


def test_acot_is_maples_branch() -> None:
    u = np.array([-1e6, -5.0, -1.0, 0.0, 1.0, 5.0, 1e6])
    got = ev("acot(x)", u)
    assert np.all((got > 0) & (got < np.pi))  # open range (0, pi); at +-1e300 it rounds to 0, pi
    np.testing.assert_allclose(
        ev("acot(x)", np.array([-1.0, 0.0, 1.0])), [0.75, 0.5, 0.25] * np.array(np.pi)
    )
    assert np.all(np.diff(got) < 0)  # decreasing and continuous through 0 (not atan(1/u))
    assert ev("acot(1/0)") == 0.0 and ev("acot(-1/0)") == np.pi


def test_power_semantics() -> None:
    assert np.isnan(ev("(-8)^(1/3)"))
    assert np.isnan(ev("x^0.5", -2.0))
    assert ev("(-2)^3") == -8.0
    assert ev("(-2)^2") == 4.0
    assert ev("0^0") == 1.0
    assert ev("0^(-1)") == np.inf
    assert ev("abs(x)^0.31", -1.0) == 1.0


def test_special_values() -> None:
    np.testing.assert_array_equal(ev("sign(x)", np.array([-3.0, -0.0, 0.0, 2.0])), [-1, 0, 0, 1])
    assert np.isnan(ev("asin(2)")) and np.isnan(ev("acos(-1.5)"))
    assert np.isnan(ev("log(-1)")) and ev("log(0)") == -np.inf
    assert np.isnan(ev("sqrt(-1)"))
    assert np.isnan(ev("min(x, 1)", np.nan)) and np.isnan(ev("max(1, x)", np.nan))
    assert ev("min(2, -3)") == -3.0 and ev("max(2, -3)") == 2.0
    assert ev("floor(-0.5)") == -1.0 and ev("ceil(-0.5)") == 0.0


def test_every_function_evaluates_to_float64() -> None:
    """Each built-in accepts its arity through the reference evaluator (finite or not, no error)."""
    samples = {
        "fcc": "fcc(x, 0,0, 1,1, 2,0)",
        "saw1": "saw1(x, 1, 2)",
        "tri1": "tri1(x, 1, 2)",
        "stair1": "stair1(x, 1, 0.5, 2)",
        "rect1": "rect1(x, 0.3)",
        "rect2": "rect2(x, 1, 0.3)",
        "rect3": "rect3(x, 0.3)",
        "saw2": "saw2(x, 1)",
        "tri2": "tri2(x, 1)",
        "tri3": "tri3(x, 1)",
        "stair2": "stair2(x, 1, 0.5)",
    }
    x = np.linspace(-3.3, 3.3, 11)
    for name, fdef in FUNCTIONS.items():
        text = samples.get(name) or f"{name}({', '.join(['x'] * fdef.min_args)})"
        got = ev(text, x)
        assert got.dtype == np.float64 and got.shape == x.shape, name


def test_numbers_parse_to_their_float() -> None:
    for text in ["0.1", "1e-300", "1.5e+20", "123456789.125", "2.5E-7"]:
        assert ev(text) == float(text)
    assert math.isclose(float(ev("pi")), math.pi, rel_tol=0, abs_tol=0)
