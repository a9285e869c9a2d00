"""The driver's warm-up runs every numba kernel a sampled shape needs, so forked workers never
compile one inside a shape's timeout."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from surfgen.generator.errors import SurfgenError

# In a fresh process: in this one, earlier tests may have compiled what the warm-up forgets.
CHECK = """
import json, sys, tempfile
from pathlib import Path
from numba.core.registry import CPUDispatcher
from surfgen.generator.eval import row_functions
from surfgen.pipelines.run.config import load_config
from surfgen.pipelines.run.shapes import make_shape
from surfgen.pipelines.run.warmup import shape_kernels_cached, warm_shape_kernels

def compiled():
    out = {}
    for name, module in list(sys.modules.items()):
        if name.startswith("surfgen."):
            for attr, value in vars(module).items():
                if isinstance(value, CPUDispatcher):
                    out[name + "." + attr] = len(value.signatures)
    out.update({"row " + name: 1 for name in row_functions.COMPILED})  # the interpreter's rows
    return out

warm_shape_kernels()
cached = shape_kernels_cached()
before = compiled()
config = load_config(None).with_grid(24)
accepted, families = 0, set()
with tempfile.TemporaryDirectory() as tmp:
    # every family, accepted and rejected; 50: a perforated infill shell (its depth at a point)
    for index in (*range(8), 50):
        out = make_shape(index, seed=7, config=config, staging=Path(tmp), pictures=True)
        accepted += out.verdict.accepted
        model = json.loads(out.row["model"])
        families.add(model["family"] + ("-shell" if model["structure"].get("shell") else ""))
after = compiled()
grew = {k: [before.get(k, 0), v] for k, v in after.items() if v != before.get(k, 0)}
print(json.dumps({"kernels": sum(before.values()), "accepted": accepted, "grew": grew,
                  "cached": cached, "families": sorted(families)}))
