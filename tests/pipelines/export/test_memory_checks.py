"""``render`` and ``export --regrid`` check their memory again once a sparse run knows the
surface's size: a space-filling surface (equation B's foam) passes the estimate made before the
run, which assumes a typical one, and is refused in one line before its mesh is made, with
nothing written."""

from __future__ import annotations

import json
from pathlib import Path

from surfgen.generator.formula.limits import (
    CLEANUP_MESH_COPIES,
    SPARSE_BYTES_PER_MIXED_CELL,
    format_bytes,
)
from surfgen.generator.model.presets import PRESETS
from surfgen.pipelines.cli.main import main
from surfgen.pipelines.export.meshes import ExportOptions, export_shapes


def one_line_error(args: list[str], capsys) -> str:
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert rc != 0 and len(lines) == 1 and lines[0].startswith("error: "), (out, err)
    assert "Traceback" not in err
    return lines[0]


def test_render_refuses_the_mesh_of_a_space_filling_surface(tmp_path: Path, capsys) -> None:
    """Equation B at 256^3: the estimate (a typical surface: 348 MiB) passes 600 MiB, its 4.8
    million crossed cells (10 million faces) do not; the same grid with room renders."""
    out = tmp_path / "b.ply"
    args = ["render", "--preset", "eqB", "--grid", "256", "--evaluator", "sparse", "-o", out]
    line = one_line_error([*args, "--max-memory", "600M"], capsys)
    assert line.startswith("error: render on a 256x256x256 grid (sparse evaluator): meshing the ")
    assert "cells the surface crosses needs about 1.8 GiB more" in line
    assert "limit of 600.0 MiB (--max-memory sets it); use a smaller grid" in line
    assert list(tmp_path.iterdir()) == []
    assert main([str(a) for a in [*args, "--max-memory", "4G"]]) == 0
    assert out.stat().st_size > 100 << 20


def test_export_regrid_counts_the_copies_its_cleanup_holds(tmp_path: Path, capsys) -> None:
    spec = tmp_path / "eqB.json"
    spec.write_text(json.dumps(PRESETS["eqB"].spec().to_dict()))
    line = one_line_error(
        [
            "export",
            spec,
            "--regrid",
            "160",
            "--evaluator",
            "sparse",
            "--max-memory",
            "1G",
            "-o",
            tmp_path / "o",
        ],
        capsys,
    )
    assert line.startswith("error: exporting eqB on a 160^3 grid: meshing the ")
    cells = int(line.split("meshing the ")[1].split()[0].replace(",", ""))
    need = format_bytes(cells * SPARSE_BYTES_PER_MIXED_CELL * CLEANUP_MESH_COPIES)
    assert f"cells the surface crosses needs about {need} more" in line
    assert "limit of 1.0 GiB" in line
    assert not (tmp_path / "o").exists()


def test_export_reports_each_shape_s_stages(tmp_path: Path) -> None:
    """A re-gridded formula's meshing stages, then its cleaning, after the shape's name."""
    spec = tmp_path / "sphere.json"
    spec.write_text(json.dumps(PRESETS["sphere"].spec().to_dict()))
    seen: list[tuple[int, int, str]] = []
    options = ExportOptions(format="ply", regrid=40, evaluator="sparse")
    export_shapes([str(spec)], tmp_path / "o", options, progress=lambda *a: seen.append(a))
    names = [name for _, _, name in seen]
    assert names[0] == "sphere" and seen[-1][:2] == (1, 1)
    stages = [name.split(": ", 1)[1] for name in names if ": " in name]
    assert stages[0] == "bounding" and "sampling" in stages
    assert stages.index("meshing") < stages.index("cleaning") == len(stages) - 1
    assert all(i == 0 for i, _, name in seen if ": " in name)
