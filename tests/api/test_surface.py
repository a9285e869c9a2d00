"""surfgen.Surface: its constructors and their errors, field, mesh, metrics, check and reprs."""

from __future__ import annotations

import dataclasses
import json
import math
import pickle
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image

import surfgen
from surfgen import Surface
from surfgen.generator.mesh.realise import realise
from surfgen.generator.model.presets import get_preset
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.run.config import Config, load_config

SPHERE = "x^2+y^2+z^2-1"
TORUS = "(sqrt(x^2+y^2)-1)^2+z^2-0.16"


@pytest.fixture(scope="module")
def sphere() -> Surface:
    return Surface.from_formula(SPHERE, box=(-1.5, 1.5), grid=32)


def test_from_formula_is_the_spec_render_builds(sphere: Surface) -> None:
    assert sphere.formula == SPHERE and sphere.grid == (32, 32, 32)
    assert sphere.box == (-1.5, 1.5) * 3 and sphere.level == 0.0 and not sphere.cap
    spec = SurfaceSpec(SPHERE, box=(-1.5, 1.5) * 3, grid=(32, 32, 32))
    assert sphere.spec == spec and sphere.key == spec.key and sphere.to_json() == spec.to_json()
    # defaults: render's --box -2,2 --grid 64
    assert Surface.from_formula(SPHERE).spec == SurfaceSpec(SPHERE, (-2, 2) * 3, (64, 64, 64))
    odd = Surface.from_formula("x^2+y^2+z^2-r^2", grid=(20, 21, 22), params={"r": 1.2}, level=0.1)
    assert odd.grid == (20, 21, 22) and odd.params == {"r": 1.2} and odd.level == 0.1


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"formula": "sinn(x)"}, surfgen.FormulaSyntaxError, "unknown function 'sinn' at column"),
        ({"formula": "x+a"}, surfgen.FormulaSyntaxError, "unknown variable 'a' at column 3"),
        ({"formula": "x", "params": {"b": 1}}, surfgen.SpecError, "parameter 'b' is not used"),
        ({"formula": "x", "grid": 1}, surfgen.GridError, "grid"),
        ({"formula": "x", "grid": (8, 8)}, surfgen.SurfgenError, "grid"),
        ({"formula": "x", "box": (1, 1)}, surfgen.GridError, "box"),
    ],
)
def test_from_formula_errors_are_the_cli_s(kwargs: dict, error: type, message: str) -> None:
    formula = kwargs.pop("formula")
    with pytest.raises(error, match=message):
        Surface.from_formula(formula, **kwargs)


def test_from_preset_keeps_the_preset_s_cap_and_takes_overrides() -> None:
    i3 = Surface.from_preset("I3")
    assert i3.spec == get_preset("I3").spec() and i3.cap == get_preset("I3").cap
    assert i3.provenance == {"preset": "I3"}
    torus = Surface.from_preset("torus", grid=24, cap=True)
    assert torus.grid == (24, 24, 24) and torus.cap
    with pytest.raises(surfgen.SpecError, match=r"unknown preset 'nope' \(presets: eqA"):
        Surface.from_preset("nope")
    with pytest.raises(surfgen.SpecError, match="has no parameter 'zz'"):
        Surface.from_preset("torus", params={"zz": 1.0})
    assert "torus" in surfgen.presets()


MATHMOD = {
    "Iso3D": {
        "Name": ["Two"],
        "Component": ["ball", "cube"],
        "Fxyz": ["x^2+y^2+z^2-1", "x^4+y^4+z^4-1"],
        "Xmin": ["-2", "-2"],
        "Xmax": ["2", "2"],
        "Ymin": ["-2", "-2"],
        "Ymax": ["2", "2"],
        "Zmin": ["-2", "-2"],
        "Zmax": ["2", "2"],
    }
}


def test_from_mathmod_reads_files_text_and_dicts(tmp_path: Path) -> None:
    path = tmp_path / "two.json"
    path.write_text(json.dumps(MATHMOD))
    ball = Surface.from_mathmod(path, component="ball", grid=24)
    assert ball.formula == SPHERE and ball.grid == (24, 24, 24)
    assert Surface.from_mathmod(json.dumps(MATHMOD), component="1").formula == "x^4+y^4+z^4-1"
    assert Surface.from_mathmod(MATHMOD, component="ball", grid=24) == ball
    with pytest.raises(
        surfgen.SpecError, match=r"has 2 components \(ball, cube\): give component="
    ):
        Surface.from_mathmod(MATHMOD)
    with pytest.raises(surfgen.SpecError, match="no component 'egg'"):
        Surface.from_mathmod(MATHMOD, component="egg")
    with pytest.raises(surfgen.SpecError, match="no model 'Other'"):
        Surface.from_mathmod(MATHMOD, name="Other", component="ball")


