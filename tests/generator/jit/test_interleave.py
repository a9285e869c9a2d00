"""Four vectors per iteration for the evaluator's loops (generator/vector_loops.py): which
compiles get LLVM's forced interleave, that they really get it, and that nothing else does."""

from __future__ import annotations

import json
import logging
import os
import re
import subprocess
import sys
import types

import numpy as np
import pytest
from numba import njit

from surfgen.generator.jit import cache as numba_cache
from surfgen.generator.jit import interleave as vector_loops
from surfgen.generator.jit.interleave import evaluator_function, interleave_from, make_listener


def _event(module: str | None):
    if module is None:
        return types.SimpleNamespace(data=None)
    func = types.SimpleNamespace(__module__=module)
    return types.SimpleNamespace(data={"dispatcher": types.SimpleNamespace(py_func=func)})


def test_which_functions_are_the_evaluators():
    for module in (
        "surfgen.generator.eval.interpreter",
        "surfgen.generator.eval.row_operations",
        "surfgen.generator.elementary",
        "surfgen.generator.elementary.trig",
        "surfgen.generator.elementary.roundtrip",
    ):
        assert evaluator_function(module), module
    for module in (
        "surfgen.generator.eval.grid_driver",
        "surfgen.generator.mesh.walls",
        "surfgen.generator.interpreterx",
        "surfgen.generator.elementaryfoo",
        "surfgen.filters.metrics",
        "numpy",
        "",
        None,
    ):
        assert not evaluator_function(module), module


def test_the_option_is_on_from_the_outermost_evaluator_compile_to_its_end():
    calls: list[int] = []
    listener = make_listener(setter=calls.append)
    ours, other = (
        _event("surfgen.generator.eval.interpreter"),
        _event("surfgen.generator.mesh.mesh"),
    )

    listener.on_start(other)  # another kernel: LLVM's choice
    listener.on_end(other)
    assert calls == []

    listener.on_start(ours)  # the interpreter ...
    listener.on_start(_event("surfgen.generator.elementary.trig"))  # ... compiles a row
    listener.on_start(other)  # ... and something else on the way (inherits the option)
    listener.on_end(other)
    listener.on_end(ours)
    assert calls == [vector_loops.INTERLEAVE]  # still on: the outer compile goes on
    listener.on_end(ours)
    assert calls == [vector_loops.INTERLEAVE, 0]  # LLVM's default back

    calls.clear()
    listener.on_start(other)  # an evaluator function compiled inside another kernel's compile
    listener.on_start(ours)
    listener.on_end(ours)
    listener.on_end(other)
    assert calls == [vector_loops.INTERLEAVE, 0]

    calls.clear()
    listener.on_end(ours)  # an end without its start (installed mid-compile): ignored
    listener.on_start(_event(None))  # not a dispatcher's compile
    listener.on_end(_event(None))
    assert calls == []


def test_a_failed_compile_resets_the_option():
    from numba.core import event
    from numba.core.errors import TypingError

    calls: list[int] = []
    listener = make_listener(setter=calls.append)

    def bad(x):
        return x.no_such_attribute

    bad.__module__ = "surfgen.generator.elementary.probe"
    with event.install_listener("numba:compile", listener), pytest.raises(TypingError):
        njit(bad)(1.0)
    assert calls == [vector_loops.INTERLEAVE, 0]


def test_interleave_count_from_the_environment(caplog):
    assert interleave_from({}) == vector_loops.DEFAULT_INTERLEAVE
    assert interleave_from({"SURFGEN_INTERLEAVE": " 2 "}) == 2
    assert interleave_from({"SURFGEN_INTERLEAVE": "0"}) == 0
    assert interleave_from({"SURFGEN_INTERLEAVE": "16"}) == 16
    with caplog.at_level(logging.WARNING, logger="surfgen.generator.jit.interleave"):
        for bad in ("17", "-1", "four", "2.5"):
            caplog.clear()
            assert interleave_from({"SURFGEN_INTERLEAVE": bad}) == vector_loops.DEFAULT_INTERLEAVE
            assert "SURFGEN_INTERLEAVE" in caplog.text and "0 (LLVM's choice) to 16" in caplog.text


def test_the_interleave_count_is_part_of_the_cache_stamp(monkeypatch):
    before = numba_cache.package_digest()
    monkeypatch.setattr(vector_loops, "INTERLEAVE", vector_loops.INTERLEAVE + 1)
    assert numba_cache.package_digest() != before


def _probe(out, a, n):
    """A loop body long enough that LLVM's cost model gives it one vector per iteration."""
    for k in range(n):
        x = a[k]
        y = np.sqrt(x * x + 1.0)
        p = ((((y * 0.5 + 0.25) * y + 0.125) * y + 0.0625) * y + 0.03125) * y
        out[k] = p / (x + 2.0)