"""


def test_sampled_shapes_compile_nothing_after_the_warm_up() -> None:
    out = subprocess.run(
        [sys.executable, "-c", CHECK], capture_output=True, text=True, timeout=600, check=True
    )
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["kernels"] >= 10 and result["accepted"] >= 1
    assert {"sculpture", "infill-shell", "lattice"} <= set(result["families"]), result["families"]
    assert not result["grew"], f"compiled while sampling, not in the warm-up: {result['grew']}"
    # what tells a cold start (and its notice) checks kernels the warm-up does cache
    assert result["cached"] is True


# ----------------------------------------------------------------------------- a cold cache


def test_a_cold_cache_is_told_from_a_warm_one(tmp_path) -> None:
    from surfgen.pipelines.run.warmup import grid_kernel_cached, warm_grid_kernel

    warm_grid_kernel()
    assert grid_kernel_cached()
    code = "from surfgen.pipelines.run import warmup as w; print(w.grid_kernel_cached(), w.shape_kernels_cached())"
    fresh = subprocess.run(
        [sys.executable, "-c", code], env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)},
        capture_output=True, text=True, timeout=120, check=True,
    )  # fmt: skip
    assert fresh.stdout.split() == ["False", "False"]


def test_a_cold_start_says_it_compiles_first(monkeypatch, caplog) -> None:
    from surfgen.pipelines.run import warmup

    heard: list[str] = []
    warmup.warm_shape_kernels(parallel=False, notice=heard.append)
    assert heard == []  # warm: nothing to say
    monkeypatch.setattr(warmup, "shape_kernels_cached", lambda: False)  # as on a new machine
    with caplog.at_level("INFO", logger="surfgen.pipelines.run.warmup"):
        warmup.warm_shape_kernels(parallel=False, notice=heard.append)
    assert heard == [warmup.COMPILE_NOTICE]
    assert warmup.COMPILE_NOTICE in caplog.messages  # the library logs it too


def test_meanwhile_runs_once_the_interpreter_is_ready_before_the_child_is_awaited(
    monkeypatch,
) -> None:
    from surfgen.generator.eval import interpreter
    from surfgen.pipelines.run import warmup

    order: list[str] = []

    class Child:  # a child still compiling: awaited after ``meanwhile``
        returncode = 0

        def communicate(self):
            order.append("child awaited")
            return b"", b""

        def poll(self):
            return self.returncode

    monkeypatch.setattr(warmup, "_start_children", lambda: (None, Child()))
    warmup.warm_shape_kernels(
        parallel=True,
        meanwhile=lambda: order.append(f"meanwhile {interpreter.interpreter_loaded()}"),
    )
    assert order == ["meanwhile True", "child awaited"]


class _Cycle:
    def __init__(self) -> None:
        self.me = self  # only the cycle collector frees it


@pytest.mark.parametrize("collect", [True, False])
def test_the_cycle_collector_is_paused_while_compiling(collect) -> None:
    import gc
    import weakref

    from surfgen.pipelines.run.warmup import _collector_paused

    assert gc.isenabled()
    with _collector_paused(collect=collect):
        assert not gc.isenabled()
        gc.collect()  # what came before is not this block's garbage
        garbage = weakref.ref(_Cycle())
        assert garbage() is not None
    assert gc.isenabled()
    assert (garbage() is None) == collect  # one collection after, unless the process exits
    gc.collect()
    assert garbage() is None


def test_the_cycle_collector_is_left_alone_with_a_warm_cache_or_off() -> None:
    import gc

    from surfgen.pipelines.run.warmup import _collector_paused

    with _collector_paused(pause=False):
        assert gc.isenabled()
    gc.disable()
    try:
        with _collector_paused():
            assert not gc.isenabled()
        assert not gc.isenabled()  # the caller's choice kept
    finally:
        gc.enable()


def test_sample_prints_the_compile_notice_once(monkeypatch, tmp_path, capsys) -> None:
    from surfgen.pipelines.cli.main import main
    from surfgen.pipelines.run import warmup

    monkeypatch.setattr(warmup, "shape_kernels_cached", lambda: False)
    args = ["sample", "--n", "1", "--seed", "3", "--grid", "16", "--workers", "1"]
    assert main([*args, "--no-thumbnails", "--out", str(tmp_path / "cat")]) == 0
    err = capsys.readouterr().err
    assert err.count("compiling surfgen's numba kernels") == 1, err


def test_kernel_cached_tells_each_kernel(tmp_path) -> None:
    from surfgen.generator.eval import grid_driver as kernels
    from surfgen.pipelines.run.warmup import kernel_cached, warm_grid_kernel

    warm_grid_kernel()
    assert kernel_cached(kernels.run_grid)
    code = (
        "from surfgen.generator.eval import grid_driver as kernels, point_driver as points; "
        "from surfgen.pipelines.run.warmup import kernel_cached as c; "
        "print(c(kernels.run_grid), c(points.eval_points))"
    )
    fresh = subprocess.run(
        [sys.executable, "-c", code], env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)},
        capture_output=True, text=True, timeout=120, check=True,
    )  # fmt: skip
    assert fresh.stdout.split() == ["False", "False"]


NOTICE = "compiling surfgen's numba kernels"


def _commands(tmp_path):
    """Commands that evaluate with the fast evaluator, each on something small."""
    sphere = ["--formula", "x^2+y^2+z^2-r^2", "--box", "-1.2,1.2", "--grid", "12"]
    model = tmp_path / "model.json"  # a MathMod script: one sphere
    bounds = {f"{a}{m}": [f"{s}1.5"] for a in "XYZ" for m, s in (("min", "-"), ("max", ""))}
    fields = {"Name": ["Ball"], "Component": ["S"], "Fxyz": ["x^2+y^2+z^2-1"], "Grid": ["12"]}
    model.write_text(json.dumps({"Iso3D": {**fields, **bounds}}))
    return {
        "render": ["render", "--formula", "x^2+y^2+z^2-1", "--grid", "12", "-o", str(tmp_path / "a.ply")],
        "render --mathmod": ["render", "--mathmod", str(model), "-o", str(tmp_path / "b.ply")],
        "sweep": ["sweep", *sphere, "--param", "r=0.5:1.0:0.5", "-o", str(tmp_path / "sweep")],
    }  # fmt: skip


@pytest.mark.parametrize("cold", [True, False])
@pytest.mark.parametrize("command", ["render", "render --mathmod", "sweep"])
def test_commands_that_evaluate_say_when_they_compile_first(
    command, cold, monkeypatch, tmp_path, capsys
) -> None:
    from surfgen.pipelines.cli.main import main
    from surfgen.pipelines.run import warmup

    warm_ups: list[dict] = []
    monkeypatch.setattr(warmup, "grid_kernel_cached", lambda: not cold)
    monkeypatch.setattr(warmup, "_cpus", lambda: 2)
    monkeypatch.setattr(warmup, "warm_shape_kernels", lambda **kw: warm_ups.append(kw) or 0.0)
    assert main(_commands(tmp_path)[command]) == 0
    err = capsys.readouterr().err
    assert err.count(NOTICE) == (1 if cold else 0), err
    # cold, with a second CPU: every kernel first, on two processes (not one by one)
    assert warm_ups == ([{"parallel": True}] if cold else [])


def test_on_one_cpu_a_cold_command_compiles_as_it_goes(monkeypatch, tmp_path, capsys) -> None:
    from surfgen.pipelines.cli.main import main
    from surfgen.pipelines.run import warmup

    warm_ups: list[dict] = []
    monkeypatch.setattr(warmup, "grid_kernel_cached", lambda: False)
    monkeypatch.setattr(warmup, "_cpus", lambda: 1)
    monkeypatch.setattr(warmup, "warm_shape_kernels", lambda **kw: warm_ups.append(kw) or 0.0)
    assert main(_commands(tmp_path)["render"]) == 0
    assert capsys.readouterr().err.count(NOTICE) == 1 and warm_ups == []


def test_render_with_the_reference_evaluator_says_nothing(monkeypatch, tmp_path, capsys) -> None:
    from surfgen.pipelines.cli.main import main
    from surfgen.pipelines.run import warmup

    monkeypatch.setattr(warmup, "grid_kernel_cached", lambda: False)
    args = ["render", "--formula", "x^2+y^2+z^2-1", "--grid", "12", "--evaluator", "reference"]
    assert main([*args, "-o", str(tmp_path / "a.ply")]) == 0
    assert NOTICE not in capsys.readouterr().err


def test_reproduce_says_so_for_the_surfaces_only(monkeypatch, tmp_path, capsys) -> None:
    from surfgen.pipelines.cli.main import main
    from surfgen.pipelines.run import warmup
    from surfgen.pipelines.studies import reproduce

    monkeypatch.setattr(warmup, "grid_kernel_cached", lambda: False)
    assert main(["reproduce", "-o", str(tmp_path / "f1"), "--figure", "1"]) == 0
    assert NOTICE not in capsys.readouterr().err  # Figure 1 plots curves: nothing to compile

    def stop(*args, **kwargs):
        raise SurfgenError("stopped before the figures")

    monkeypatch.setattr(reproduce, "reproduce", stop)
    assert main(["reproduce", "-o", str(tmp_path / "f3"), "--figure", "3"]) == 1
    assert capsys.readouterr().err.count(NOTICE) == 1


def test_serve_says_the_explorer_compiles_in_the_background(monkeypatch, tmp_path, capsys) -> None:
    from surfgen.pipelines.cli import web as cli_web
    from surfgen.pipelines.run import warmup
    from surfgen.pipelines.web import app as web_app

    class Server:
        host, server_port = "127.0.0.1", 8123

        def serve_forever(self):
            raise KeyboardInterrupt

        def server_close(self):
            pass

    monkeypatch.setattr(web_app, "make_server", lambda *args: Server())
    monkeypatch.setattr(warmup, "grid_kernel_cached", lambda: False)
    cli_web.serve_cmd(tmp_path / "cat", 0, "127.0.0.1")
    err = capsys.readouterr().err
    assert err.count(NOTICE) == 1 and "in the background" in err


CHILD_ONLY = """
import json
from numba.core.registry import CPUDispatcher
from surfgen.generator.eval import interpreter, grid_driver as kernels
from surfgen.generator.mesh import marching, mesh, placement, refine, sparse_bricks, walls
from surfgen.pipelines.pictures import kernels as pictures
from surfgen.pipelines.run.warmup import warm_in_child