def test_from_spec_takes_specs_dicts_json_and_files(sphere: Surface, tmp_path: Path) -> None:
    path = tmp_path / "s.json"
    path.write_text(sphere.to_json())
    for source in (sphere.spec, sphere.to_dict(), sphere.to_json(), path, str(path)):
        assert Surface.from_spec(source) == sphere
    with pytest.raises(surfgen.SpecError, match="spec: missing key 'box'"):
        Surface.from_spec({"formula": "x", "grid": 8})


def test_surfaces_pickle(sphere: Surface) -> None:
    copy = pickle.loads(pickle.dumps(sphere))
    assert copy == sphere and copy.key == sphere.key and copy.cap == sphere.cap
    drawn = surfgen.draw(7, 3, grid=16)
    again = pickle.loads(pickle.dumps(drawn))
    assert again == drawn and again.family == drawn.family and again.config == drawn.config


def test_with_grid_changes_the_key_and_keeps_the_rest(sphere: Surface) -> None:
    fine = sphere.with_grid(40)
    assert fine.grid == (40, 40, 40) and fine.key != sphere.key and fine.formula == sphere.formula
    assert fine.with_grid((32, 32, 32)) == sphere and hash(fine.with_grid(32)) == hash(sphere)


def test_field_is_the_formula_on_the_grid(sphere: Surface) -> None:
    values = sphere.field()
    assert values.shape == (32, 32, 32) and values.dtype == np.float64
    x = np.linspace(-1.5, 1.5, 32)  # both ends included
    expected = x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2 - 1
    np.testing.assert_allclose(values, expected, rtol=0, atol=1e-12)
    assert sphere.field(grid=(5, 6, 7)).shape == (5, 6, 7)
    np.testing.assert_array_equal(sphere.field(evaluator="reference"), values)


def test_mesh_is_a_trimesh_with_its_facts(sphere: Surface) -> None:
    mesh = sphere.mesh()
    assert isinstance(mesh, trimesh.Trimesh) and mesh.is_watertight
    assert mesh.metadata["key"] == sphere.key and mesh.metadata["formula"] == SPHERE
    assert mesh.metadata["spec"] == sphere.to_dict()
    assert math.isclose(mesh.volume, 4 / 3 * math.pi, rel_tol=0.02)
    assert mesh.euler_number == 2
    made = realise(sphere.spec).mesh  # the one path: the same vertices and faces
    np.testing.assert_array_equal(mesh.vertices, made.vertices)
    np.testing.assert_array_equal(mesh.faces, made.faces)
    finer = sphere.mesh(grid=40)
    assert finer.metadata["key"] == sphere.with_grid(40).key and len(finer.faces) > len(mesh.faces)


def test_mesh_caps_and_walls() -> None:
    cut = Surface.from_formula("x^2+y^2-1", box=(-1.5, 1.5), grid=24)  # a cylinder the box cuts
    assert not cut.mesh().is_watertight
    assert cut.mesh(cap=True).is_watertight and cut.mesh(cap=True).metadata["cap"] is True
    pole = Surface.from_formula("tan(x)", box=(-2, 2), grid=24)  # a root and two poles
    marked = pole.mesh(walls="mark")
    kinds = marked.face_attributes["kind"]
    assert set(np.unique(kinds)) >= {0, 1} and 0 < marked.metadata["wall_fraction"] < 1
    assert len(pole.mesh(walls="remove").faces) < len(marked.faces)
    with pytest.raises(surfgen.SpecError, match="unknown --walls mode 'gone'"):
        pole.mesh(walls="gone")  # type: ignore[arg-type]


def test_an_empty_surface_raises_and_still_shows() -> None:
    empty = Surface.from_formula("x^2+y^2+z^2+1", grid=16)
    with pytest.raises(surfgen.EmptySurface):
        empty.mesh()
    assert empty._repr_png_() is None
    assert "no picture" in empty._repr_html_() and empty.key in empty._repr_html_()


