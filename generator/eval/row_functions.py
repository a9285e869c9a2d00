"""The interpreter's heavy row operations, each compiled once as a C function of its own and
called through the row table (:mod:`surfgen.generator.eval.row_calls`).

Each C function here unpacks the table's one signature and runs one row operation: an elementary
function's row (:mod:`surfgen.generator.elementary`), a round trip, ``pow`` with the ``x^c``
convention, the series of eqs. (2)-(4) or a segment sum. Those are ``inline="always"`` numba
functions, so each is optimised and emitted once, here, and not again in every caller.

:func:`load_rows` loads them from numba's cache (or compiles them, about 16 s on one CPU the
first time on a machine, 0.2 to 1.7 s each) and fills their slots;
:func:`surfgen.generator.eval.interpreter.load_interpreter` loads those of equation (13) first
(:data:`~.row_calls.EQUATION_13_ROWS`), and a slot called before its row is loaded loads it.
"""

from __future__ import annotations

import logging
import threading

import numpy as np
from numba import carray, cfunc, njit

from surfgen.generator.elementary import explog as _el
from surfgen.generator.elementary import roundtrip as _rt
from surfgen.generator.elementary import trig as _tr
from surfgen.generator.eval import row_calls as far
from surfgen.generator.eval import row_operations as ops
from surfgen.generator.jit import interleave as vector_loops
from surfgen.generator.jit.cache import c_function_cached
from surfgen.generator.jit.options import C_FUNCTION, C_HELPER

log = logging.getLogger(__name__)


@njit(**C_HELPER)
def _w(w_p, rows, cols):
    return carray(w_p, (rows, cols), np.float64)


@njit(**C_HELPER)
def _k(k_p, n_k):
    return carray(k_p, n_k, np.float64)


# One C function per slot, arguments: W, rows, columns, d, a, b, s, n, consts, size, base.
# fmt: off
def _sin(w, r, c, d, a, b, s, n, k, nk, base): _tr.sin_row(_w(w, r, c), d, a, n)
def _cos(w, r, c, d, a, b, s, n, k, nk, base): _tr.cos_row(_w(w, r, c), d, a, n)
def _tan(w, r, c, d, a, b, s, n, k, nk, base): _tr.tan_row(_w(w, r, c), d, a, n)
def _asin(w, r, c, d, a, b, s, n, k, nk, base): _tr.asin_row(_w(w, r, c), d, a, n)
def _acos(w, r, c, d, a, b, s, n, k, nk, base): _tr.acos_row(_w(w, r, c), d, a, n)
def _atan(w, r, c, d, a, b, s, n, k, nk, base): _tr.atan_row(_w(w, r, c), d, a, n)
def _sec(w, r, c, d, a, b, s, n, k, nk, base): _tr.trig_row(_w(w, r, c), d, a, n, _tr.COS, True)  # noqa: E501
def _csc(w, r, c, d, a, b, s, n, k, nk, base): _tr.trig_row(_w(w, r, c), d, a, n, _tr.SIN, True)  # noqa: E501
def _cot(w, r, c, d, a, b, s, n, k, nk, base): _tr.trig_row(_w(w, r, c), d, a, n, _tr.TAN, True)  # noqa: E501
def _sinh(w, r, c, d, a, b, s, n, k, nk, base): _el.sinh_row(_w(w, r, c), d, a, n)
def _cosh(w, r, c, d, a, b, s, n, k, nk, base): _el.cosh_row(_w(w, r, c), d, a, n)
def _tanh(w, r, c, d, a, b, s, n, k, nk, base): _el.tanh_row(_w(w, r, c), d, a, n)
def _asinh(w, r, c, d, a, b, s, n, k, nk, base): _el.asinh_row(_w(w, r, c), d, a, n)
def _acosh(w, r, c, d, a, b, s, n, k, nk, base): _el.acosh_row(_w(w, r, c), d, a, n)
def _atanh(w, r, c, d, a, b, s, n, k, nk, base): _el.atanh_row(_w(w, r, c), d, a, n)
def _exp(w, r, c, d, a, b, s, n, k, nk, base): _el.exp_row(_w(w, r, c), d, a, n)
def _log(w, r, c, d, a, b, s, n, k, nk, base): _el.log_row(_w(w, r, c), d, a, n)
def _log10(w, r, c, d, a, b, s, n, k, nk, base): _el.log10_row(_w(w, r, c), d, a, n)
def _cbrt(w, r, c, d, a, b, s, n, k, nk, base): _el.cbrt_row(_w(w, r, c), d, a, n)
def _atantan(w, r, c, d, a, b, s, n, k, nk, base): _rt.atantan_row(_w(w, r, c), d, a, n)
def _asinsin(w, r, c, d, a, b, s, n, k, nk, base): _rt.asinsin_row(_w(w, r, c), d, a, n)
def _acoscos(w, r, c, d, a, b, s, n, k, nk, base): _rt.acoscos_row(_w(w, r, c), d, a, n)
def _acotcot(w, r, c, d, a, b, s, n, k, nk, base): _rt.acotcot_row(_w(w, r, c), d, a, n)
def _atan2_vv(w, r, c, d, a, b, s, n, k, nk, base): _tr.atan2_row_vv(_w(w, r, c), d, a, b, n)
def _atan2_vs(w, r, c, d, a, b, s, n, k, nk, base): _tr.atan2_row_vs(_w(w, r, c), d, a, s, n)
def _atan2_sv(w, r, c, d, a, b, s, n, k, nk, base): _tr.atan2_row_sv(_w(w, r, c), d, s, b, n)
def _pow_vv(w, r, c, d, a, b, s, n, k, nk, base): ops.power_vv(_w(w, r, c), d, a, b, n)
def _pow_vs(w, r, c, d, a, b, s, n, k, nk, base): ops.power_vs(_w(w, r, c), d, a, s, n)
def _pow_sv(w, r, c, d, a, b, s, n, k, nk, base): ops.power_sv(_w(w, r, c), d, s, b, n)
def _series(w, r, c, d, a, b, s, n, k, nk, base): ops.series_row(_w(w, r, c), d, a, n, _k(k, nk), base)  # noqa: E501
def _segsum(w, r, c, d, a, b, s, n, k, nk, base): ops.segsum_row(_w(w, r, c), d, a, n, _k(k, nk), base)  # noqa: E501
# fmt: on

