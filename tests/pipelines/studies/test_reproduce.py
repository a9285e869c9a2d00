"""`surfgen reproduce` on small grids: every file, the table, and the verdicts on Figures 3, 4."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from surfgen.pipelines.cli.main import main
from surfgen.pipelines.studies.reproduce import (
    CLAIMS,
    PANELS,
    READINGS,
    SENSITIVITY_HIGH,
    eq_a_float32,
    reproduce,
    scaled_grid,
)


@pytest.fixture(scope="module")
def figures_3_4(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Figure 3 at the paper's grids (34³, 33³: already small), Figure 4 at half its grid."""
    out = tmp_path_factory.mktemp("paper")
    reproduce(out / "f3", figures=[3])
    reproduce(out / "f4", figures=[4], grid_scale=0.5)
    return out


def test_every_panel_is_written_open_and_capped(figures_3_4: Path) -> None:
    for fig, folder in ((3, "f3"), (4, "f4")):
        for name in PANELS[fig]:
            for suffix in ("", "-capped"):
                for ext in ("png", "ply"):
                    path = figures_3_4 / folder / f"figure{fig}" / f"{name}{suffix}.{ext}"
                    assert path.stat().st_size > 1000, path
        assert (figures_3_4 / folder / "report.html").exists()


def test_figure_3_shapes_are_significantly_different_as_the_paper_says(figures_3_4: Path) -> None:
    s = json.loads((figures_3_4 / "f3" / "sensitivity.json").read_text())
    pairs = {(p["a"], p["b"]): p for p in s["pairs"]}
    assert set(pairs) == {("I3", "I4"), ("I3", "I5"), ("I4", "I5")}
    for p in pairs.values():
        assert p["verdict"] == "reproduced"
        assert p["sensitivity"] > SENSITIVITY_HIGH
        assert p["relative_change"] < 0.035  # box 7 -> 7.05, grid 34 -> 33
    # the shapes themselves: same formula, three samplings, three different meshes
    faces = {n: s["shapes"][n]["faces"] for n in ("I3", "I4", "I5")}
    assert len(set(faces.values())) == 3
    assert s["shapes"]["I5"]["nonfinite"] > 0  # the odd grid samples the 0/0 at the origin


def test_figure_4_neighbours_change_less_than_the_ends(figures_3_4: Path) -> None:
    s = json.loads((figures_3_4 / "f4" / "sensitivity.json").read_text())
    assert [(p["a"], p["b"]) for p in s["pairs"]] == [
        ("C-m0.25", "C-m0.5"),
        ("C-m0.5", "C-m0.75"),
        ("C-m0.75", "C-m1"),
    ]
    for p in s["pairs"]:
        assert p["relative_change"] > 0.2  # m in steps of 0.25
        assert p["sensitivity"] == pytest.approx((1 - p["iou"]) / p["relative_change"], abs=2e-3)
        assert p["verdict"] == "reproduced"  # low sensitivity, as the paper says
    # m from 0.25 to 1 deforms one shape continuously: one component each
    assert all(s["shapes"][n]["components"] == 1 for n in PANELS[4])


def test_the_report_lists_every_claim(figures_3_4: Path) -> None:
    page = (figures_3_4 / "f3" / "report.html").read_text()
    assert page.count("data:image/png;base64,") == 6
    assert page.count("<td class='ok'>reproduced</td>") == 3


def test_figure_2_readings_at_a_small_grid(tmp_path: Path) -> None:
    result = reproduce(tmp_path, figures=[2], grid_scale=0.25)
    s = result.sensitivity
    assert [r["reading"] for r in s["figure2_readings"]] == [r.name for r in READINGS]
    literal = s["figure2_readings"][0]
    assert literal["found"] == "low"  # as printed, m hardly matters
    assert [c.figure for c in CLAIMS].count(2) == 1
    for r in s["figure2_readings"]:
        folder = tmp_path / "figure2" / "readings" / r["reading"]
        assert folder.is_dir()


def test_float32_reading_matches_double_precision_to_single_precision() -> None:
    from surfgen.generator.eval.evaluate import evaluate
    from surfgen.generator.model.presets import get_preset

    spec = get_preset("I1").spec().replace(grid=(12, 12, 12))
    f64 = evaluate(spec.tree(), spec.to_grid(), spec.params).values
    f32 = eq_a_float32(0.851, spec.to_grid())
    import numpy as np

    both = np.isfinite(f64) & np.isfinite(f32)
    assert both.mean() > 0.9
    assert np.allclose(f32[both], f64[both], rtol=1e-3, atol=1e-2 * np.abs(f64[both]).max())


def test_scaled_grids_have_a_floor() -> None:
    assert scaled_grid(82, 0.5) == 41
    assert scaled_grid(34, 0.01) == 8


def test_cli_errors_are_one_line(tmp_path: Path, capsys) -> None:
    def error_of(args: list[str]) -> str:
        assert main(["reproduce", *args]) != 0
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("error: "), err
        return err[0]

    msg = error_of(["-o", str(tmp_path / "x"), "--figure", "5"])
    assert msg == "error: unknown figure 5 (figures: 1, 2, 3, 4)"
    assert "grid-scale" in error_of(["-o", str(tmp_path / "y"), "--grid-scale", "0"])
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()
    afile = tmp_path / "file"
    afile.write_text("")
    assert "not a folder" in error_of(["-o", str(afile), "--figure", "1"])


def test_cli_figure_1_alone(tmp_path: Path, capsys) -> None:
    assert main(["reproduce", "-o", str(tmp_path), "--figure", "1"]) == 0
    assert (tmp_path / "figure1.png").stat().st_size > 10000
    assert "report.html" in capsys.readouterr().out
