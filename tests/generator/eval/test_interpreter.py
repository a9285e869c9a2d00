"""The interpreter behind a pointer (:mod:`surfgen.generator.eval.interpreter`): compiled once, as a
C function; the kernels call it, they do not contain it; a kernel called before it is loaded
loads it; a failed load gives NaN, never stale memory."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from surfgen.generator.eval import grid_driver as kernels
from surfgen.generator.eval import interpreter, row_operations
from surfgen.generator.eval import point_driver as points
from surfgen.generator.eval import row_calls as far
from surfgen.generator.eval import row_functions as row_table
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh import refine

# Poles inside the box: the walls' classification runs its kernel too.
FORMULA = "x^2 + y^2 + z^2 - 1 + 0.02*tan(2*x + 0.3)"


def _tiny_grid() -> Grid:
    return Grid(Box.cube(1.1), (14, 14, 14))


def _cached_code(cache) -> list[bytes]:
    """What numba's on-disk ``cache`` (a dispatcher's, or a C function's) holds for this
    machine: each cached overload's file (its object code, pickled)."""
    from numba.core.registry import cpu_target

    here = cpu_target.target_context.codegen().magic_tuple()
    index = cache._cache_file._load_index()
    names = [name for key, name in index.items() if key[1] == here]
    assert names, "nothing cached for this machine"
    return [Path(cache._cache_path, name).read_bytes() for name in names]


def test_the_kernels_call_the_interpreter_and_do_not_contain_it() -> None:
    from numba.core.caching import FunctionCache

    from surfgen.generator.mesh.mesh import extract_with_edges
    from surfgen.generator.mesh.walls import label_walls

    tree = parse(FORMULA)
    field = evaluate(tree, _tiny_grid(), evaluator="fast", threads=1)
    mesh, edges = extract_with_edges(field, 0.0, cap=True)
    label_walls(mesh, edges, field, tree, {}, 0.0, True, "keep")
    (own,) = _cached_code(FunctionCache(interpreter._run_code_c))
    row_table.load_rows()  # every row (the interpreter loads those of equation (13) only)
    rows = sum(len(c) for f in row_table.FUNCTIONS.values() for c in _cached_code(FunctionCache(f)))
    # the interpreter calls its rows through the row table (far.py) and does not contain them:
    # with them linked in it was 1.35 MB on a Zen 3, the rows alone 1.9 MB; now about 0.2 MB
    assert far._TABLE_SYMBOL.encode() in own
    assert len(own) < 0.25 * rows, (len(own), rows)
    inside = len(own) + rows
    symbol = interpreter._CELL_SYMBOL.encode()
    for kernel in (kernels.run_grid, points.eval_edges, refine._bisect_kernel):
        for code in _cached_code(kernel._cache):
            assert symbol in code, kernel  # the call through the cell
            # with the interpreter linked in, each was bigger than the interpreter (1.0-1.4x
            # on a Zen 3); without, a quarter to a half
            assert len(code) < 0.75 * inside, (kernel, len(code), inside)


CALLED_FIRST = """
import numpy as np
from surfgen.generator.eval import tape as fast, interpreter, grid_driver as kernels
from surfgen.generator.eval.compiler import compile_tree
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.parser import parse
from surfgen.generator.eval.reference import evaluate_reference

{setup}
tree = parse("sin(3*x)*y + z^2 - 1")
grid = Grid(Box.cube(1.0), (6, 6, 6))
prog = fast._prog(compile_tree(tree))
stores = kernels.grid_stores(prog[5], *grid.axes())
out = np.full(grid.shape, 7.0)
assert not interpreter.interpreter_loaded()
kernels.run_grid(prog, fast._tile(6), *stores, out, np.empty(0), kernels.GRID_ALL, 0, 0)
ref = evaluate_reference(tree, grid).values
print(interpreter.interpreter_loaded(), np.array_equal(out, ref), bool(np.isnan(out).all()))
"""


def _called_first(setup: str = "") -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", CALLED_FIRST.format(setup=setup)],
        capture_output=True, text=True, timeout=600, check=True,
    )  # fmt: skip


def test_a_kernel_called_first_loads_the_interpreter() -> None:
    # straight to the grid kernel, without the evaluator's load: the cell's first target loads
    out = _called_first()
    assert out.stdout.split() == ["True", "True", "False"], out.stderr


def test_a_failed_load_gives_nan_not_stale_memory() -> None:
    setup = "def broken(*args, **kwargs):\n    raise MemoryError('no room for the interpreter')\n"
    setup += "interpreter.cfunc = broken\n"
    out = _called_first(setup)
    assert out.stdout.split() == ["False", "False", "True"]  # every value NaN
    assert "no room for the interpreter" in out.stderr
    assert "this evaluation gives NaN" in out.stderr


def test_run_code_far_takes_c_contiguous_arrays_only() -> None:
    @njit
    def call(code, consts, W, S, T, prof):
        interpreter.run_code_far(code, 0, 0, consts, W, S, T, 1, prof)

    code, consts = np.zeros((1, 6), np.int64), np.zeros(1)
    W, S, T, prof = np.zeros((2, 4)), np.zeros(1), np.zeros((2, 4)), np.empty(0)
    call(code, consts, W, S, T, prof)  # no rows: nothing runs
    with pytest.raises(TypingError, match="C-contiguous"):
        call(code, consts, W[:, ::2], S, T, prof)
    with pytest.raises(TypingError, match="int64 values"):
        call(code.astype(np.int32), consts, W, S, T, prof)


# 1.3562357016817128 * (1/1.3562357016817128) rounds below 1: floor(x * (1/r)) is 0 for x = r,
# the lower bound of segment 2 (two candidates up).
SERIES_CASES = [(0.5, 3), (1.0, 0), (0.37, 12), (1e-300, 4), (3.0, 100), (1.3562357016817128, 3)]


@pytest.mark.parametrize(("r", "p"), SERIES_CASES)
def test_the_series_row_gives_the_series_bits(r: float, p: int) -> None:
    """The series row's branch-free loop (three candidate segments around x * (1/r), a select)
    gives what the scalar ``_series`` gives, bit for bit: on every segment bound and its two
    neighbouring doubles, random points in and beyond the sum's range, signed zeros, NaN, inf
    and huge values (those take the slow way), in place too."""
    rng = np.random.default_rng(p)
    bounds = np.arange(-(p + 3), p + 4) * r
    xs = np.concatenate(
        [
            rng.uniform(-(p + 4) * r, (p + 4) * r, 3000),
            bounds,
            np.nextafter(bounds, np.inf),
            np.nextafter(bounds, -np.inf),
            [0.0, -0.0, np.nan, np.inf, -np.inf, 1e308, -1e308, 1e307, 5e-324, -5e-324, 1e300],
        ]
    )
    n = xs.size
    consts = np.array([r, float(p), 0.0])
    want = np.array([row_operations.series(x, r, p) for x in xs])
    W = np.zeros((2, n))
    W[0] = xs
    row_operations.series_row(W, 1, 0, n, consts, 0)
    in_place = W[:1].copy()
    row_operations.series_row(in_place, 0, 0, n, consts, 0)
    for got in (W[1], in_place[0]):
        same = (got.view(np.int64) == want.view(np.int64)) | (np.isnan(got) & np.isnan(want))
        assert same.all(), xs[~same][:5]
