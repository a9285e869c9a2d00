"""Shape quality: symmetry measured on the mesh, solidity, departure from the envelope, plain."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from surfgen.filters import geometry, metrics, shape
from surfgen.filters.metrics import measure_mesh
from surfgen.filters.shape import (
    mesh_symmetries,
    quality_metrics,
    solidity,
    symmetry_metrics,
)
from surfgen.filters.verdict import FilterConfig, judge
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import extract_mesh
from surfgen.generator.model.families.carving import envelope_departure

GRID = 40


def mesh_of(formula: str, half: float = 1.6, n: int = GRID):
    field = evaluate(parse(formula), Grid(Box.cube(half), (n,) * 3), evaluator="reference")
    return extract_mesh(field, cap=True)


def test_sphere_has_every_permutation_and_mirror() -> None:
    m = symmetry_metrics(mesh_of("x^2+y^2+z^2-1"))
    assert m["symmetry"] == 48
    assert m["symmetry_permutations"] == 6 and m["symmetry_mirrors"] == 3


def test_a_cyclic_shape_has_only_the_cyclic_symmetry() -> None:
    # x y^2 + y z^2 + z x^2 is unchanged by x -> y -> z -> x, by nothing else of the 48
    m = symmetry_metrics(mesh_of("x^2+y^2+z^2-1+0.6*(x*y^2+y*z^2+z*x^2)"))
    assert m["symmetries"].split() == ["xyz", "yzx", "zxy"]
    assert (m["symmetry"], m["symmetry_permutations"], m["symmetry_mirrors"]) == (3, 3, 0)


def test_an_asymmetric_shape_has_only_the_identity() -> None:
    found = mesh_symmetries(mesh_of("x^2+y^2+z^2-1+0.5*x*y^2+0.4*y*z^3+0.3*x*z+0.2*z"))
    assert found == ["xyz"]


def test_symmetry_is_measured_about_the_shape_not_the_box() -> None:
    # an off-centre ellipsoid stretched along z keeps the x <-> y swap and the three mirrors
    m = symmetry_metrics(mesh_of("(x-0.3)^2+(y-0.3)^2+(z/1.3+0.2)^2-0.8", half=2.0))
    assert m["symmetry_permutations"] == 2 and m["symmetry_mirrors"] == 3
    assert "yxz" in m["symmetries"].split() and "zyx" not in m["symmetries"].split()


def test_solidity_of_a_sphere_and_a_torus() -> None:
    sphere = mesh_of("x^2+y^2+z^2-1")
    torus = mesh_of("(sqrt(x^2+y^2)-1)^2+z^2-0.16")
    s = solidity(sphere, measure_mesh(sphere).volume)
    t = solidity(torus, measure_mesh(torus).volume)
    assert s == pytest.approx(1.0, abs=0.03)
    # 2 pi^2 R r^2 = 3.16 inside a hull of about 4.4 (a rounded disc of radius 1.4, height 0.8)
    assert 0.6 < t < 0.8
    assert solidity(sphere, None) is None


def test_quality_metrics_of_a_free_and_a_cut_shape() -> None:
    sphere = mesh_of("x^2+y^2+z^2-1")
    m = measure_mesh(sphere).to_dict() | {"box_fraction": 0.0}
    q = quality_metrics(sphere, m)
    assert q["free_standing"] is True and q["symmetry"] == 48
    q = quality_metrics(sphere, m | {"box_fraction": 0.2})
    assert q["free_standing"] is False


def _fields(bump: float, n: int = GRID):
    ax = np.linspace(-1.6, 1.6, n)
    x, y, z = np.meshgrid(ax, ax, ax, indexing="ij")
    envelope = x**2 + y**2 + z**2 - 1
    # a Gaussian bump (or dent) of height ~bump on the +x pole
    mark = bump * np.exp(-((x - 1) ** 2 + y**2 + z**2) / 0.02)
    return envelope + mark, envelope


def test_a_sphere_with_a_tiny_bump_is_plain_and_a_carved_one_is_not() -> None:
    cfg = FilterConfig()
    carved_values, envelope = _fields(0.0)
    ax = np.linspace(-1.6, 1.6, GRID)
    x, y, z = np.meshgrid(ax, ax, ax, indexing="ij")
    carved_values = envelope + 0.8 * np.sin(5 * x) * np.sin(5 * y) * np.sin(5 * z)
    tiny = envelope_departure(_fields(0.3)[0], envelope)
    shrunk = envelope_departure(envelope + 0.3, envelope)  # the same shape, smaller
    carved = envelope_departure(carved_values, envelope)
    assert tiny < cfg.plain_max_departure and shrunk < 0.05
    assert carved > 2 * cfg.plain_max_departure
    base = {"faces": 5000, "components": 1, "largest_component_fraction": 1.0, "box_fraction": 0.0}
    assert judge(base | {"departure": tiny}, cfg, capped=True).reasons == ("plain",)
    assert judge(base | {"departure": carved}, cfg, capped=True).accepted
    assert judge(base, cfg, capped=True).accepted  # no envelope: never plain


def test_column_bounds_has_one_signature_from_the_metrics_and_the_symmetries(monkeypatch) -> None:
    """The metrics read the mesh's (read-only) vertices, the symmetry check a cloud it made:
    both hand the kernel a read-only array, so numba compiles it once."""
    seen = []

    def spy(a, mask):
        seen.append(numba.typeof(a))
        return geometry.column_bounds(a, mask)

    monkeypatch.setattr(metrics, "column_bounds", spy)
    monkeypatch.setattr(shape, "column_bounds", spy)
    m = mesh_of("x^2+y^2+z^2-1")
    measure_mesh(m)
    assert mesh_symmetries(m)[0] == "xyz"
    assert len(seen) >= 3 and len(set(seen)) == 1 and not seen[0].mutable
