"""The row table: the interpreter calls its heavy row operations through a table of pointers.

numba compiles the code of every jitted function a function calls into that function, and LLVM
optimises and emits it again there. Each elementary function's vector loop (sin, cos, tan,
atan, pow, ...) was thus optimised and emitted four times on a fresh machine: alone, inside the
interpreter's unary dispatcher, inside ``run_code`` and inside the interpreter's C function. Now
each heavy row operation is compiled once, as a C function of its own (:mod:`.row_functions`), and
the interpreter calls it through one slot of this table (:func:`far_row`): its own compile is
its dispatch and its cheap loops only, and the rows can compile in another process meanwhile.

The table lives in this process, an external symbol of the interpreter's machine code, so the
code numba caches holds no address. Until its row is loaded, each slot points to a small
Python function that loads it (:func:`surfgen.generator.eval.row_functions.load_rows`, set by
:func:`set_loader`), then forwards the call: the interpreter can never call an empty slot. The
interpreter loads the rows of equation (13) (:data:`EQUATION_13_ROWS`) with itself; the others
(the hyperbolic functions, exp, log, cbrt, atan2, powers with a variable exponent and the
segment sums, for typed and MathMod formulas) are compiled the first time a formula calls
them, so that a first run's warm-up does not compile what the sampler never runs (6.5 s of a
Xeon's CPU).

Every slot has one C signature: the register file (data, rows, columns), the destination row
``d``, the operand rows ``a`` and ``b``, the scalar operand ``s``, the length ``n``, the
constants (data, size) and an immediate ``base``; each row reads what it needs.
"""

from __future__ import annotations

import ctypes
import logging
from collections.abc import Callable

import numpy as np
from llvmlite import binding as llvm
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic

log = logging.getLogger(__name__)

# The slots, in table order (append-only: a slot's number is compiled into the interpreter).
ROWS = ("sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh", "asinh", "acosh")
ROWS += ("atanh", "exp", "log", "log10", "cbrt", "atantan", "asinsin", "acoscos", "acotcot")
ROWS += ("atan2_vv", "atan2_vs", "atan2_sv", "pow_vv", "pow_vs", "pow_sv", "series", "segsum")
ROWS += ("sec", "csc", "cot")
SLOT = {name: i for i, name in enumerate(ROWS)}
# The rows equation (13)'s vocabulary lowers to (its direct and inverse trigonometric functions,
# their round trips and reciprocals, powers with constant real exponents — in the points' and
# the row tiles' programs too, where a constant exponent is a row — and the series of the
# constituent functions): what the sampler runs, loaded with the interpreter.
EQUATION_13_ROWS = ("sin", "cos", "tan", "asin", "acos", "atan", "sec", "csc", "cot")
EQUATION_13_ROWS += ("atantan", "asinsin", "acoscos", "acotcot", "pow_vs", "pow_vv", "series")

_TABLE_SYMBOL = "surfgen_row_table_v1"
_I64 = types.int64
# W, its rows, its columns; d, a, b; s; n; consts, their size; base
C_SIGNATURE = types.void(
    types.voidptr, _I64, _I64, _I64, _I64, _I64, types.float64, _I64, types.voidptr, _I64, _I64
)
_C_TYPES = [
    {types.voidptr: ctypes.c_void_p, types.float64: ctypes.c_double}.get(a, ctypes.c_int64)
    for a in C_SIGNATURE.args
]
C_PROTOTYPE = ctypes.CFUNCTYPE(None, *_C_TYPES)

_TABLE = (ctypes.c_void_p * len(ROWS))()


# load_rows of row_functions.py, once it is imported
_LOADER: list[Callable[[tuple[str, ...]], object]] = []


def set_loader(load: Callable[[tuple[str, ...]], object]) -> None:
    """What a slot's first call runs to load its row (given a tuple of row names):
    :func:`surfgen.generator.eval.row_functions.load_rows`, which registers itself when its
    module is imported (the rows import this table; the table imports no row)."""
    _LOADER[:] = [load]


def _load_rows(names: tuple[str, ...]):
    if not _LOADER:
        raise RuntimeError("no rows to load: surfgen.generator.eval.row_functions is not imported")
    return _LOADER[0](names)


