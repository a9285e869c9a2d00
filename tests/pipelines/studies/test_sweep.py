"""Tests for surfgen.pipelines.studies.sweep: ranges, the files of a sweep, and distances that must grow."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.cli.main import main
from surfgen.pipelines.studies.sweep import (
    SweepError,
    iou,
    mesh_distances,
    parse_range,
    sweep_specs,
)


def cli(capsys, *args: str) -> tuple[int, str, str]:
    rc = main(list(args))
    out, err = capsys.readouterr()
    return rc, out, err


def test_parse_range() -> None:
    assert parse_range("m=0.25:1:0.25") == ("m", [0.25, 0.5, 0.75, 1.0])
    assert parse_range("box=2:1:-0.5") == ("box", [2.0, 1.5, 1.0])
    assert parse_range("grid=32:40:4") == ("grid", [32.0, 36.0, 40.0])
    assert parse_range("#3=0.1:0.35:0.1") == ("#3", [0.1, 0.2, 0.3])  # stop between steps
    for bad, what in [
        ("m=1:2", "NAME=START:STOP:STEP"),
        ("m=1:2:0", "does not lead"),
        ("m=2:1:0.5", "does not lead"),
        ("m=a:2:1", "must be numbers"),
        ("m=0:1000:1", "a sweep has 2 to 200"),
        ("grid=32:33:0.5", "whole numbers"),
    ]:
        with pytest.raises(SweepError, match=what):
            parse_range(bad)


def test_iou_and_distances() -> None:
    a = np.zeros((4, 4, 4), dtype=bool)
    b = a.copy()
    a[:2], b[1:3] = True, True
    assert (
        iou(a, b) == pytest.approx(1 / 3) and iou(a, a) == 1.0 and iou(a & False, b & False) == 1.0
    )
    p = np.array([[0.0, 0, 0], [1, 0, 0]])
    assert mesh_distances(p, p + [0, 0.5, 0]) == (0.5, 0.5)
    assert mesh_distances(p, np.empty((0, 3))) == (None, None)


def test_sweep_of_growing_spheres(capsys, tmp_path) -> None:
    """Spheres of radius 0.4..1.0: every file is written, each step is 0.2 from the previous one,
    and the distance from the first step grows with the radius, as must the inside."""
    out = tmp_path / "sweep"
    rc, stdout, err = cli(
        capsys, "sweep", "--formula", "x^2+y^2+z^2-r^2", "--param", "r=0.4:1.0:0.2",
        "--box", "-1.2,1.2", "--grid", "32", "-o", str(out),
    )  # fmt: skip
    assert rc == 0, err
    assert "wrote 4 steps" in stdout
    data = json.loads((out / "sweep.json").read_text())
    steps = data["steps"]
    assert data["param"] == "r" and [s["value"] for s in steps] == [0.4, 0.6, 0.8, 1.0]
    for s in steps:
        assert (out / s["mesh"]).is_file() and (out / s["frame"]).is_file()
        assert (s["components"], s["genus"]) == (1, 0)
    assert all(a["faces"] < b["faces"] for a, b in zip(steps[:-1], steps[1:], strict=True))
    assert steps[0]["distance_prev"] is None and steps[0]["iou_first"] == 1.0
    for s in steps[1:]:
        assert s["distance_prev"] == pytest.approx(0.2, abs=0.02)
        assert 0.2 <= s["hausdorff_prev"] < 0.3
    first = [s["distance_first"] for s in steps]
    assert all(a < b for a, b in zip(first[:-1], first[1:], strict=True))
    overlap = [s["iou_first"] for s in steps]
    assert all(a > b for a, b in zip(overlap[:-1], overlap[1:], strict=True))
    # nested balls: IoU is the volume ratio (r0 / r)^3, up to the grid
    assert steps[-1]["iou_first"] == pytest.approx(0.4**3, abs=0.02)
    with Image.open(out / "sweep.gif") as gif:
        assert gif.n_frames == 4
    with Image.open(out / "contact-sheet.png") as sheet:
        assert sheet.width > 4 * 256
    assert (out / "distance.png").stat().st_size > 10_000


def test_sweep_of_grid_and_box(capsys, tmp_path) -> None:
    """Figure 3's effect as a sweep: equation B on 33³ and 34³ gives different shapes."""
    out = tmp_path / "grid"
    rc, _, err = cli(capsys, "sweep", "--preset", "eqB", "--param", "grid=33:34:1", "-o", str(out))
    assert rc == 0, err
    steps = json.loads((out / "sweep.json").read_text())["steps"]
    assert [s["grid"] for s in steps] == [[33] * 3, [34] * 3]
    assert steps[0]["faces"] != steps[1]["faces"] and steps[1]["iou_prev"] < 0.9
    specs = sweep_specs(SurfaceSpec("x^2+y^2+z^2-1", (-2.0, 2.0) * 3, (16,) * 3), "box", [1.5, 2.5])
    assert [s.box for s in specs] == [(-1.5, 1.5) * 3, (-2.5, 2.5) * 3]


def test_sweep_refusals_write_nothing(capsys, tmp_path) -> None:
    out = tmp_path / "never"
    rc, _, err = cli(capsys, "sweep", "--preset", "eqC", "--param", "q=1:2:1", "-o", str(out))
    assert rc == 1 and err.startswith("error: unknown change 'q'") and "m, box, grid" in err
    rc, _, err = cli(capsys, "sweep", "--preset", "sphere", "--param", "grid=2:4:1", "-o", str(out))
    assert rc == 1 and "from 4 to" in err and err.count("\n") == 1
    rc, _, err = cli(capsys, "sweep", "--preset", "sphere", "--param", "m=1", "-o", str(out))
    assert rc == 1 and "NAME=START:STOP:STEP" in err
    assert not out.exists()


def test_sweep_memory_is_checked_before_and_as_each_step_learns_its_size(capsys, tmp_path):
    """The estimate of every step (the field, the mesh and a sparse field's dense sign proxy)
    before anything runs; then equation B's foam, which the bounds cannot prune, is checked
    again as its sparse mesh learns its size. Each refusal one line, nothing written."""
    out = tmp_path / "never"
    args = ["sweep", "--preset", "eqB", "--grid", "256", "--param", "d=0:0.1:0.05", "-o", out]
    rc, _, err = cli(capsys, *map(str, args), "--max-memory", "300M")
    assert rc == 1 and err.count("\n") == 1
    assert err.startswith("error: sweep step on a 256x256x256 grid needs about 459.5 MiB")
    assert "sign proxy 128.0 MiB" in err and "limit of 300.0 MiB (--max-memory sets it)" in err
    rc, _, err = cli(capsys, *map(str, args), "--max-memory", "700M")
    assert rc == 1 and err.count("\n") == 1
    assert err.startswith("error: sweep step on a 256x256x256 grid: meshing the 4,730,018 cells "
                          "the surface crosses needs about 1.8 GiB more")  # fmt: skip
    assert not out.exists()