FUNCTIONS = {name: globals()[f"_{name}"] for name in far.ROWS}

COMPILED: dict[str, object] = {}  # numba's CFunc of each row once loaded
_LOCK = threading.Lock()


def load_rows(names: tuple[str, ...] = far.ROWS) -> dict[str, object]:
    """Load the rows ``names`` (every row by default) from numba's cache (or compile them) and
    point their slots at them; returns the C functions loaded so far, by name. Thread-safe;
    each row is loaded once per process."""
    with _LOCK:
        missing = [name for name in names if name not in COMPILED]
        if missing:
            log.debug("loading the rows %s", ", ".join(missing))
            with vector_loops.evaluator_compile():  # numba's C functions send no compile event
                for name in missing:
                    compiled = cfunc(far.C_SIGNATURE, **C_FUNCTION)(FUNCTIONS[name])
                    far.fill(far.SLOT[name], compiled.address)
                    COMPILED[name] = compiled
    return COMPILED


far.set_loader(load_rows)  # a slot called before its row is loaded loads it


def run(name: str, W: np.ndarray, d: int, a: int, n: int, b: int = 0, s: float = 0.0) -> None:
    """Row ``name`` from Python, through its compiled C function (the machine code the
    interpreter runs): ``W[d, :n] = f(W[a, :n])`` (or of rows ``a`` and ``b``, row ``a`` and the
    scalar ``s``, ... by the slot's operand mode). ``W``: a C-contiguous 2-d float64 array.
    Without the constants the series and the segment sums need (the interpreter's only)."""
    if name not in FUNCTIONS or name in ("series", "segsum"):
        names = ", ".join(r for r in far.ROWS if r not in ("series", "segsum"))
        raise ValueError(f"unknown row {name!r}: expected one of {names}")
    if not (isinstance(W, np.ndarray) and W.dtype == np.float64 and W.ndim == 2):
        raise ValueError("W must be a 2-d float64 array")
    if not W.flags.c_contiguous or not W.flags.writeable:
        raise ValueError("W must be C-contiguous and writable")
    rows, cols = W.shape
    if not all(0 <= int(i) < rows for i in (d, a, b)) or not 0 <= int(n) <= cols:
        raise ValueError(f"rows d, a, b must be in [0, {rows}) and n in [0, {cols}]")
    none = np.zeros(1)
    load_rows((name,))[name].ctypes(
        W.ctypes.data, rows, cols, int(d), int(a), int(b), float(s), int(n), none.ctypes.data, 1, 0
    )


def rows_loaded(names: tuple[str, ...] = far.ROWS) -> bool:
    """Whether this process has loaded (or compiled) the rows ``names`` (every row by default)."""
    return all(name in COMPILED for name in names)


def rows_cached(names: tuple[str, ...] = far.ROWS) -> bool:
    """Whether numba's on-disk cache holds the rows ``names`` (every row by default) for this
    machine and this code. True when that cannot be told (numba's internals moved)."""
    return all(c_function_cached(FUNCTIONS[name], f"the {name} row") for name in names)


def rows_asm() -> str:
    """The rows' machine code (assembly), compiled first if need be; empty for the rows loaded
    from numba's on-disk cache (numba keeps no assembly of cached code)."""
    return "\n".join(c._library.get_asm_str() for c in load_rows().values())