def test_metrics_are_the_catalogue_s(sphere: Surface) -> None:
    m = sphere.metrics()
    assert m["genus"] == 0 and m["components"] == 1 and m["watertight"] is True
    assert m["nonfinite"] == 0 and m["wall_fraction"] == 0.0 and m["box_fraction"] == 0.0
    assert math.isclose(m["total_curvature"], 1.0, rel_tol=1e-6)  # convex: Gauss-Bonnet
    assert m["symmetry"] == 48 and m["free_standing"] is True
    torus = Surface.from_formula(TORUS, box=(-1.6, 1.6), grid=32).metrics()
    assert torus["genus"] == 1 and torus["euler"] == 0


def test_check_is_the_sampler_s_verdict(sphere: Surface) -> None:
    blob = sphere.check()
    assert not blob and blob.reasons == ("blob",) and "rejected: blob" in repr(blob)
    assert blob.metrics["genus"] == 0  # measured all the way (the blob test is the last)
    tanglecube = Surface.from_formula(
        "x^4-5*x^2+y^4-5*y^2+z^4-5*z^2+11.8", box=(-2.5, 2.5), grid=32, cap=True
    )
    verdict = tanglecube.check()
    assert verdict.accepted and verdict.reasons == () and verdict.metrics["genus"] == 5
    gyroid = Surface.from_formula("sin(x)*cos(y)+sin(y)*cos(z)+sin(z)*cos(x)", box=(-5, 5))
    # open sheets: judged as the surface meshes (uncapped)...
    assert gyroid.with_grid(32).check().accepted
    capped = Surface.from_formula(gyroid.formula, box=(-5, 5), grid=32, cap=True)
    assert capped.check().reasons == ("box_dominated",)  # ...capped, mostly the box's faces
    noise = Surface.from_formula("sin(40*x)*sin(40*y)*sin(40*z)", grid=24).check()
    assert noise.reasons == ("noise",) and noise.metrics == {}  # stopped at the coarse field
    strict = tanglecube.check(_config(max_genus=1))
    assert strict.reasons == ("too_complex",)


def _config(**filters: float) -> Config:
    """The default config with these ``[filters]`` thresholds."""
    cfg = load_config()
    return Config(cfg.run, cfg.sampler, dataclasses.replace(cfg.filters, **filters))


def test_thumbnail_and_reprs(sphere: Surface) -> None:
    image = sphere.thumbnail(size=64)
    assert isinstance(image, Image.Image) and image.size == (64, 64) and image.mode == "RGB"
    assert len(np.unique(np.asarray(image).reshape(-1, 3), axis=0)) > 10  # shaded, not blank
    png = sphere._repr_png_()
    assert png is not None and png.startswith(b"\x89PNG")
    page = sphere._repr_html_()
    assert sphere.key in page and "data:image/png;base64," in page and "formula" in page
    text = repr(sphere)
    assert text.startswith("Surface(key='") and sphere.key in text and SPHERE in text
    long = Surface.from_formula("+".join(f"sin({k}*x)" for k in range(1, 30)) + "+y+z")
    assert "..." in repr(long) and len(repr(long)) < 200


def test_only_the_pictures_keep_a_mesh() -> None:
    surface = Surface.from_formula(SPHERE, box=(-1.5, 1.5), grid=16)
    first = surface.mesh()
    assert surface._made == {}  # a data loader holding many surfaces holds no fields
    surface.thumbnail(32)
    assert len(surface._made) == 1  # shown twice in a notebook (PNG, HTML), made once
    np.testing.assert_array_equal(surface.mesh().vertices, first.vertices)
    assert pickle.loads(pickle.dumps(surface))._made == {}


def test_a_mesh_beyond_the_memory_is_refused_before_it_is_made(monkeypatch) -> None:
    """As ``render``: the estimate first (a dense 2048^3 grid), then a sparse run's own checks
    (equation B's foam passes the estimate, which counts a typical surface, and is refused
    once its cells are counted), each a LimitError naming the limit."""
    from surfgen.generator.formula import limits

    with pytest.raises(limits.LimitError, match=r"fast evaluator\) needs about 464.0 GiB") as e:
        Surface.from_preset("sphere").mesh(grid=2048, evaluator="fast")
    assert str(e.value).endswith("(the available memory); use a smaller grid")
    monkeypatch.setattr(limits, "available_memory", lambda: 600 << 20)
    foam = Surface.from_preset("eqB")
    with pytest.raises(limits.LimitError, match="meshing the .* cells the surface crosses"):
        foam.mesh(grid=256, evaluator="sparse")
    monkeypatch.undo()
    assert len(foam.mesh(grid=48, evaluator="sparse").faces) > 0
