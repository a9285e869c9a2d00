"""`surfgen render`, `check`, `presets`, `config show`: results and one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.model.presets import PRESETS
from surfgen.pipelines.cli.main import main
from tests.support.commands import CHECK_KEYS, heavy_modules_loaded

CANONICAL = {
    # name: (formula, box, grid, components, genus)
    "sphere": ("x^2+y^2+z^2-1", "-1.5,1.5", "32", 1, 0),
    "torus": ("(sqrt(x^2+y^2)-1)^2+z^2-0.16", "-1.6,1.6", "40", 1, 1),
    "genus2": ("(x^2*(1-x^2)-y^2)^2+z^2-0.04", "-1.3,1.3", "40", 1, 2),
    "two_spheres": (
        "min((x-1)^2+y^2+z^2-0.5,(x+1)^2+y^2+z^2-0.5)",
        "-2.2,2.2,-1.2,1.2,-1.2,1.2",
        "44,24,24",
        2,
        0,
    ),
    # a sphere cut by the box: --cap closes it
    "cut_sphere": ("x^2+y^2+z^2-1", "-0.8,0.8", "24", 1, 0),
}


def run_json(args: list[str], capsys) -> dict:
    assert main(args) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("name", sorted(CANONICAL))
def test_render_cap_then_check_gives_components_and_genus(
    name: str, tmp_path: Path, capsys
) -> None:
    formula, box, grid, components, genus = CANONICAL[name]
    mesh = tmp_path / f"{name}.ply"
    r = run_json(
        [
            "render",
            "--formula",
            formula,
            "--box",
            box,
            "--grid",
            grid,
            "--cap",
            "-o",
            str(mesh),
            "--json",
        ],
        capsys,
    )
    assert r["faces"] > 0 and r["nonfinite"] == 0
    c = run_json(["check", str(mesh), "--json"], capsys)
    assert set(c) >= set(CHECK_KEYS)
    assert c["watertight"] is True and c["boundary_edges"] == 0
    assert c["nonmanifold_edges"] == 0 and c["nonmanifold_vertices"] == 0
    assert (c["components"], c["genus"]) == (components, genus)
    assert c["euler"] == 2 * components - 2 * genus * components
    assert c["volume"] > 0


def test_render_json_keys_and_field_file(tmp_path: Path, capsys) -> None:
    field = tmp_path / "f.npy"
    r = run_json(["render", "--preset", "I5", "--save-field", str(field), "--json"], capsys)
    for key in (
        "formula",
        "box",
        "grid",
        "level",
        "params",
        "vertices",
        "faces",
        "nonfinite",
        "seconds",
    ):
        assert key in r
    assert r["box"] == [-7.05, 7.05] * 3 and r["grid"] == [33, 33, 33]
    assert r["faces"] is None  # --save-field without -o: no mesh is extracted
    values = np.load(field)
    spec = PRESETS["I5"].spec()
    want = evaluate_reference(spec.tree(), spec.to_grid()).values
    assert values.dtype == np.float64 and values.shape == (33, 33, 33)
    np.testing.assert_array_equal(np.isnan(values), np.isnan(want))
    fin = np.isfinite(want)
    np.testing.assert_allclose(values[fin], want[fin], rtol=1e-12)
    assert r["nonfinite"] == int((~np.isfinite(want)).sum()) > 0


def test_render_params_and_grid_overrides(capsys) -> None:
    r = run_json(
        [
            "render",
            "--preset",
            "eqC",
            "--param",
            "m=0.5",
            "--grid",
            "20,22,24",
            "--box",
            "-5,5",
            "--json",
        ],
        capsys,
    )
    assert r["params"] == {"m": 0.5} and r["grid"] == [20, 22, 24] and r["box"] == [-5.0, 5.0] * 3


def test_spec_file_round_trip(tmp_path: Path, capsys) -> None:
    spec = tmp_path / "s.json"
    spec.write_text(PRESETS["torus"].spec().replace(grid=(24, 24, 24)).to_json())
    r = run_json(["render", "--spec", str(spec), "--json"], capsys)
    assert r["formula"] == PRESETS["torus"].spec().formula and r["faces"] > 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["render", "--formula", "sinn(x)"],
            "unknown function 'sinn' at column 1 (did you mean sin?)",
        ),
        (["render", "--formula", "x + (y"], "unbalanced parentheses"),
        (["render", "--formula", "x + y)"], "unbalanced parentheses"),
        (["render", "--formula", "sin(x, y)"], "sin takes 1 argument, got 2"),
        (["render", "--formula", "   "], "empty formula"),
        (["render", "--formula", "x + q"], "unknown variable 'q' at column 5"),
        (["render", "--formula", "x^2+y^2+z^2+5"], "no surface"),
        (["render", "--preset", "nope"], "unknown preset 'nope'"),
        (["render", "--preset", "eqA", "--param", "q=1"], "has no parameter 'q'"),
        (["render", "--preset", "eqA", "--param", "m"], "--param takes NAME=VALUE"),
        (["render", "--preset", "sphere", "--grid", "3"], "grid: Nx must be a whole number from 4"),
        (["render", "--preset", "sphere", "--grid", "a,b"], "--grid must be whole numbers"),
        (["render", "--preset", "sphere", "--box", "1,-1"], "xmin must be less than xmax"),
        (["render", "--preset", "sphere", "--box", "1,2,3"], "--box takes 2 or 6 values"),
        (["render", "--preset", "sphere", "--box", "0,1e308"], "must lie within ±1000000"),
        (["render", "--preset", "sphere", "--box", "-1e308,1e308"], "must lie within ±1000000"),
        (
            ["render", "--preset", "sphere", "--box", "999999,1000000"],
            "too fine for mesh files",
        ),
        (
            ["render", "--preset", "sphere", "--formula", "x"],
            "exactly one of --preset, --formula, --spec or --from",
        ),
        (["render"], "exactly one of --preset, --formula, --spec or --from"),
        (["render", "--spec", "/nonexistent.json"], "cannot read spec file"),
        (["render", "--preset", "sphere", "--evaluator", "magic"], "unknown evaluator 'magic'"),
        (["check", "/nonexistent.ply"], "/nonexistent.ply"),
    ],
)
def test_bad_input_one_line_error_and_no_output(args, message, tmp_path: Path, capsys) -> None:
    out = tmp_path / "mesh.ply"
    extra = ["-o", str(out)] if args[0] == "render" else []
    assert main([*args, *extra]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and message in err[0], err
    assert list(tmp_path.iterdir()) == []  # no partial output file


def test_bad_output_paths_fail_before_work(tmp_path: Path, capsys) -> None:
    assert main(["render", "--preset", "sphere", "-o", str(tmp_path / "m.xyz")]) == 1
    assert "unknown format '.xyz'" in capsys.readouterr().err
    assert main(["render", "--preset", "sphere", "-o", str(tmp_path / "no" / "m.ply")]) == 1
    assert "does not exist" in capsys.readouterr().err


def test_bad_spec_file(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text('{"formula": "x", "box": [0, 1], "grid": 8, "colour": 1}')
    assert main(["render", "--spec", str(bad)]) == 1
    assert "unknown key 'colour'" in capsys.readouterr().err
    bad.write_text("{not json")
    assert main(["render", "--spec", str(bad)]) == 1
    assert "not valid JSON" in capsys.readouterr().err


def test_presets_listing(capsys) -> None:
    rows = run_json(["presets", "--json"], capsys)
    names = [r["name"] for r in rows]
    for name in (
        "eqA",
        "eqB",
        "eqC",
        "I1",
        "I2",
        "I3",
        "I4",
        "I5",
        "C-m0.25",
        "C-m0.5",
        "C-m0.75",
        "C-m1",
        "sphere",
        "torus",
        "gyroid",
        "klein",
        "clebsch",
        "schwarz",
        "chmutov",
    ):
        assert name in names
    assert main(["presets"]) == 0
    assert "I5" in capsys.readouterr().out


def test_config_show_is_the_default_toml(capsys) -> None:
    import tomllib

    assert main(["config", "show"]) == 0
    data = tomllib.loads(capsys.readouterr().out)
    assert set(data) == {"run", "sampler", "filters"}


def test_render_png_and_every_mesh_format(tmp_path: Path, capsys) -> None:
    for suffix in (".ply", ".obj", ".stl", ".off", ".glb"):
        out = tmp_path / f"t{suffix}"
        assert main(["render", "--preset", "torus", "--grid", "24", "-o", str(out)]) == 0
        capsys.readouterr()
        c = run_json(["check", str(out), "--json"], capsys)
        assert c["genus"] == 1, suffix
    png = tmp_path / "t.png"
    assert main(["render", "--preset", "torus", "--grid", "24", "--png", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_constituents_command(tmp_path: Path, capsys) -> None:
    out = tmp_path / "constituents.png"
    assert main(["plot", "constituents", "-o", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["plot", "constituents", "-o", str(tmp_path / "c.jpg")]) == 1
    assert "unknown format '.jpg'" in capsys.readouterr().err


def test_cut_presets_are_capped_unless_asked_not_to(tmp_path: Path, capsys) -> None:
    capped, open_ = tmp_path / "capped.ply", tmp_path / "open.ply"
    assert main(["render", "--preset", "gyroid", "--grid", "24", "-o", str(capped)]) == 0
    assert main(["render", "--preset", "gyroid", "--grid", "24", "--no-cap", "-o", str(open_)]) == 0
    capsys.readouterr()
    assert run_json(["check", str(capped), "--json"], capsys)["watertight"] is True
    assert run_json(["check", str(open_), "--json"], capsys)["watertight"] is False


def test_help_and_unknown_commands(capsys) -> None:
    assert main([]) == 0
    assert "Commands:" in capsys.readouterr().out
    assert main(["nonsense"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No such command 'nonsense'" in err[0] and "sample" in err[0]


def test_version_names_surfgen_python_and_the_libraries(capsys) -> None:
    import platform
    from importlib import metadata

    from surfgen.generator import __version__

    assert main(["--version"]) == 0
    first, second = capsys.readouterr().out.strip().splitlines()
    assert first == f"surfgen {__version__}" == f"surfgen {metadata.version('surfgen')}"
    assert second.startswith(f"python {platform.python_version()}, numpy {np.__version__}, ")
    import numba
    import trimesh

    assert f"numba {numba.__version__}" in second and f"trimesh {trimesh.__version__}" in second
    assert main(["--version", "nonsense"]) == 0  # eager: it answers before anything else


# A Ctrl-C can land inside a constructor (one of llvmlite's while numba loads a kernel, say):
# the half-built object's destructor fails when it is collected, after the one-line message.
_INTERRUPTED_SAMPLE = """
import surfgen.pipelines.run.sampling as sampling
from surfgen.pipelines.cli.main import main

