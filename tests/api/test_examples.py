"""The Python guide's examples run, in order, as a reader would run them (one namespace, a
fresh folder); the README's Python section is run by tests/test_docs.py and does what the
issue asks of it."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
GUIDE = ROOT / "docs" / "guide" / "python.md"


def python_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, re.S)


def test_the_python_guide_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    blocks = python_blocks(GUIDE.read_text())
    assert len(blocks) >= 8, "the guide lost its examples?"
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {"__name__": "__guide__"}
    for number, code in enumerate(blocks, 1):
        exec(compile(code, f"docs/guide/python.md, python block {number}", "exec"), namespace)
    assert (tmp_path / "gyroid.stl").is_file()
    assert (tmp_path / "out" / "guide" / "catalogue.sqlite").is_file()
    assert len(list((tmp_path / "out" / "guide-print").glob("*.stl"))) == 1


def test_the_readme_s_python_example_does_what_a_new_user_asks() -> None:
    section = re.search(r"^## Python\n(.*?)(?=^## )", (ROOT / "README.md").read_text(), re.S | re.M)
    assert section is not None
    (code,) = python_blocks(section[1])
    steps = (
        "import surfgen",
        "surfgen.draw(7, 3)",  # draw shape (7, 3)
        ".mesh(grid=128)",  # mesh it at grid 128
        '.export("shape-7-3.stl")',  # export it as STL
        "surfgen.sample(20,",  # sample 20 shapes into a catalogue
        ".query(",  # and query it
    )
    positions = [code.find(step) for step in steps]
    assert -1 not in positions and positions == sorted(positions), positions
    assert "surfgen.generator" not in code and "surfgen.pipelines" not in code
