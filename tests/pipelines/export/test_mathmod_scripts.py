"""MathMod scripts: every key of the Iso3D format, the CLI, and export -> import round trips."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from surfgen.filters.metrics import measure_mesh
from surfgen.generator.errors import SpecError
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.formula.parser import parse
from surfgen.generator.interop.builtins import expand_builtins
from surfgen.generator.interop.mathmod import build_model, load_model, parse_script
from surfgen.generator.mesh.exchange import load_mesh
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.cli.main import main
from surfgen.pipelines.export.mathmod_scripts import import_script, render_model


def iso(**fields) -> dict:
    base = {
        "Name": ["Shape"],
        "Component": ["S"],
        "Fxyz": ["x^2+y^2+z^2-1"],
        **{k: [v] for k, v in (("Xmin", "-1.5"), ("Xmax", "1.5"), ("Ymin", "-1.5"))},
        **{k: [v] for k, v in (("Ymax", "1.5"), ("Zmin", "-1.5"), ("Zmax", "1.5"))},
        "Grid": ["24"],
    }
    base.update(fields)
    return {"Iso3D": base}


def write(tmp_path: Path, doc: dict | str, name: str = "script.json") -> Path:
    path = tmp_path / name
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return path


def field_of(spec: SurfaceSpec) -> np.ndarray:
    return evaluate(spec.tree(), spec.to_grid(), spec.params).values


def test_minimal_model_is_the_formula_in_its_box() -> None:
    model = load_model(parse_script(json.dumps(iso())))
    (comp,) = model.components
    assert comp.spec.formula == "x^2+y^2+z^2-1"
    assert comp.spec.box == (-1.5, 1.5) * 3 and comp.spec.grid == (24, 24, 24)


def test_constants_functions_redefinition_and_time() -> None:
    doc = iso(
        Const=["r = (1/4)*(1+3*sqrt(5))", "c = r*2"],
        Funct=["f1=x^2+y^2+z^2-c", "f2 = f1(x,y,z,t)+t*0.1", "f2=f2(2*x,y,z,t)"],
        Fxyz=["f2(x,y,z,t)"],
        Xmax=["c"],
    )
    model = build_model(parse_script(json.dumps(doc))[0], params={"t": 3.0})
    spec = model.components[0].spec
    r = (1 / 4) * (1 + 3 * np.sqrt(5))
    assert spec.params == {"c": pytest.approx(2 * r), "t": 3.0}
    assert parse(spec.formula, ["c", "t"]) == parse("(2*x)^2+y^2+z^2-c+t*0.1", ["c", "t"])
    assert spec.box[1] == pytest.approx(2 * r)


def test_recursion_and_unknown_function_are_clean_errors() -> None:
    with pytest.raises(SpecError, match="calls itself"):
        build_model(iso(Funct=["g=g(x,y,z,t)+1"], Fxyz=["g(x,y,z,t)"]))
    with pytest.raises(SpecError, match="unknown function 'h'"):
        build_model(iso(Funct=["g=h(x,y,z,t)+1"], Fxyz=["g(x,y,z,t)"]))


def test_condition_makes_samples_outside() -> None:
    model = build_model(iso(Cnd=["z>0"]))
    spec = model.components[0].spec
    values = field_of(spec)
    z = spec.to_grid().axes()[2]
    assert np.isnan(values[:, :, z < 0]).all() and np.isfinite(values[:, :, z > 0]).all()
    mesh = render_model(model)
    assert mesh["faces"] > 100


def test_if_clipped_blend_renders_and_matches_its_pieces() -> None:
    doc = iso(Fxyz=["if(x^2+y^2+z^2<1.2, x^4+y^4+z^4-0.5, 1)"])
    spec = build_model(doc).components[0].spec
    values = field_of(spec)
    x, y, z = spec.to_grid().open_axes()
    r2 = x**2 + y**2 + z**2
    want = np.where(r2 < 1.2 - 1e-12, x**4 + y**4 + z**4 - 0.5, 1.0)
    np.testing.assert_allclose(values, np.broadcast_to(want, values.shape), rtol=1e-14)


def test_components_render_into_one_mesh_and_can_be_picked(tmp_path: Path) -> None:
    doc = iso(
        Component=["A", "B"],
        Fxyz=["x^2+y^2+z^2-1", "(x-4)^2+y^2+z^2-1"],
        Xmin=["-1.5", "2.5"],
        Xmax=["1.5", "5.5"],
    )
    model = build_model(doc)
    out = tmp_path / "both.ply"
    summary = render_model(model, mesh_path=out)
    assert measure_mesh(load_mesh(out)).components == 2
    assert len(summary["components"]) == 2
    one = render_model(model, component="B")
    assert one["faces"] == summary["components"][1]["faces"]
    with pytest.raises(SpecError, match="no component 'C'"):
        render_model(model, component="C")


def test_sliders_choose_a_set() -> None:
    doc = {**iso(Fxyz=["x^2+y^2+z^2-A"])}
    doc["Sliders"] = {"Name": ["A"], "Position": ["1", "0.5"], "Min": ["0"], "Max": ["2"],
                      "Step": ["0.1"], "SetNames": ["one", "half"]}  # fmt: skip
    assert build_model(doc).components[0].spec.params == {"A": 1.0}
    assert build_model(doc, slider_set=1).components[0].spec.params == {"A": 0.5}
    with pytest.raises(SpecError, match="slider sets 0 to 1"):
        build_model(doc, slider_set=2)


def test_collections_names_and_parametric_models() -> None:
    coll = {"MathModels": [{"Param3D": {"Name": ["Tube"]}}, iso(Name=["Ball"])]}
    models = parse_script(json.dumps(coll))
    assert load_model(models).name == "Ball"
    with pytest.raises(SpecError, match="not supported: model Tube is a parametric Param3D"):
        load_model(models, "Tube")
    with pytest.raises(SpecError, match=r"no model 'Cube' in the script \(models: Tube, Ball\)"):
        load_model(models, "Cube")


def test_texture_is_a_notice_and_description_is_kept() -> None:
    doc = {**iso(Description=["A round thing"]), "Texture": {"Colors": ["R=1"]}}
    model = build_model(doc)
    assert model.notices == ("ignored: Texture (colour formulas)",)
    assert model.components[0].spec.provenance["description"] == "A round thing"


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ("{not json", "not valid JSON"),
        ("[1, 2]", "a MathMod script is a JSON object"),
        (iso(Fxyz=["NoiseW(x,y,z,1,2,0)"]), "not supported: NoiseW"),
        (iso(Fxyz=["x+CmpId(0)"]), "not supported: CmpId"),
        (iso(Xmin=["abc"]), "Xmin: unknown variable 'abc'"),
        (iso(Xmin=["x"]), "must not depend on x, y or z"),
        (iso(Xmin=["2"]), "xmin must be less than xmax"),
        (iso(Import=["something.so"]), "not supported: Import"),
        (iso(Vect=["v=[1,2]"]), "not supported: Vect"),
        (iso(Fxyz=[]), "has no Fxyz formula"),
        (iso(Const=["3 = x"]), "is not 'name = expression'"),
        (iso(Grid=["many"]), "Grid 'many' is not a whole number"),
    ],
)
def test_bad_scripts_are_one_line_errors(
    tmp_path: Path, capsys, doc: dict | str, message: str
) -> None:
    path = write(tmp_path, doc)
    out = tmp_path / "out.ply"
    assert main(["render", "--mathmod", str(path), "-o", str(out)]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and message in err[0], err
    assert not out.exists()


def test_cli_render_and_import(tmp_path: Path, capsys) -> None:
    doc = {"MathModels": [iso(Name=["Ball"]), {**iso(Name=["Cube"], Fxyz=["x^8+y^8+z^8-1"])}]}
    path = write(tmp_path, doc)
    assert main(["render", "--mathmod", str(path), "--name", "Cube", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["model"] == "Cube" and summary["faces"] > 100
    assert main(["import", "mathmod", str(path), "-o", str(tmp_path / "specs")]) == 0
    assert capsys.readouterr().out.count("wrote ") == 2
    files = sorted(p.name for p in (tmp_path / "specs").iterdir())
    assert files == ["Ball.json", "Cube.json"]
    assert main(["render", "--spec", str(tmp_path / "specs" / "Cube.json"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["faces"] == summary["faces"]


CONSTITUENT_FORMULA = (
    "saw1(x,0.5,4)+tri1(y,0.7,3)*stair1(z,0.3,0.2,5)+rect1(x,0.3)+rect2(y,1.5,0.4)"
    "+rect3(z,0.25)+saw2(x,m)+tri2(y,0.9)+tri3(z,1.1)+stair2(x*y,0.5,0.3)"
    "+fcc(x,0,0,1,2,3,-1)+fcc8(y*3+5)+sign(z)+acot(x)-m"
)


def test_builtins_are_written_exactly_in_standard_functions() -> None:
    tree = parse(CONSTITUENT_FORMULA, ["m"])
    plain = expand_builtins(tree, {"m": 0.7})
    names = {n.op for n in _walk(plain)}
    assert not names & {"saw1", "tri1", "stair1", "rect1", "rect2", "rect3", "saw2", "acot"}
    spec = SurfaceSpec(CONSTITUENT_FORMULA, (-3.0, 3.0) * 3, (21, 19, 17), {"m": 0.7})
    other = spec.replace(formula=str(plain))
    a, b = field_of(spec), field_of(other)
    assert np.array_equal(a.view(np.int64), b.view(np.int64))


def _walk(tree):
    stack = [tree]
    while stack:
        n = stack.pop()
        yield n
        stack.extend(n.args)


def test_export_then_import_gives_the_same_field(tmp_path: Path, capsys) -> None:
    spec = SurfaceSpec(
        CONSTITUENT_FORMULA, (-3.0, 3.0, -2.0, 2.5, -1.0, 3.0), (20, 18, 16), {"m": 0.7}
    )
    spec_file = write(tmp_path, spec.to_json(), "shape.json")
    out = tmp_path / "scripts"
    assert main(["export", str(spec_file), "--format", "mathmod", "-o", str(out)]) == 0
    assert main(["export", str(spec_file), "--format", "k3dsurf", "-o", str(out)]) == 0
    capsys.readouterr()
    script = out / "shape.mathmod.json"
    k3d = (out / "shape.k3dsurf.txt").read_text()
    assert "F(x,y,z) = " in k3d and "saw1" not in k3d and "Grid = [20, 18, 16]" in k3d
    (back,) = import_script(script, tmp_path / "back")
    again = SurfaceSpec.from_json(back.read_text())
    assert again.box == spec.box and again.params == {"m": 0.7}
    a, b = field_of(spec), field_of(again.replace(grid=spec.grid))
    assert np.array_equal(a.view(np.int64), b.view(np.int64))


def test_export_of_a_mesh_file_is_refused(tmp_path: Path, capsys) -> None:
    mesh = tmp_path / "m.ply"
    mesh.write_text("ply\n")
    assert main(["export", str(mesh), "--format", "mathmod", "-o", str(tmp_path / "o")]) != 0
    assert "a mesh file has no formula" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