warm_in_child()
ran = {k: len(v.signatures) for m in (mesh, marching, placement) for k, v in vars(m).items()
       if isinstance(v, CPUDispatcher)}
print(json.dumps({"interpreter": interpreter.interpreter_loaded(),
                  "grid": len(kernels.run_grid.signatures),
                  "columns": len(kernels.run_columns.signatures),
                  "walls": len(refine._bisect_kernel.signatures), "mesh": sum(ran.values()),
                  "labels": len(walls._label_faces.signatures),
                  "sparse": len(sparse_bricks.raise_bricks.signatures),
                  "pictures": len(pictures._rasterise.signatures)}))
"""


def test_the_other_child_warms_every_kernel_but_the_first_childs() -> None:
    # what lets the warm-up compile them all beside the interpreter: the grid and walls'
    # kernels are compiled for their argument types, never run (they would call it)
    out = subprocess.run(
        [sys.executable, "-c", CHILD_ONLY], capture_output=True, text=True, timeout=600, check=True
    )
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["mesh"] >= 3 and result["walls"] == 1 and result["sparse"] >= 1
    assert result["labels"] == 1  # the faces labelled though the classification found no wall
    assert result["grid"] == 0 and result["columns"] == 0  # the first child's
    assert result["pictures"] == 0  # likewise
    assert result["interpreter"] is False


FIRST_ONLY = """
import json
from numba.core.registry import CPUDispatcher
from surfgen.generator.eval import interpreter, grid_driver as kernels
from surfgen.generator.mesh import marching, placement, refine, sparse_bricks, sparse_lewiner
from surfgen.pipelines.pictures import kernels as pictures
from surfgen.pipelines.run.warmup import warm_first_in_child

