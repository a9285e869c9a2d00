"""One result everywhere: the sha256 of the fields of every preset and of 50 eq. (13) formulas is
pinned here, and must hold on every CPU (AMD AVX2, Intel AVX-512, ...) and with vectorisation
disabled (``SURFGEN_NO_VECTORIZE=1``, checked in a subprocess); another subprocess compiles the
evaluator for an Intel Xeon (numba's ``NUMBA_CPU_NAME``, numpy's dispatch cut down to that Xeon's:
:func:`intel_target`) and checks the same hashes there.

The formulas are stored in ``tests/support/data/eq13_formulas.jsonl`` (drawn once by the sampler, seed 7;
they are data now, not regenerated). The hashes are in ``data/field_hashes.json``; after a
deliberate change of the numerics, regenerate them with

    python tests/generator/test_field_hashes.py --update

and say why in the commit. Every NaN is hashed as the same NaN (IEEE leaves the sign and
payload of a NaN made by an invalid operation to the hardware: x86 and ARM differ).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.eval.tape import evaluate_fast
from surfgen.generator.formula.parser import parse
from surfgen.generator.model.presets import PRESETS
from tests.support.processes import python_env

DATA = Path(__file__).resolve().parents[2] / "support" / "data"
FORMULAS = DATA / "eq13_formulas.jsonl"
HASHES = DATA / "field_hashes.json"
SHAPE = (13, 12, 11)  # small, odd/even sizes: 0 on the x and z axes of symmetric boxes


def field_hash(values: np.ndarray) -> str:
    v = np.array(values, dtype="<f8")
    v[np.isnan(v)] = np.nan
    return hashlib.sha256(v.tobytes()).hexdigest()


def cases() -> list[tuple[str, object, Grid, dict]]:
    """(key, tree, grid, params) of every preset and stored eq. (13) formula."""
    out = []
    for name in sorted(PRESETS):
        spec = PRESETS[name].spec()
        out.append((f"preset {name}", spec.tree(), Grid(spec.to_grid().box, SHAPE), spec.params))
    for i, line in enumerate(FORMULAS.read_text().splitlines()):
        row = json.loads(line)
        grid = Grid(Box(tuple(row["lo"]), tuple(row["hi"])), SHAPE)
        out.append((f"eq13 #{i}", parse(row["formula"]), grid, {}))
    return out


def fast_hashes() -> dict[str, str]:
    return {
        key: field_hash(evaluate_fast(tree, grid, params, threads=1).values)
        for key, tree, grid, params in cases()
    }


def _pinned() -> dict[str, str]:
    return json.loads(HASHES.read_text())["fields"]


def _diff(got: dict[str, str], want: dict[str, str]) -> list[str]:
    return [k for k in want if got.get(k) != want[k]] + [k for k in got if k not in want]


def test_formula_data_holds_50_eq13_formulas():
    rows = FORMULAS.read_text().splitlines()
    assert len(rows) == 50 and len(set(rows)) == 50


def test_fields_match_the_pinned_hashes():
    got = fast_hashes()
    bad = _diff(got, _pinned())
    assert not bad, f"{len(bad)} fields changed: {bad[:5]}"


def test_the_reference_gives_the_pinned_hashes_too():
    pinned = _pinned()
    for key, tree, grid, params in cases():
        assert field_hash(evaluate_reference(tree, grid, params).values) == pinned[key], key


_SUBPROCESS = """
import json, re, sys
from tests.generator.eval.test_field_hashes import fast_hashes
from surfgen.generator import NO_VECTORIZE
from surfgen.generator.eval.interpreter import interpreter_asm, load_interpreter
from surfgen.generator.eval.row_functions import rows_asm
from surfgen.generator.elementary.division import ROW_DIVISION
import numba, os
from numpy._core._multiarray_umath import __cpu_features__ as cpu_features
hashes = fast_hashes()
asm = interpreter_asm()
library = load_interpreter()._library
ir = library.get_llvm_str()
fma = r"\\bv?f(n)?m(add|sub)\\d"
disabled = os.environ.get("NPY_DISABLE_CPU_FEATURES", "").split()
print(json.dumps({{
    "cpu": numba.config.CPU_NAME,
    "features": disabled,
    "dispatched": [f for f in disabled if cpu_features.get(f)],
    "switch": NO_VECTORIZE,
    "hashes": hashes,
    "asm_chars": len(asm),
    "packed": len(re.findall(r"\\bv?(mul|add|sub|div)pd\\b", asm)),
    "fma_rows": len(re.findall(fma, rows_asm())),
    "fma_interpreter": len(re.findall(fma, library.get_asm_str())),
    "row_division": ROW_DIVISION,
    "contract": len(re.findall(
        r"= f(?:add|sub|mul|div|neg)(?: (?:nnan|ninf|nsz|arcp|afn))* (?:contract|reassoc|fast)\\b", ir
    )),
    "fmuladd": ir.count("llvm.fmuladd"),
    "zmm": len(re.findall(r"%zmm", asm)),
}}))
"""


_BACKGROUND: dict[str, tuple[subprocess.Popen, str]] = {}
BACKGROUND_TESTS = (
    "test_same_hashes_with_vectorisation_disabled",
    "test_same_hashes_with_intel_code_generation",
)


def intel_target() -> tuple[str, str]:
    """The Intel Xeon this machine can stand in for: numba's code generation for that CPU
    (``NUMBA_CPU_NAME``) and numpy's SIMD dispatch cut down to what it has
    (``NPY_DISABLE_CPU_FEATURES``).  With AVX-512 (F, BW, DQ, VL: an AMD Zen 4/5 or an Intel
    Xeon), a Skylake-SP Xeon: LLVM's instruction selection and vector widths for
    ``skylake-avx512``, numpy's AVX-512 (Skylake) kernels without the Ice Lake ones; else a
    Haswell/Broadwell Xeon (``haswell``: Intel's AVX2 code generation)."""
    from llvmlite import binding

    features = binding.get_host_cpu_features()
    avx512 = all(features.get(f, False) for f in ("avx512f", "avx512bw", "avx512dq", "avx512vl"))
    if avx512:
        return "skylake-avx512", "AVX512_ICL AVX512_SPR"
    return "haswell", "X86_V4 AVX512_ICL AVX512_SPR"


def _background_env(test: str) -> dict[str, str]:
    if test == "test_same_hashes_with_vectorisation_disabled":
        return {"SURFGEN_NO_VECTORIZE": "1"}
    cpu, disabled = intel_target()
    return {"NUMBA_CPU_NAME": cpu, "NPY_DISABLE_CPU_FEATURES": disabled}


def start_in_background(test: str) -> None:
    """Start the subprocess of background test ``test`` now; the test collects it later.  Each
    compiles the whole evaluator afresh (60-90 s of one core), so ``tests/conftest.py`` starts
    them as soon as the tests are collected: they then overlap the rest of the suite instead of
    adding to it."""
    if test in _BACKGROUND:
        return
    # A fresh numba cache: numba's cache key ignores the vectoriser flags, and a fresh compile
    # lets us read the machine code (no packed arithmetic left, no FMA; the target's registers).
    cache = tempfile.mkdtemp(prefix="surfgen-hashes-")
    env = python_env(NUMBA_CACHE_DIR=cache, **_background_env(test))
    code = _SUBPROCESS.format()
    proc = subprocess.Popen(
        [sys.executable, "-c", code],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    _BACKGROUND[test] = (proc, cache)


def stop_background(test: str | None = None) -> None:
    """Kill a run that no test collected (an interrupted session; all of them without ``test``)
    and drop its cache."""
    for name in [test] if test is not None else list(_BACKGROUND):
        if name not in _BACKGROUND:
            continue
        proc, cache = _BACKGROUND.pop(name)
        if proc.poll() is None:
            proc.kill()
        proc.wait()
        shutil.rmtree(cache, ignore_errors=True)


def _background_result(test: str) -> dict:
    start_in_background(test)  # already running when the whole suite runs
    proc, _cache = _BACKGROUND[test]
    try:
        stdout, stderr = proc.communicate(timeout=1800)
    finally:
        stop_background(test)
    assert proc.returncode == 0, stderr[-2000:]
    return json.loads(stdout.strip().splitlines()[-1])


def _no_contraction(result: dict) -> None:
    """No multiply-add is ever fused behind the code's back: no FMA in the elementary functions'
    rows, no contraction flag or ``fmuladd`` in the interpreter's IR; its only FMAs are the ones
    it asks for, the row division's (elementary/division.py), on a CPU that has them."""
    assert result["fma_rows"] == 0
    assert result["contract"] == 0 and result["fmuladd"] == 0
    assert (result["fma_interpreter"] > 0) == result["row_division"]


@pytest.mark.xdist_group("field-hashes-background")  # one worker starts both
def test_same_hashes_with_vectorisation_disabled():
    result = _background_result("test_same_hashes_with_vectorisation_disabled")
    assert result["switch"] is True
    assert result["asm_chars"] > 10_000  # the interpreter and everything it calls
    assert result["packed"] == 0, "vectorisation is still on"
    _no_contraction(result)
    bad = _diff(result["hashes"], _pinned())
    assert not bad, f"{len(bad)} fields differ without vectorisation: {bad[:5]}"


@pytest.mark.xdist_group("field-hashes-background")  # one worker starts both
def test_same_hashes_with_intel_code_generation():
    """The machines of this project are AMD EPYCs and Intel Xeons; the fields must not depend
    on which.  What differs between them is the code: LLVM's instruction selection and vector
    widths for the CPU numba compiles for, and the SIMD kernels numpy dispatches to.  This
    compiles the whole evaluator for an Intel Xeon (:func:`intel_target`) with numpy's dispatch
    cut down to that Xeon's, and checks every pinned field on it."""
    cpu, disabled = intel_target()
    result = _background_result("test_same_hashes_with_intel_code_generation")
    assert result["cpu"] == cpu, "numba did not compile for the Intel target"
    assert result["asm_chars"] > 10_000
    assert result["packed"] > 0, "the Intel build is not vectorised"
    _no_contraction(result)
    assert result["features"] == disabled.split()
    assert not result["dispatched"], f"numpy still dispatches {result['dispatched']}"
    if cpu == "skylake-avx512":  # 512-bit vectors, not LLVM's 256-bit tuning for that Xeon
        assert result["zmm"] > 0, "the AVX-512 build runs on 256-bit vectors"
    bad = _diff(result["hashes"], _pinned())
    assert not bad, f"{len(bad)} fields differ with {cpu} code: {bad[:5]}"


_NUMPY_SUBPROCESS = """
import json, sys
from numpy._core._multiarray_umath import __cpu_features__ as features
from tests.generator.eval.test_field_hashes import cases, field_hash
from surfgen.generator.eval.reference import evaluate_reference
print(json.dumps({{
    "x86_v3": bool(features.get("X86_V3")),
    "hashes": {{key: field_hash(evaluate_reference(tree, grid, params).values)
               for key, tree, grid, params in cases()}},
}}))
"""


def test_the_reference_ignores_numpys_simd_dispatch():
    """numpy picks its kernels by CPU (SSE4.2, AVX2, AVX-512 ...); the reference only uses
    operations that are exactly rounded on every path, so its fields keep their bits with
    numpy's AVX2/AVX-512 kernels switched off (``NPY_DISABLE_CPU_FEATURES``: numpy then runs
    its x86-64-v2 baseline, another code path for every ufunc the reference calls)."""
    import platform

    if platform.machine() not in ("x86_64", "AMD64"):
        raise AssertionError(f"this test names x86 features; add {platform.machine()}'s")
    env = python_env(NPY_DISABLE_CPU_FEATURES="X86_V3 X86_V4 AVX512_ICL AVX512_SPR")
    code = _NUMPY_SUBPROCESS.format()
    proc = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["x86_v3"] is False, "numpy still dispatches its AVX2 kernels"
    bad = _diff(result["hashes"], _pinned())
    assert not bad, f"{len(bad)} reference fields differ on numpy's baseline kernels: {bad[:5]}"


def _update() -> None:
    import platform

    hashes = fast_hashes()
    cpu = platform.processor() or platform.machine()
    if os.path.exists("/proc/cpuinfo"):
        m = re.search(r"model name\s*:\s*(.*)", Path("/proc/cpuinfo").read_text())
        cpu = m.group(1) if m else cpu
    doc = {"grid": list(SHAPE), "generated_on": cpu, "fields": hashes}
    HASHES.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    print(f"wrote {len(hashes)} hashes to {HASHES}")


if __name__ == "__main__":
    if sys.argv[1:] == ["--update"]:
        _update()
    else:
        print(__doc__)
