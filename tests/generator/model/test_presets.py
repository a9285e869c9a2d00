"""The paper's examples: transcription, and their sensitivity to parameters and to the grid."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.filters.metrics import measure_mesh
from surfgen.generator.errors import SpecError
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.mesh.mesh import extract_mesh
from surfgen.generator.model.presets import PRESETS, get_preset

# Independent transcriptions, written straight from the paper with numpy.


def eq_a(x, y, z, m, outer=0.3):
    ax_, ay_, az_ = np.abs(x), np.abs(y), np.abs(z)
    den = np.abs(ax_**1.3 + ay_**1.3 + az_**1.3)

    def a(u):
        return np.arctan(np.tan(1 - u**0.31 + 5.76 * u**1.38 / den)) ** 3

    def b(u, v):
        return (u**0.3 / np.abs(1 / np.tan(m * v))) ** outer

    return (
        (ax_**3.3 + ay_**3.3 + az_**3.3 - 600)
        + (a(ax_) + a(ay_) + a(az_)) ** 3
        - 0.51 * (b(ax_, x) + b(ay_, y) + b(az_, z)) ** 3
        + 100
    )


def eq_b(x, y, z):
    alpha = (
        (1 / 24.4)
        * (x**2 + y**2 + z**2 - 5)
        * (np.abs(x) ** 0.13 * np.abs(y) ** 0.13 * np.abs(z) ** 0.13 - 5)
    )
    sec = 1 / np.cos(0.1 * y)
    bx = (
        np.abs(np.cos(2 * x))
        * np.arctan(np.tan(12 * (x**2 + np.abs(y) ** 2 + z**2) / (x**2 * y**2 + z**2))) ** 2
        * sec
    )
    by = (
        np.abs(np.cos(2 * y))
        * np.arctan(np.tan(12 * (y**2 + np.abs(z) ** 2 + x**2) / (x**2 + y**2 * z**2))) ** 2
        * sec
    )
    bz = (
        np.abs(np.cos(2 * z))
        * np.arctan(np.tan(12 * (z**2 + np.abs(x) ** 2 + y**2) / (y**2 + x**2 * z**2))) ** 2
        * sec
    )
    return alpha + (bx + by + bz) ** 3 - 0.135


def eq_c(x, y, z, m):
    first = (np.abs(np.cos(0.7 * m * x**-1.0)) / np.cos(0.003 * x**2)) ** 10
    second = (np.abs(np.sin(0.7 * m * y)) ** 10 * np.abs(np.sin(0.7 * m * z)) ** 10) / (
        np.cos(0.003 * y**2) ** 10 * np.cos(0.003 * z**2) ** 10
    )
    return first + second - 0.02 * (x**3 + y**2 + z**2)


def independent(name: str):
    p = PRESETS[name]
    spec = p.spec()
    x, y, z = spec.to_grid().open_axes()
    with np.errstate(all="ignore"):
        if p.formula == PRESETS["eqA"].formula:
            v = eq_a(x, y, z, spec.params["m"])
        elif p.formula == PRESETS["I1-b1"].formula:
            v = eq_a(x, y, z, spec.params["m"], outer=1.0)
        elif p.formula == PRESETS["eqB"].formula:
            v = eq_b(x, y, z)
        else:
            v = eq_c(x, y, z, spec.params["m"])
    return np.broadcast_to(v, spec.grid)


PAPER = [
    "eqA",
    "I1",
    "I2",
    "I1-b1",
    "I2-b1",
    "eqB",
    "I3",
    "I4",
    "I5",
    "eqC",
    "C-m0.25",
    "C-m0.5",
    "C-m0.75",
    "C-m1",
]


def assert_same_field(got: np.ndarray, want: np.ndarray) -> None:
    assert got.shape == want.shape
    np.testing.assert_array_equal(np.isfinite(got), np.isfinite(want))
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    fin = np.isfinite(want)
    # The transcription computes with numpy's ufuncs, the evaluators with surfgen's own
    # functions (each within an ulp or two): near F = 0 the sums cancel, so the tolerance is
    # relative to the field's magnitude (the size of its partial results), not to each value.
    scale = float(np.abs(want[fin]).max()) if fin.any() else 0.0
    np.testing.assert_allclose(got[fin], want[fin], rtol=1e-12, atol=1e-12 * scale)


@pytest.mark.parametrize("name", PAPER)
def test_paper_presets_equal_independent_transcription(name: str) -> None:
    spec = PRESETS[name].spec()
    field = evaluate_reference(spec.tree(), spec.to_grid(), spec.params)
    assert_same_field(field.values, independent(name))


def test_figure_settings_are_the_papers() -> None:
    assert PRESETS["I1"].params["m"] == 0.851 and PRESETS["I2"].params["m"] == 0.861
    assert PRESETS["eqA"].box == (-155.0, 155.0) * 3 and PRESETS["eqA"].grid == (82, 82, 82)
    assert PRESETS["I3"].box == (-7.0, 7.0) * 3 and PRESETS["I3"].grid == (34, 34, 34)
    assert PRESETS["I4"].box == (-7.05, 7.05) * 3 and PRESETS["I4"].grid == (34, 34, 34)
    assert PRESETS["I5"].box == (-7.05, 7.05) * 3 and PRESETS["I5"].grid == (33, 33, 33)
    assert [PRESETS[f"C-m{m}"].params["m"] for m in ("0.25", "0.5", "0.75", "1")] == [
        0.25,
        0.5,
        0.75,
        1.0,
    ]


def test_equation_b_keeps_the_printed_oddities() -> None:
    f = PRESETS["eqB"].spec().formula
    assert f.count("cos(0.1*y)^(-1)") == 3  # every beta divides by cos(0.1 y), as printed
    assert "x^2*y^2+z^2" in f and "x^2+y^2*z^2" in f and "y^2+x^2*z^2" in f


def _mesh_signature(name: str):
    spec = PRESETS[name].spec()
    mesh = extract_mesh(evaluate_reference(spec.tree(), spec.to_grid(), spec.params), cap=True)
    m = measure_mesh(mesh)
    return m.faces, m.components, m.genus


def test_equation_b_is_sensitive_to_box_and_grid() -> None:
    """Figure 3: I3 (±7, 34³), I4 (±7.05, 34³) and I5 (±7.05, 33³) are different shapes."""
    sigs = {name: _mesh_signature(name) for name in ("I3", "I4", "I5")}
    assert len(set(sigs.values())) == 3, sigs
    # The odd grid of I5 samples the origin, where every beta is 0/0: non-finite samples.
    i5 = PRESETS["I5"].spec()
    assert evaluate_reference(i5.tree(), i5.to_grid()).nonfinite > 0
    i4 = PRESETS["I4"].spec()
    assert evaluate_reference(i4.tree(), i4.to_grid()).nonfinite == 0


def test_equation_a_fields_differ_between_i1_and_i2() -> None:
    """Figure 2: m = 0.851 vs 0.861 moves the poles of cot(m x) across the 82-point grid."""
    a, b = (PRESETS[n].spec() for n in ("I1", "I2"))
    fa = evaluate_reference(a.tree(), a.to_grid(), a.params).values
    fb = evaluate_reference(b.tree(), b.to_grid(), b.params).values
    changed = np.abs(fa - fb) > 1e-6 * np.maximum(np.abs(fa), 1)
    assert changed.mean() > 0.5


def test_equation_c_changes_smoothly_with_m() -> None:
    """Figure 4 (low sensitivity): neighbouring m change few signs; m=0.25 vs 1 changes more."""
    signs = {}
    for m in ("0.25", "0.5", "0.75", "1"):
        s = PRESETS[f"C-m{m}"].spec()
        signs[m] = evaluate_reference(s.tree(), s.to_grid(), s.params).values < 0
    step = np.mean(signs["0.75"] != signs["1"])
    far = np.mean(signs["0.25"] != signs["1"])
    assert 0 < step < far


def test_unknown_preset_and_parameter() -> None:
    with pytest.raises(SpecError, match="unknown preset 'eqZ'"):
        get_preset("eqZ")
    with pytest.raises(SpecError, match="has no parameter 'q'"):
        get_preset("eqA").spec({"q": 1.0})


def test_classic_surfaces_have_a_surface() -> None:
    for name in ("sphere", "torus", "gyroid", "klein", "clebsch", "schwarz", "chmutov"):
        spec = PRESETS[name].spec()
        v = evaluate_reference(spec.tree(), spec.to_grid()).values
        assert (v < 0).any() and (v > 0).any(), name


def test_figure_2_reading_b1_makes_i1_and_i2_differ() -> None:
    """As printed, m = 0.851 and 0.861 give the same lump; with B = |x|^0.3/|cot(m x)| the
    walls at the zeros of cot(m x) are sampled differently and the insides differ."""

    def inside(name: str) -> np.ndarray:
        spec = PRESETS[name].spec()
        v = evaluate_reference(spec.tree(), spec.to_grid(), spec.params).values
        return np.isfinite(v) & (v < 0)

    lit1, lit2 = inside("I1"), inside("I2")
    assert np.array_equal(lit1, lit2)
    b1, b2 = inside("I1-b1"), inside("I2-b1")
    iou = (b1 & b2).sum() / (b1 | b2).sum()
    assert iou < 0.5 and min(b1.sum(), b2.sum()) > 10 * lit1.sum()
