"""``surfgen export``: catalogued shapes, spec and mesh files out as clean, checked files."""

from __future__ import annotations

import json
import shlex
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
import trimesh

from surfgen.filters.cleanup import edge_lengths
from surfgen.filters.metrics import measure_mesh
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.mesh.exchange import load_mesh, save_mesh
from surfgen.generator.mesh.formats import EXPORT_FORMATS
from surfgen.generator.mesh.mesh import Mesh, extract_mesh
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.cli.main import main
from tests.support.catalogues import catalogue_shapes

TORUS = "(sqrt(x^2+y^2)-1)^2+z^2-0.16"


def torus_spec(index: int) -> SurfaceSpec:
    """The capped torus (cut by the box in x and y), one spec per ``index``."""
    return SurfaceSpec(
        formula=TORUS, box=(-1.2, 1.2) * 3, grid=(32, 32, 32), provenance={"index": index}
    )


@pytest.fixture(scope="module")
def catalogue(tmp_path_factory) -> tuple[Path, list[str]]:
    """A catalogue of three capped tori; the first two keys share their first hex digit."""
    root = tmp_path_factory.mktemp("catalogue")
    by_digit: dict[str, list[SurfaceSpec]] = defaultdict(list)
    index = 0
    while not any(len(v) >= 2 for v in by_digit.values()):
        spec = torus_spec(index)
        by_digit[spec.key[0]].append(spec)
        index += 1
    pair = next(v for v in by_digit.values() if len(v) >= 2)[:2]
    other = next(s for v in by_digit.values() for s in v if s.key[0] != pair[0].key[0])
    specs = [*pair, other]
    # Meshed as the sampler does (the default evaluator, caps), so a spec remeshes identically.
    mesh = extract_mesh(evaluate(specs[0].tree(), specs[0].to_grid()), cap=True)
    catalogue_shapes(root, [(spec, mesh) for spec in specs], seed=1, grid=32)
    return root, [s.key for s in specs]


def unique_prefix(keys: list[str], key: str) -> str:
    n = next(n for n in range(1, len(key)) if sum(k.startswith(key[:n]) for k in keys) == 1)
    return key[:n]


def export(*args: str | Path) -> int:
    return main(["export", *map(str, args)])


def read_back(path: Path) -> trimesh.Trimesh:
    return trimesh.load(path, force="mesh")


@pytest.mark.parametrize("fmt", EXPORT_FORMATS)
def test_capped_torus_exports_watertight_manifold_genus_1_in_every_format(catalogue, tmp_path, fmt):
    root, keys = catalogue
    prefix = unique_prefix(keys, keys[2])
    assert export(prefix, "--catalogue", root, "--format", fmt, "-o", tmp_path) == 0
    path = tmp_path / f"{keys[2]}.{fmt}"
    sidecar = json.loads((tmp_path / f"{keys[2]}.json").read_text())
    after = sidecar["metrics"]["after"]
    assert after["watertight"] and after["genus"] == 1
    assert after["nonmanifold_edges"] == 0 and after["nonmanifold_vertices"] == 0
    tm = read_back(path)
    assert len(tm.faces) == after["faces"]
    assert tm.is_watertight and tm.is_winding_consistent and tm.euler_number == 0
    m = measure_mesh(Mesh(tm.vertices, tm.faces))
    assert m.genus == 1 and m.components == 1 and m.volume > 0


def test_size_scales_the_longest_side_to_millimetres(catalogue, tmp_path):
    root, keys = catalogue
    assert export(keys[2], "--catalogue", root, "--size", "50", "-o", tmp_path) == 0
    tm = read_back(tmp_path / f"{keys[2]}.stl")
    assert np.ptp(tm.vertices, axis=0).max() == pytest.approx(50.0, abs=0.01)
    sidecar = json.loads((tmp_path / f"{keys[2]}.json").read_text())
    assert sidecar["units"] == "millimeter" and sidecar["steps"][-1]["step"] == "scale"
    assert sidecar["scale"] == pytest.approx(50.0 / 2.4, rel=1e-3)
    assert max(np.diff(sidecar["metrics"]["after"]["bbox"])[::2]) == pytest.approx(50.0)


def test_3mf_says_millimetres(catalogue, tmp_path):
    root, keys = catalogue
    assert export(keys[2], "--catalogue", root, "--format", "3mf", "-o", tmp_path) == 0
    assert read_back(tmp_path / f"{keys[2]}.3mf").units == "millimeter"


def test_remeshing_to_a_target_edge_in_millimetres(catalogue, tmp_path):
    root, keys = catalogue
    args = ["--size", "50", "--target-edge", "2.5", "--format", "ply"]
    assert export(keys[2], "--catalogue", root, *args, "-o", tmp_path) == 0
    mesh = load_mesh(tmp_path / f"{keys[2]}.ply")
    assert float(np.median(edge_lengths(mesh))) == pytest.approx(2.5, rel=0.2)
    m = measure_mesh(mesh)
    assert m.watertight and m.genus == 1


@pytest.fixture()
def open_surface(tmp_path) -> Path:
    """An uncapped sphere cut by the box: six open boundary loops."""
    spec = SurfaceSpec(formula="x^2+y^2+z^2-1", box=(-0.9, 0.9) * 3, grid=(24, 24, 24))
    mesh = extract_mesh(evaluate_reference(spec.tree(), spec.to_grid()), cap=False)
    return save_mesh(mesh, tmp_path / "open.ply")


