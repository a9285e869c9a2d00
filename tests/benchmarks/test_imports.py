"""Every benchmark and tool imports without running (its work is in ``main()``) and has a
``main``; none reaches into ``tests/`` or its siblings through ``sys.path``."""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path

import pytest

import benchmarks
import tools

ROOT = Path(__file__).resolve().parents[2]
MODULES = [f"benchmarks.{m.name}" for m in pkgutil.iter_modules(benchmarks.__path__)]
MODULES += [f"tools.{m.name}" for m in pkgutil.iter_modules(tools.__path__)]
LIBRARIES = {"benchmarks.harness", "benchmarks.workloads"}


def test_the_packages_hold_the_scripts():
    assert len(MODULES) >= 28  # 21 benchmarks, 8 tools, the harness and the workloads


@pytest.mark.parametrize("name", MODULES)
def test_imports_without_running(name: str, capsys):
    module = importlib.import_module(name)
    assert capsys.readouterr().out == ""  # importing printed nothing: nothing ran
    if name not in LIBRARIES:
        assert callable(module.main)
        assert module.__doc__, "the docstring says what it measures and how to run it"


def test_no_sys_path_tricks():
    for folder in ("benchmarks", "tools", "tests"):
        for path in (ROOT / folder).rglob("*.py"):
            if path != Path(__file__):
                assert "sys.path.insert" not in path.read_text(), path


@pytest.mark.parametrize("name", sorted(set(MODULES) - LIBRARIES))
def test_benchmarks_use_the_harness(name: str):
    if name.startswith("benchmarks."):
        text = (ROOT / f"{name.replace('.', '/')}.py").read_text()
        assert "harness.parser(" in text and "harness.Run(" in text and "run.save()" in text
