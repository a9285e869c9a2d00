"""The fast evaluator equals the numpy reference bit for bit: every opcode and operand mode, every
constituent function, the presets, and random eq. (13)-shaped formulas (property test).

Both evaluators compute every transcendental with surfgen's own functions
(:mod:`surfgen.generator.elementary`), so the equality holds on every CPU and nothing here may
xfail. Every NaN counts as equal to every NaN (IEEE leaves the sign and payload of a NaN made by
an invalid operation to the hardware). numpy's own ufuncs are an accuracy cross-check only
(``test_numpy_ufuncs_agree_within_the_conditioning``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from surfgen.generator import elementary as E
from surfgen.generator.errors import FormulaError
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.eval.tape import (
    evaluate_fast,
    evaluate_program,
    profile_program,
    scratch_bytes,
)
from surfgen.generator.formula.expr import Expr, X, Y, Z, add_all, call, mul_all, num
from surfgen.generator.formula.parser import parse
from surfgen.generator.model.presets import PRESETS
from tests.support.numerics_tolerance import compare_with_numpy_ufuncs

# Odd sizes put 0 on the x and z axes; different sizes catch mixed-up axes.
GRID = Grid(Box.cube(2.5), (9, 10, 11))
# Steps of 0.5: x*y+z lands exactly on the nodes of the piecewise constituent functions.
NODE_GRID = Grid(Box.cube(4.0), (17, 13, 9))


def same_bits(got: np.ndarray, want: np.ndarray) -> np.ndarray:
    """Elementwise: the same float64 bits, or both NaN."""
    return (got.view(np.int64) == want.view(np.int64)) | (np.isnan(got) & np.isnan(want))


def assert_identical(got: np.ndarray, want: np.ndarray, what: str = "") -> None:
    assert got.shape == want.shape
    same = same_bits(got, want)
    if not same.all():
        bad = ~same
        raise AssertionError(
            f"{what}: {bad.sum()} values differ, e.g. {got[bad][:3]} vs {want[bad][:3]}"
        )


def check(tree: Expr, grid: Grid = GRID, params=None, threads: int = 1) -> np.ndarray:
    want = evaluate_reference(tree, grid, params).values
    got = evaluate_fast(tree, grid, params, threads=threads).values
    assert_identical(got, want, str(tree))
    return got


def check_text(text: str, grid: Grid = GRID, params=None, threads: int = 1) -> np.ndarray:
    return check(parse(text, (params or {}).keys()), grid, params, threads)


# ----------------------------------------------------------------------------- opcodes

UNARY = [
    "sin",
    "cos",
    "tan",
    "cot",
    "sec",
    "csc",
    "asin",
    "acos",
    "atan",
    "acot",
    "sinh",
    "cosh",
    "tanh",
    "asinh",
    "acosh",
    "atanh",
    "exp",
    "log",
    "log10",
    "sqrt",
    "cbrt",
    "abs",
    "sign",
    "floor",
    "ceil",
]
# Arguments at every level: per point, a plane, one axis, and in and out of [-1, 1].
ARGS = ["x*y-z", "(x*y-z)/6", "y*z", "x+z", "x", "z/2"]


@pytest.mark.parametrize("fn", UNARY)
def test_unary_functions_at_every_level(fn):
    for arg in ARGS:
        check_text(f"{fn}({arg})*(y+3)")


# Operand pairs giving the modes vector-vector, vector-scalar and scalar-vector at the point,
# plane and axis levels, with zeros (0/0, 0^-1) and negative bases (pow -> NaN).
PAIRS = [
    ("x*y-z", "y+z*x"),
    ("x*y+z", "z"),
    ("z", "x*y"),
    ("x", "y*z"),
    ("y*z-x", "3"),
    ("2", "x*y*z"),
    ("x", "y"),
    ("z", "x+z"),
    ("x*z", "0"),
]
BINARY = ["+", "-", "*", "/", "^", "min", "max", "atan2"]


@pytest.mark.parametrize("op", BINARY)
def test_binary_operations_in_every_mode(op):
    for a, b in PAIRS:
        text = f"({a}){op}({b})" if op in "+-*/^" else f"{op}({a},{b})"
        check_text(text)


def test_min_max_keep_numpy_signed_zero_and_nan_rules():
    got = check_text("min(x*z, -(y*0)) + max(-(x*0), z*0) + min(0/0*x, y) + max(z, 0/0)")
    assert np.isnan(got).all()
    got = check_text("1/min(x*0, -(z*0))")  # which zero numpy returns decides the infinity
    assert np.isinf(got).all()


@pytest.mark.parametrize("exponent", [2, 0.5, -1, 1, 0, 3, -2, -3, 4, 7, 10, -12, 2.5, -0.3, 40])
def test_constant_exponents(exponent):
    check_text(f"(x*y+z)^({exponent})")
    check_text(f"abs(x*y+z+0.1)^({exponent})")
    check_text(f"(x*y*z)^({exponent})")  # zeros: 0^-n = inf, 0^0 = 1


def test_integer_powers_are_surfgens_pow_within_2_ulp_of_c():
    grid = Grid(Box((-3.0, 0.1, -2.0), (3.0, 7.0, 2.0)), (41, 37, 29))
    x, y, z = grid.open_axes()
    base = np.broadcast_to(x * y + z * 1.37, grid.shape)
    for n in [3, 4, 5, 6, 9, 17, 32, 33, -2, -3, -5, -8, -32]:
        tree = parse(f"(x*y+z*1.37)^{n}" if n > 0 else f"(x*y+z*1.37)^({n})")
        got = evaluate_fast(tree, grid, threads=1).values
        assert_identical(got, E.power(base, float(n)), f"n={n}")
        with np.errstate(all="ignore"):
            want = np.vectorize(lambda u, n=n: _c_pow(u, n))(base)
        fin = np.isfinite(want) & (np.abs(want) > 1e-300)
        assert np.array_equal(np.isfinite(got), np.isfinite(want))
        ulps = np.abs(got[fin] - want[fin]) / np.spacing(np.abs(want[fin]))
        assert ulps.max() <= 2.0, f"n={n}: {ulps.max()} ulp from C pow"


def _c_pow(u: float, n: int) -> float:
    try:
        return math.pow(u, n)
    except (OverflowError, ValueError, ZeroDivisionError):  # C returns inf or nan
        return float(np.power(np.float64(u), np.float64(n)))


def test_exponent_shortcuts_apply_per_element_also_when_the_exponent_varies():
    # y takes the values -1, -0.5, 0, 0.5, 1, 1.5, 2: where it is 2, 0.5, -1, 1, 0 the power is
    # u*u, sqrt(u), 1/u, u, 1 (numpy's fast path of a constant exponent, kept as a convention).
    grid = Grid(Box((-2.0, -1.0, -3.0), (2.0, 2.0, 3.0)), (9, 7, 13))
    got = check_text("(x*z+0.3)^y", grid)
    x, y, z = grid.open_axes()
    u = np.broadcast_to(x * z + 0.3, grid.shape)
    yy = np.broadcast_to(y, grid.shape)
    with np.errstate(all="ignore"):
        for e, want in [
            (2.0, u * u),
            (0.5, np.sqrt(u)),
            (-1.0, 1 / u),
            (1.0, u),
            (0.0, 1.0 + 0 * u),
        ]:
            m = yy == e
            assert m.any() and same_bits(got[m], np.broadcast_to(want, grid.shape)[m]).all()
    check_text("(x+z)^y", grid)
    check_text("(z-x)^(x*y)", grid)
    check_text("2^(x*y*z)", grid)
    check_text("(-0*x)^(0.5+0*y) + (x*y*z)^(-1+0*x)", grid)  # sqrt(-0) = -0 by the convention


def test_special_values():
    check_text("1/(x*y*z) + 1/x")
    check_text("log(x*z) - log(-(x*z))")
    check_text("(x*z)^(-3) - (x*z)^(-4)")
    check_text("0*(1/(x*z)) + exp(1000*z*y) - exp(1000*z*y)")
    check_text("atan(tan(x*y*z*1e10)) + sqrt(-(x*z)^2)")


def test_constant_and_low_level_formulas_fill_the_grid():
    assert (check_text("2*pi-1") == 2 * np.pi - 1).all()
    check_text("x")
    check_text("sin(y)")
    check_text("z^2")
    for text in ("x*y", "cos(y*z)", "exp(x*z)", "y-z", "z"):  # written as broadcasts
        check_text(text)
        check_text(text, threads=2)


@pytest.mark.parametrize("shape", [(5, 4, 700), (4, 6, 5), (4, 4, 4)])
def test_broadcast_roots_of_every_source(shape):
    # A formula of one or two variables is a copy of a lower level's store or a row scalar
    # (kernels._broadcast, one call per x index): every kind of source, on a long z axis
    # (runs longer than half a tile), short ones and the smallest grid, 1 and 2 threads.
    from surfgen.generator.eval.opcodes import M_S, OP

    grid = Grid(Box((-1.5, -2.0, -0.5), (2.0, 1.5, 3.0)), shape)
    for text in ("0.25-pi", "x^2-y", "atan(y)", "x*y-1", "z/3", "cos(x*z)", "y*z^2"):
        program = compile_tree(parse(text))
        c0, c1 = program.blocks[7, :2]
        assert c1 - c0 == 1 and program.code[c0, 0] == OP["copy"], text
        want = evaluate_reference(parse(text), grid).values
        for threads in (1, 2):
            got = evaluate_program(program, grid, threads=threads).values
            assert_identical(got, want, f"{text} {shape} {threads}T")
        mode = program.code[c0, 1]
        assert (mode == M_S) == (text in ("0.25-pi", "x^2-y", "atan(y)", "x*y-1")), text


# ----------------------------------------------------------------------------- constituents

CONSTITUENTS = [
    "saw1({u}, 0.5, 3)",
    "saw1({u}, 1, 0)",
    "tri1({u}, 0.5, 4)",
    "stair1({u}, 0.5, 2, 3)",
    "stair1({u}, 1.5, -0.7, 1)",
    "rect1({u}, 0.3)",
    "rect1({u}, -0.5)",
    "rect2({u}, 1, 0.3)",
    "rect2({u}, 2, 0.5)",
    "rect3({u}, 0.5)",
    "rect3({u}, 0.25)",
    "saw2({u}, 0.5)",
    "tri2({u}, 1)",
    "tri3({u}, 0.5)",
    "stair2({u}, 0.5, 1.5)",
    "fcc({u}, -2, 1, 0, -1, 1.5, 2, 3, 0)",
    "fcc({u}, 0, 0, 1, 1)",
    "fcc8({u}+5)",
]


@pytest.mark.parametrize("template", CONSTITUENTS)
def test_constituent_functions(template):
    for u in ["x*y+z", "x", "y*z", "x*y*z*1.25"]:
        check(parse(template.format(u=u)), NODE_GRID)


def test_series_far_from_its_domain_and_with_huge_steps():
    check_text("saw1(x*y*z*1e306, 1, 2) + tri1(1/(x*z), 0.5, 2)")  # 1e307+, inf, nan
    check_text("saw1(x*y+z, 1e300, 2) + stair1(x*y*1e299+z, 1e300, 2, 3)")  # the exact loop


# ----------------------------------------------------------------------------- presets


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_presets(name):
    spec = PRESETS[name].spec()
    grid = Grid(spec.to_grid().box, tuple(min(n, 48) for n in spec.grid))
    check(spec.tree(), grid, spec.params)


# ----------------------------------------------------------------------------- eq. (13)

DIRECT = ["sin", "cos", "tan", "cot", "sec", "csc"]
INVERSE = ["asin", "acos", "atan", "acot"]
CONSTITUENT_H = [
    ("saw1", (0.5, 3)),
    ("tri1", (0.7, 2)),
    ("stair1", (0.5, 1.5, 2)),
    ("rect1", (0.3,)),
    ("rect2", (1.0, 0.3)),
    ("rect3", (0.5,)),
    ("saw2", (0.5,)),
    ("tri2", (1.0,)),
    ("tri3", (0.7,)),
    ("stair2", (0.5, 1.2)),
    ("fcc8", ()),
]
INTEGER_EXPONENTS = st.sampled_from([1, 1, 1, 2, 3, 4, -1, -2])
REAL_EXPONENTS = st.sampled_from([0.5, 1.5, 0.3, 2.7, -0.5, 1.38, 0.31])


def _exponent(draw, absolute: bool) -> float:
    """Real exponents on absolute values only, as the paper writes |x|^0.31."""
    if absolute and draw(st.booleans()):
        return draw(REAL_EXPONENTS)
    return draw(INTEGER_EXPONENTS)


@st.composite
def power_functions(draw) -> Expr:
    """Eq. (8): sum a x^b y^c z^d, the variables optionally in abs()."""
    absolute = draw(st.booleans())
    terms = []
    for _ in range(draw(st.integers(1, 3))):
        factors = [num(draw(st.sampled_from([1.0, -1.0, 2.5, -0.7, 3.0, 0.25, 1.5])))]
        for v in (X, Y, Z):
            if draw(st.integers(0, 2)) == 0:
                continue
            e = _exponent(draw, absolute)
            base = call("abs", v) if absolute else v
            factors.append(base if e == 1 else base ** num(e))
        terms.append(mul_all(factors))
    return add_all(terms)


@st.composite
def transforms(draw, names: list[str]):
    if draw(st.integers(0, 3)) == 0:
        name, params = draw(st.sampled_from(CONSTITUENT_H))
    else:
        name, params = draw(st.sampled_from(names)), ()
    return lambda u: call(name, u, *params)


def _maybe_abs(draw, e: Expr) -> Expr:
    return call("abs", e) if draw(st.integers(0, 3)) == 0 else e


def _pw(draw, base: Expr) -> Expr:
    """base^e, or |base|^e for a real e."""
    absolute = draw(st.integers(0, 2)) == 0
    e = _exponent(draw, absolute)
    if absolute and not float(e).is_integer():
        base = call("abs", base)
    return base if e == 1 else base ** num(e)


@st.composite
def eq13_factors(draw) -> Expr:
    """A/D * B/E * C/F with A = P1^l1, B = H(P3^l3)^mu1, C = G(H(P5^l5 / P6^l6))^mu3 ..."""
    h = draw(transforms(DIRECT + DIRECT + INVERSE))
    g = draw(transforms(INVERSE + INVERSE + DIRECT))
    p = [draw(power_functions()) for _ in range(8)]
    a = _maybe_abs(draw, _pw(draw, p[0]))
    d = _maybe_abs(draw, _pw(draw, p[1]))
    b = _maybe_abs(draw, _pw(draw, h(_pw(draw, p[2]))))
    e = _maybe_abs(draw, _pw(draw, h(_pw(draw, p[3]))))
    c = _maybe_abs(draw, _pw(draw, g(h(_pw(draw, p[4]) / _pw(draw, p[5])))))
    f = _maybe_abs(draw, _pw(draw, g(h(_pw(draw, p[6]) / _pw(draw, p[7])))))
    return ((a / d) * (b / e)) * (c / f)


@st.composite
def eq13_trees(draw) -> Expr:
    products = [
        mul_all([draw(eq13_factors()) for _ in range(draw(st.integers(1, 2)))])
        for _ in range(draw(st.integers(1, 2)))
    ]
    return add_all(products) - num(draw(st.sampled_from([0.0, 0.5, -1.25, 3.0])))


EQ13_GRID = Grid(Box((-2.0, -1.5, -2.5), (2.5, 1.5, 2.0)), (13, 11, 12))


@settings(
    max_examples=200,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(eq13_trees())
def test_random_eq13_formulas(tree):
    check(tree, EQ13_GRID)


# ----------------------------------------------------------------------------- the API


def test_threads_give_identical_fields():
    tree = parse("atan(tan(x*y*z*3))^3 + abs(x)^1.3*y - saw1(z*x, 0.5, 2)")
    grid = Grid(Box.cube(3.0), (21, 22, 23))
    one = check(tree, grid, threads=1)
    for threads in (2, None):
        assert np.array_equal(
            evaluate_fast(tree, grid, threads=threads).values, one, equal_nan=True
        )


def test_threads_run_at_once_and_never_more_than_asked(monkeypatch):
    import threading
    import time

    from surfgen.generator.eval import grid_driver as kernels
    from surfgen.generator.eval import tape as fast

    real, lock = kernels.run_grid, threading.Lock()
    active, seen, parts = [0], [0], []

    def tracked(*args):
        with lock:
            active[0] += 1
            seen[0] = max(seen[0], active[0])
            parts.append(args[-3])
        time.sleep(0.02)  # the kernel releases the GIL: so does this
        real(*args)
        with lock:
            active[0] -= 1

    tree = parse("atan(tan(x*y*z*3)) + sin(y*z)*z - x")  # with a yz plane
    grid = Grid(Box.cube(3.0), (21, 22, 23))
    want = check(tree, grid, threads=1)
    monkeypatch.setattr(kernels, "run_grid", tracked)
    # as many threads as asked, whatever the cores (evaluate caps them at NUMBA_NUM_THREADS)
    monkeypatch.setattr(fast, "_resolve_threads", lambda threads: threads)
    fast._pool(4)  # a pool larger than asked for below
    for threads in (2, 3):
        seen[0] = 0
        parts.clear()
        assert_identical(evaluate_fast(tree, grid, threads=threads).values, want)
        assert seen[0] == threads
        assert parts[0] == kernels.GRID_XYZ_AXES
        assert parts.count(kernels.GRID_YZ_ROWS) == parts.count(kernels.GRID_SLAB) == 4 * threads


def test_a_failing_part_is_raised_once_every_thread_has_stopped(monkeypatch):
    import threading
    import time

    from surfgen.generator.eval import grid_driver as kernels
    from surfgen.generator.eval import tape as fast

    real, lock, running = kernels.run_grid, threading.Lock(), [0]

    def failing(*args):
        with lock:
            running[0] += 1
        try:
            time.sleep(0.01)
            caller = threading.current_thread() is threading.main_thread()
            if args[-3] == kernels.GRID_SLAB and caller:  # while the helper works on
                raise MemoryError("no room for the slab's scratch")
            real(*args)
        finally:
            with lock:
                running[0] -= 1

    monkeypatch.setattr(kernels, "run_grid", failing)
    monkeypatch.setattr(fast, "_resolve_threads", lambda threads: threads)
    with pytest.raises(MemoryError, match="scratch"):
        evaluate_fast(parse("sin(x*y*z)"), Grid(Box.cube(1.0), (16, 9, 10)), threads=2)
    assert running[0] == 0


def test_threads_never_start_numbas_own_thread_pool():
    # numba.get_num_threads() would: its first choice, TBB, is older beside pymeshlab's libtbb
    # and warns on stderr, which a one-line error must not carry (tests/pipelines/
    # test_real_disks.py); surfgen's threads are its own.
    import subprocess
    import sys

    code = (
        "import pymeshlab, numba.np.ufunc.parallel as p\n"
        "from surfgen.generator.eval.tape import evaluate_fast\n"
        "from surfgen.generator.eval.grid import Box, Grid\n"
        "from surfgen.generator.formula.parser import parse\n"
        "for threads in (None, 2, 1):\n"
        "    evaluate_fast(parse('sin(x*y*z)'), Grid(Box.cube(1.0), (8, 9, 10)), threads=threads)\n"
        "print(p._is_initialized)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False" and "Numba" not in out.stderr, out.stderr


def _child_evaluates(queue) -> None:
    tree = parse("atan(tan(x*y*z*3)) + sin(y*z)*z - x")
    queue.put(evaluate_fast(tree, Grid(Box.cube(3.0), (21, 22, 23)), threads=2).values.tobytes())


def test_one_pool_of_threads_kept_and_a_forked_child_makes_its_own():
    import multiprocessing

    from surfgen.generator.eval import tape as fast

    tree = parse("atan(tan(x*y*z*3)) + sin(y*z)*z - x")
    grid = Grid(Box.cube(3.0), (21, 22, 23))
    want = evaluate_fast(tree, grid, threads=2).values
    pool = fast._pool(2)
    evaluate_fast(tree, grid, threads=2)
    assert fast._pool(2) is pool
    ctx = multiprocessing.get_context("fork")  # the pool's threads are not in the child
    queue = ctx.Queue()
    child = ctx.Process(target=_child_evaluates, args=(queue,))
    child.start()
    got = queue.get(timeout=120)
    child.join(timeout=60)
    assert child.exitcode == 0
    assert got == want.tobytes()


@pytest.mark.parametrize("threads", [0, -1, 1.5, True, "2"])
def test_bad_thread_counts(threads):
    with pytest.raises(FormulaError, match="threads"):
        evaluate_fast(parse("x"), GRID, threads=threads)


def test_compile_once_evaluate_on_several_grids():
    tree = parse("sin(x*m)*cos(y)+z^3-stair2(x*y, 0.5, m)", ["m"])
    program = compile_tree(tree, {"m": 0.7})
    for grid in (GRID, NODE_GRID, Grid(Box.cube(1.0), (4, 5, 300))):
        got = evaluate_program(program, grid, threads=1).values
        want = evaluate_reference(tree, grid, {"m": 0.7}).values
        assert_identical(got, want)


def test_evaluate_dispatches_to_the_fast_path_by_default():
    tree = parse("x^2+y^2+z^2-1")
    fast = evaluate(tree, GRID)
    ref = evaluate(tree, GRID, evaluator="reference")
    assert np.array_equal(fast.values, ref.values)
    assert not fast.values.flags.writeable


def test_profile_counts_cycles_per_code_row():
    tree = parse("sin(x*y*z)+x")
    program = compile_tree(tree)
    field, cycles = profile_program(program, GRID)
    assert np.array_equal(field.values, evaluate_reference(tree, GRID).values)
    assert cycles.shape == (len(program.code),) and (cycles > 0).all()


def test_scratch_is_a_small_fraction_of_the_field_at_512():
    grid = Grid(Box.cube(7.0), (512, 512, 512))
    for name in ("eqA", "eqB", "eqC"):
        spec = PRESETS[name].spec()
        program = compile_tree(spec.tree(), spec.params)
        assert scratch_bytes(program, grid, threads=2) < 0.05 * grid.size * 8


# ----------------------------------------------------------------------------- numpy's ufuncs


@pytest.mark.parametrize("fn", UNARY)
def test_numpy_ufuncs_agree_within_the_conditioning_per_function(fn):
    for arg in ARGS:
        checked, total = compare_with_numpy_ufuncs(parse(f"{fn}({arg})*(y+3)"), GRID)
        assert checked >= 0.5 * total, f"{fn}({arg}): only {checked} of {total} compared"


def test_numpy_ufuncs_agree_within_the_conditioning_on_presets():
    for name in sorted(PRESETS):
        spec = PRESETS[name].spec()
        grid = Grid(spec.to_grid().box, tuple(min(n, 24) for n in spec.grid))
        checked, total = compare_with_numpy_ufuncs(spec.tree(), grid, spec.params)
        assert checked >= 0.5 * total, f"{name}: only {checked} of {total} compared"


_COVERAGE: list[tuple[int, int]] = []


@settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(eq13_trees())
def test_numpy_ufuncs_agree_within_the_conditioning(tree):
    _COVERAGE.append(compare_with_numpy_ufuncs(tree, EQ13_GRID))


def test_the_conditioning_bound_compares_most_points_and_catches_errors(monkeypatch):
    # Most points of random eq. (13) formulas are compared (the bound is not vacuous) ...
    if not _COVERAGE:
        test_numpy_ufuncs_agree_within_the_conditioning()
    checked = sum(c for c, _ in _COVERAGE) / sum(t for _, t in _COVERAGE)
    assert checked > 0.6, f"only {checked:.0%} of the points compared"
    # ... and an error of 1e-9 in numpy's tan is caught.
    monkeypatch.setitem(E.UFUNCS, "tan", lambda u: np.tan(u) * (1 + 1e-9))
    with pytest.raises(AssertionError, match="beyond the bound"):
        compare_with_numpy_ufuncs(parse("tan(x*y-z)*(y+3)"), GRID)