def test_an_open_surface_is_refused_as_stl_and_written_with_force(open_surface, tmp_path, capsys):
    out = tmp_path / "out"
    assert export(open_surface, "--format", "stl", "-o", out) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("error: open: not printable as stl")
    assert "not watertight" in err and "boundary edges" in err and "--force" in err
    assert not out.exists()

    assert export(open_surface, "--format", "stl", "--force", "-o", out) == 0
    assert (out / "open.stl").is_file()
    sidecar = json.loads((out / "open.json").read_text())
    assert sidecar["problems"] and sidecar["spec"] is None and sidecar["key"] is None
    # Formats for rendering take open surfaces without --force.
    assert export(open_surface, "--format", "ply", "-o", tmp_path / "render") == 0


def test_unknown_key_is_a_one_line_error(catalogue, tmp_path, capsys):
    root, _ = catalogue
    assert export("0123456789abcdef", "--catalogue", root, "-o", tmp_path / "out") == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: no shape with key '0123456789abcdef'")
    assert not (tmp_path / "out").exists()


def test_ambiguous_prefix_is_a_one_line_error_listing_the_matches(catalogue, tmp_path, capsys):
    root, keys = catalogue
    assert export(keys[2], keys[0][0], "--catalogue", root, "-o", tmp_path / "out") == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "ambiguous" in err
    assert keys[0] in err and keys[1] in err
    assert not (tmp_path / "out").exists()  # the good key was not written either


def test_missing_catalogue_is_a_one_line_error(tmp_path, capsys):
    assert export("abc", "--catalogue", tmp_path / "none", "-o", tmp_path / "out") == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: no catalogue at")


def test_several_keys_give_several_files_and_sidecars(catalogue, tmp_path, capsys):
    root, keys = catalogue
    assert export(*keys, "--catalogue", root, "--format", "obj", "--json", "-o", tmp_path) == 0
    summary = json.loads(capsys.readouterr().out)
    assert [s["key"] for s in summary] == keys
    for key in keys:
        sidecar = json.loads((tmp_path / f"{key}.json").read_text())
        assert sidecar["key"] == key and sidecar["formula"] == TORUS
        assert SurfaceSpec.from_dict(sidecar["spec"]).key == key
        assert sidecar["metrics"]["before"]["faces"] > 0 and sidecar["metrics"]["after"]["faces"]
        assert [s["step"] for s in sidecar["steps"]][0] == "merge_close_vertices"
        assert sidecar["versions"]["pymeshlab"] and sidecar["options"]["format"] == "obj"
        assert sidecar["command"].startswith(f"surfgen export {key} --catalogue ")


def test_the_sidecar_reproduces_the_file(catalogue, tmp_path):
    root, keys = catalogue
    first, second, third = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    args = ["--remesh", "--smooth", "3", "--size", "40"]
    assert export(keys[2], "--catalogue", root, *args, "-o", first) == 0
    sidecar = json.loads((first / f"{keys[2]}.json").read_text())
    # Its command makes the same bytes again.
    command = shlex.split(sidecar["command"])
    assert command[:2] == ["surfgen", "export"] and command[-2:] == ["-o", str(first)]
    assert main([*command[1:-1], str(second)]) == 0
    assert (first / f"{keys[2]}.stl").read_bytes() == (second / f"{keys[2]}.stl").read_bytes()
    # It is also an input: its spec is meshed with caps as the catalogue's was (the catalogue's
    # PLY stores float32, hence approx).
    assert export(first / f"{keys[2]}.json", *args, "-o", third) == 0
    again = json.loads((third / f"{keys[2]}.json").read_text())["metrics"]["after"]
    assert again["faces"] == sidecar["metrics"]["after"]["faces"]
    assert again["volume"] == pytest.approx(sidecar["metrics"]["after"]["volume"], rel=1e-4)


def test_spec_file_and_regrid_warns(tmp_path, capsys):
    spec_file = tmp_path / "torus.json"
    spec_file.write_text(torus_spec(0).to_json())
    assert export(spec_file, "--regrid", "40", "-o", tmp_path / "out") == 0
    captured = capsys.readouterr()
    assert "warning: torus: re-evaluated on 40^3 instead of 32x32x32" in captured.err
    assert "Figure 3" in captured.err
    sidecar = json.loads((tmp_path / "out" / "torus.json").read_text())
    assert sidecar["options"]["regrid"] == 40 and sidecar["metrics"]["after"]["genus"] == 1
    assert "--regrid 40" in sidecar["command"]


def test_regrid_needs_a_formula(open_surface, tmp_path, capsys):
    assert export(open_surface, "--regrid", "40", "-o", tmp_path / "out") == 1
    assert "--regrid needs a formula" in capsys.readouterr().err


def test_an_export_never_overwrites_its_input(tmp_path, capsys):
    spec_file = tmp_path / "torus.json"
    spec_file.write_text(torus_spec(0).to_json())
    assert export(spec_file, "-o", tmp_path) == 1
    assert "would overwrite its own input" in capsys.readouterr().err
    assert SurfaceSpec.from_json(spec_file.read_text()) == torus_spec(0)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--format", "step"], "unknown format 'step'"),
        (["--size", "-3"], "--size must be a positive number"),
        (["--target-edge", "1", "--target-faces", "100"], "not both"),
    ],
)
def test_bad_options_are_one_line_errors(tmp_path, capsys, args, message):
    spec_file = tmp_path / "torus.json"
    spec_file.write_text(torus_spec(0).to_json())
    assert export(spec_file, *args, "-o", tmp_path / "out") == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err


def test_the_commands_default_is_the_cleanups() -> None:
    # export_cli states min_component's default without importing the cleanup (pymeshlab)
    from surfgen.filters.cleanup import CleanupOptions
    from surfgen.pipelines.cli.export import MIN_COMPONENT

    assert CleanupOptions().min_component == MIN_COMPONENT