class HalfBuilt:
    def __del__(self):
        raise AttributeError("'HalfBuilt' object has no attribute '_as_parameter_'")

def run_sample(**kwargs):
    half = HalfBuilt()  # freed with the interrupt's traceback, after the message
    raise KeyboardInterrupt

sampling.run_sample = run_sample
raise SystemExit(main(["sample", "--n", "1", "--out", {out!r}]))
"""


def _interrupted(script: str, tmp_path: Path) -> subprocess.CompletedProcess:
    """``script`` (a ``sample`` whose run is replaced) in a fresh process; it must end with an
    interrupt's exit code."""
    code = script.format(out=str(tmp_path / "cat"))
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 130, done.stderr
    return done


def test_an_interrupted_sample_ends_on_its_one_line_message(tmp_path: Path) -> None:
    done = _interrupted(_INTERRUPTED_SAMPLE, tmp_path)
    lines = done.stderr.strip().splitlines()
    assert lines[-1].startswith("interrupted: what was catalogued is kept"), done.stderr
    assert "Exception ignored" not in done.stderr and "_as_parameter_" not in done.stderr


_WRAPPED_INTERRUPT = """
import surfgen.pipelines.run.sampling as sampling
from surfgen.pipelines.cli.main import main

def run_sample(**kwargs):
    class Lazy:  # a Ctrl-C inside a class body's __set_name__, as in a lazy import of numba's
        class Name:
            def __set_name__(self, owner, name):
                raise KeyboardInterrupt
        attr = Name()

sampling.run_sample = run_sample
raise SystemExit(main(["sample", "--n", "1", "--out", {out!r}]))
"""


