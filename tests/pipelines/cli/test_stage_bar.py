"""The CLI's progress bar for a long run in stages: on a terminal only, on stderr."""

from __future__ import annotations

import sys

from surfgen.pipelines.cli.common import stage_bar
from surfgen.pipelines.cli.main import main


def test_no_bar_unless_stderr_is_a_terminal(capsys, tmp_path) -> None:
    out = tmp_path / "s.ply"
    assert main(["render", "--preset", "sphere", "--grid", "24", "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert captured.err == "" and "render:" not in captured.out and out.exists()


def test_the_bar_shows_each_stage_on_a_terminal(capsys, monkeypatch) -> None:
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    with stage_bar("render") as move:
        move("bounding", None)
        move("sampling", 0.5)
        move("sampling", 1.0)
        move("meshing", None)
    captured = capsys.readouterr()
    assert captured.out == ""
    for stage in ("bounding", "sampling", "meshing"):
        assert f"render: {stage}" in captured.err