def _first_call(slot: int):
    """Slot ``slot``'s first target: load its row (filling the slot), then run the call. An
    error here cannot reach the caller (ctypes prints it): the row's values are then NaN, never
    stale memory."""

    def call(*args):
        try:
            _load_rows((ROWS[slot],))
        except BaseException:
            log.exception("cannot load surfgen's %s row: this evaluation gives NaN", ROWS[slot])
            w_p, w_rows, tile, d, *_ = args
            rows = ctypes.cast(w_p, ctypes.POINTER(ctypes.c_double))
            np.ctypeslib.as_array(rows, shape=(w_rows, tile))[d] = np.nan
            return
        C_PROTOTYPE(_TABLE[slot])(*args)

    return C_PROTOTYPE(call)


_FIRST_CALLS = [_first_call(slot) for slot in range(len(ROWS))]  # alive while slots point there
for _slot, _target in enumerate(_FIRST_CALLS):
    _TABLE[_slot] = ctypes.cast(_target, ctypes.c_void_p).value
llvm.add_symbol(_TABLE_SYMBOL, ctypes.addressof(_TABLE))


def fill(slot: int, address: int) -> None:
    """Point ``slot`` at a compiled row (a C function of :data:`C_SIGNATURE`)."""
    _TABLE[slot] = address


def target(slot: int) -> int:
    """The address slot ``slot`` points to now."""
    return _TABLE[slot]


def first_call(slot: int) -> int:
    """The address of slot ``slot``'s loader (its target until the rows are loaded)."""
    return ctypes.cast(_FIRST_CALLS[slot], ctypes.c_void_p).value


# ----------------------------------------------------------------------------- C calls
# What an intrinsic that calls a C function of numba arrays needs (here and in interpreter.py).


def require_c_arrays(who: str, arrays) -> None:
    """Typing: each ``(type, ndim, dtype)`` is a C-contiguous array of that rank and dtype."""
    for ty, ndim, dtype in arrays:
        if not (isinstance(ty, types.Array) and ty.layout == "C" and ty.ndim == ndim):
            raise TypingError(f"{who}: expected a C-contiguous {ndim}-d array, got {ty}")
        if ty.dtype != dtype:
            raise TypingError(f"{who}: expected {dtype} values, got {ty}")


def require_integers(who: str, tys) -> None:
    for ty in tys:
        if not isinstance(ty, types.Integer):
            raise TypingError(f"{who}: expected an integer, got {ty}")


def c_arguments(context, builder, signature, args):
    """Code generation: ``whole(k)``, argument k as an int64, and ``buffer(k)``, array argument
    k as (its data as i8*, [its sizes])."""
    tys = signature.args

    def whole(k):
        return context.cast(builder, args[k], tys[k], types.int64)

    def buffer(k):
        array = context.make_array(tys[k])(context, builder, args[k])
        data = builder.bitcast(array.data, ir.IntType(8).as_pointer())
        return data, cgutils.unpack_tuple(builder, array.shape, tys[k].ndim)

    return whole, buffer


@intrinsic
def far_row(typingctx, slot, W, d, a, b, s, n, consts, base):
    """Row operation ``ROWS[slot]`` through the table: ``W`` a C-contiguous 2-d float64 array,
    ``consts`` a C-contiguous 1-d one, ``s`` a float, the rest integers."""
    require_c_arrays("far_row", ((W, 2, types.float64), (consts, 1, types.float64)))
    require_integers("far_row", (slot, d, a, b, n, base))
    if not isinstance(s, types.Float):
        raise TypingError(f"far_row: expected a float operand, got {s}")
    sig = types.void(slot, W, d, a, b, s, n, consts, base)

    def codegen(context, builder, signature, args):
        tys = signature.args
        whole, buffer = c_arguments(context, builder, signature, args)
        w_p, (w_rows, tile) = buffer(1)
        k_p, (n_k,) = buffer(7)
        s_value = context.cast(builder, args[5], tys[5], types.float64)
        values = [w_p, w_rows, tile, whole(2), whole(3), whole(4), s_value, whole(6), k_p, n_k]
        values.append(whole(8))
        fnty = ir.FunctionType(ir.VoidType(), [v.type for v in values])
        module = builder.module
        table = module.globals.get(_TABLE_SYMBOL)
        if table is None:
            table = ir.GlobalVariable(
                module, ir.ArrayType(fnty.as_pointer(), len(ROWS)), _TABLE_SYMBOL
            )
        zero = ir.Constant(ir.IntType(64), 0)
        entry = builder.gep(table, [zero, whole(0)], inbounds=True)
        builder.call(builder.load(entry), values)
        return context.get_dummy_value()

    return sig, codegen