def test_a_ctrl_c_python_wrapped_still_ends_on_the_one_line_message(tmp_path: Path) -> None:
    done = _interrupted(_WRAPPED_INTERRUPT, tmp_path)
    assert done.stderr.strip().splitlines()[-1].startswith("interrupted: what was catalogued")
    assert "Traceback" not in done.stderr


def test_from_interrupt_follows_the_chain_only_to_a_ctrl_c() -> None:
    from surfgen.pipelines.cli.common import from_interrupt

    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as cause:
            raise RuntimeError("Error calling __set_name__") from cause
    except RuntimeError as exc:
        wrapped = exc
    assert from_interrupt(wrapped) and from_interrupt(KeyboardInterrupt())
    assert not from_interrupt(RuntimeError("a bug")) and not from_interrupt(ValueError())
    looped = RuntimeError("loop")
    looped.__context__ = RuntimeError("other")
    looped.__context__.__context__ = looped  # a cycle ends the walk
    assert not from_interrupt(looped)


def test_main_turns_a_wrapped_ctrl_c_into_interrupted(monkeypatch, capsys) -> None:
    from surfgen.pipelines.cli import main as cli

    def app(**kwargs):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as cause:
            raise RuntimeError("Error calling __set_name__") from cause

    monkeypatch.setattr(sys, "unraisablehook", sys.unraisablehook)  # restored afterwards
    monkeypatch.setattr(cli, "app", app)
    assert cli.main(["presets"]) == 130
    assert capsys.readouterr().err.strip() == "interrupted"

    def bug(**kwargs):
        raise RuntimeError("a bug")

    monkeypatch.setattr(cli, "app", bug)
    with pytest.raises(RuntimeError, match="a bug"):
        cli.main(["presets"])


def test_after_an_interrupt_a_failing_destructor_is_logged_not_printed(
    monkeypatch, capsys, caplog
) -> None:
    import logging

    from surfgen.pipelines.cli import common

    monkeypatch.setattr(sys, "unraisablehook", sys.unraisablehook)  # restored afterwards

    class HalfBuilt:
        def __del__(self):
            raise AttributeError("half-built")

    common.quiet_after_interrupt()
    with caplog.at_level(logging.DEBUG, logger="surfgen.pipelines.cli.common"):
        half = HalfBuilt()
        del half
    assert "half-built" not in capsys.readouterr().err
    assert "after the interrupt" in caplog.text and "half-built" in caplog.text


def test_commands_that_compute_nothing_load_no_kernel_library(tmp_path: Path) -> None:
    # (the catalogue commands: tests/pipelines/test_curation.py)
    commands = [("--help",), ("--version",), ("export", "--help"), ("sample", "--help")]
    commands += [("presets",)]
    for args in [*commands, ("config", "show")]:
        assert heavy_modules_loaded(*args) == [], args
    # and the check can fail: a command that checks a mesh loads them (trimesh only when a
    # file is read: this one is missing)
    assert "numba" in heavy_modules_loaded("check", str(tmp_path / "none.ply"))