warm_first_in_child()
ran = {k: len(v.signatures) for m in (marching, placement, sparse_lewiner) for k, v in vars(m).items()
       if isinstance(v, CPUDispatcher)}
print(json.dumps({"interpreter": interpreter.interpreter_loaded(),
                  "grid": len(kernels.run_grid.signatures),
                  "columns": len(kernels.run_columns.signatures),
                  "pictures": len(pictures._rasterise.signatures),
                  "mesh": sum(ran.values()),
                  "sparse": len(sparse_bricks.raise_bricks.signatures),
                  "walls": len(refine._bisect_kernel.signatures)}))
"""


def test_the_first_child_warms_the_interpreter_the_grid_the_fine_band_and_the_pictures() -> None:
    # not the marching cubes, sparse or dense, or the walls (the other child's): were the
    # first child to mesh with them, both children might compile the same kernels
    out = subprocess.run(
        [sys.executable, "-c", FIRST_ONLY], capture_output=True, text=True, timeout=600, check=True
    )
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["interpreter"] is True
    assert result["grid"] >= 1 and result["columns"] >= 1 and result["pictures"] >= 1
    assert result["sparse"] == 0 and result["walls"] == 0 and result["mesh"] == 0


def test_compiled_not_run_compiles_for_the_arguments_and_runs_nothing() -> None:
    from numba import njit

    from surfgen.generator.eval import interpreter
    from surfgen.generator.eval.evaluate import compiled_not_run, grid_kernel

    @njit
    def fill(out, value):
        out[:] = value

    class Module:
        kernel = fill

    out, load, grid = np.zeros(3), interpreter.load_interpreter, grid_kernel()
    with compiled_not_run((Module, "kernel")):
        assert Module.kernel(out, 2.0) == 0
        assert grid_kernel() is not grid  # the grid kernel too: compiled, not run
        assert interpreter.load_interpreter() is None
    assert Module.kernel is fill and interpreter.load_interpreter is load
    assert grid_kernel() is grid
    assert len(fill.signatures) == 1 and not out.any()  # compiled, not run
    Module.kernel(out, 2.0)
    assert (out == 2.0).all() and len(fill.signatures) == 1


class _Spy:
    """Watches what the warm-up does with its child: the child's process, and whether this
    process ran the grid kernel while the child was still at work (it should not: the child
    compiles it) or after (with the child's exit code then)."""

    def __init__(self, monkeypatch) -> None:
        from surfgen.generator.eval import grid_driver as kernels
        from surfgen.pipelines.run import warmup

        self.children: list[subprocess.Popen] = []
        self.grid_runs_beside_child = 0
        self.loaded_after_child: list[int | None] = []
        popen, run_grid = subprocess.Popen, kernels.run_grid

        def start(*args, **kwargs):
            self.children.append(popen(*args, **kwargs))
            return self.children[-1]

        def grid(*args):
            if any(c.poll() is None for c in self.children):
                self.grid_runs_beside_child += 1
            elif self.children:
                self.loaded_after_child.append(self.children[-1].returncode)
            return run_grid(*args)

        monkeypatch.setattr(warmup.subprocess, "Popen", start)
        monkeypatch.setattr(kernels, "run_grid", grid)
        monkeypatch.setattr(warmup, "_kernels_cached", lambda: False)  # as on a new machine
        monkeypatch.setattr(warmup, "_cpus", lambda: 2)


def test_a_cold_cache_compiles_in_two_children_and_loads_here(monkeypatch) -> None:
    from surfgen.generator.eval import tape
    from surfgen.pipelines.run import warmup

    spy = _Spy(monkeypatch)
    interpreter_beside = []
    warm = tape.warm_interpreter

    def interpreter():  # loaded here once the first child has compiled it, never meanwhile
        interpreter_beside.append(spy.children[0].poll() is None)
        return warm()

    monkeypatch.setattr(tape, "warm_interpreter", interpreter)
    warmup.warm_shape_kernels()
    assert [c.args[-1] for c in spy.children] == [warmup._FIRST_CHILD, warmup._CHILD]
    assert [c.returncode for c in spy.children] == [0, 0]
    assert interpreter_beside == [False]
    assert spy.grid_runs_beside_child == 0  # the second child compiled the grid kernel
    assert spy.loaded_after_child[:1] == [0]  # loaded here once the children were done
    # one CPU, or parallel=False: no child, everything here as before
    runs = len(spy.loaded_after_child)
    warmup.warm_shape_kernels(parallel=False)
    monkeypatch.setattr("surfgen.pipelines.run.warmup._cpus", lambda: 1)
    warmup.warm_shape_kernels()
    assert len(spy.children) == 2 and len(spy.loaded_after_child) > runs


def test_a_failing_child_leaves_the_work_to_this_process(monkeypatch, caplog) -> None:
    from surfgen.pipelines.run import warmup

    spy = _Spy(monkeypatch)
    monkeypatch.setattr(warmup, "_CHILD", "import sys; sys.exit('no compiler here')")
    with caplog.at_level("DEBUG", logger="surfgen.pipelines.run.warmup"):
        warmup.warm_shape_kernels()
    assert [c.returncode for c in spy.children] == [0, 1]
    assert spy.loaded_after_child[:1] == [1]
    assert "no compiler here" in caplog.text


def test_an_interrupted_warm_up_leaves_no_child_behind(monkeypatch) -> None:
    from surfgen.pipelines.run import warmup

    spy = _Spy(monkeypatch)
    monkeypatch.setattr(warmup, "_CHILD", "import time; time.sleep(60)")

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("surfgen.generator.eval.tape.warm_interpreter", interrupted)  # Ctrl-C there
    t0 = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        warmup.warm_shape_kernels()
    assert all(c.returncode is not None for c in spy.children)  # the sleeper killed
    assert len(spy.children) == 2 and time.perf_counter() - t0 < 30


def test_cpus_counted_where_the_os_has_no_affinity(monkeypatch) -> None:
    from surfgen.pipelines.run import warmup

    if hasattr(os, "sched_getaffinity"):
        assert warmup._cpus() == len(os.sched_getaffinity(0))
        monkeypatch.delattr(os, "sched_getaffinity")  # as on macOS
    assert warmup._cpus() == (os.cpu_count() or 1)