def _compiled_as(module: str):
    func = types.FunctionType(_probe.__code__, _probe.__globals__, "probe")
    func.__module__ = module
    f = njit(error_model="numpy")(func)
    a = np.linspace(-3.0, 3.0, 100)
    out = np.empty(100)
    f(out, a, 100)
    return f, out


def _vector_sqrts(f) -> int:
    return len(re.findall(r"\bv?sqrtpd\b", f.inspect_asm(f.signatures[0])))


def test_an_evaluator_loop_runs_four_vectors_per_iteration_and_others_keep_llvms_choice():
    """The listener installed by ``surfgen.generator`` in this very process: a function of the
    elementary functions' package is compiled with four vector square roots in its loop (plus
    the epilogue's), the same function anywhere else with LLVM's one; the same values. (With
    ``SURFGEN_INTERLEAVE=0`` or ``SURFGEN_NO_VECTORIZE=1`` in the environment, what those
    promise instead.)"""
    from surfgen.generator import NO_VECTORIZE

    ours, ours_out = _compiled_as("surfgen.generator.elementary.probe")
    other, other_out = _compiled_as("tests.probe")
    assert np.array_equal(ours_out.view(np.int64), other_out.view(np.int64))
    if NO_VECTORIZE:  # SURFGEN_NO_VECTORIZE=1: no vector loop, whatever the count
        assert _vector_sqrts(ours) == _vector_sqrts(other) == 0
        return
    assert _vector_sqrts(other) >= 1, "the probe loop is not vectorised at all"
    if vector_loops.INTERLEAVE == 0:  # SURFGEN_INTERLEAVE=0: LLVM's choice everywhere
        assert vector_loops._INSTALLED is None
        assert _vector_sqrts(ours) == _vector_sqrts(other)
        return
    assert vector_loops._INSTALLED is not None
    assert _vector_sqrts(ours) >= vector_loops.INTERLEAVE * _vector_sqrts(other)
    # and LLVM's default is back for whatever compiles next
    again, _ = _compiled_as("tests.probe_again")
    assert _vector_sqrts(again) == _vector_sqrts(other)


def test_zero_leaves_the_choice_to_llvm():
    code = (
        "from surfgen.generator.jit import interleave as v; import json; import numba;"
        "print(json.dumps([v.INTERLEAVE, v._INSTALLED is None]))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code],
        env=dict(os.environ, SURFGEN_INTERLEAVE="0"),
        capture_output=True,
        text=True,
        check=True,
    )
    assert json.loads(done.stdout) == [0, True]


def test_a_held_compile_keeps_the_option_through_nested_compiles_and_errors():
    calls: list[int] = []
    listener = make_listener(setter=calls.append)
    row = _event("surfgen.generator.elementary.trig")
    with listener.held():  # a row's C function: numba sends no event for it
        listener.on_start(row)  # ... a helper it calls, compiled on the way
        listener.on_end(row)
        assert calls == [vector_loops.INTERLEAVE]  # still on
    assert calls == [vector_loops.INTERLEAVE, 0]
    calls.clear()
    with pytest.raises(RuntimeError), listener.held():
        raise RuntimeError("compile failed")
    assert calls == [vector_loops.INTERLEAVE, 0]


def test_a_c_function_compiled_as_the_evaluators_runs_four_vectors_per_iteration():
    """What :mod:`surfgen.generator.eval.row_functions` does for its rows, on the probe loop: a C function
    compiled inside :func:`vector_loops.evaluator_compile` gets the interleave, one compiled
    outside it LLVM's choice; the same values."""
    from numba import carray, cfunc
    from numba import types as nt

    from surfgen.generator import NO_VECTORIZE

    inner = njit(inline="always", error_model="numpy")(_probe)

    def c_probe(out_p, a_p, n):
        inner(carray(out_p, n, np.float64), carray(a_p, n, np.float64), n)

    sig = nt.void(nt.voidptr, nt.voidptr, nt.int64)

    def compiled(held: bool):  # each cfunc() compiles afresh (no cache)
        if held:
            with vector_loops.evaluator_compile():
                f = cfunc(sig, error_model="numpy")(c_probe)
        else:
            f = cfunc(sig, error_model="numpy")(c_probe)
        a, out = np.linspace(-3.0, 3.0, 100), np.empty(100)
        f.ctypes(out.ctypes.data, a.ctypes.data, 100)
        asm = f._library.get_asm_str()
        return len(re.findall(r"\bv?sqrtpd\b", asm)), out

    (ours, ours_out), (other, other_out) = compiled(True), compiled(False)
    assert np.array_equal(ours_out.view(np.int64), other_out.view(np.int64))
    if NO_VECTORIZE:
        assert ours == other == 0
    elif vector_loops.INTERLEAVE == 0:
        assert ours == other >= 1
    else:
        assert other >= 1, "the probe loop is not vectorised at all"
        assert ours >= vector_loops.INTERLEAVE * other
