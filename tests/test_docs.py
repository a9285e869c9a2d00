"""The README and the documentation site: the site builds strictly, the generated config
reference lists every config key, the README stays short, its Quick start is what CI runs, its
links resolve and its Python example runs."""

from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys
import tomllib
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import pytest

from surfgen.pipelines.run.config import default_config_text, load_config

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
MAX_README_LINES = 300


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The site, built with ``mkdocs build --strict`` into a temporary folder."""
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", "mkdocs.yml", "-d", str(out)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, f"mkdocs build --strict failed:\n{done.stderr}"
    return out


def test_site_builds_strictly(site: Path) -> None:
    for page in ("index.html", "architecture/index.html", "performance/log/index.html"):
        assert (site / page).is_file(), page


def _config_keys(obj: Any, path: tuple[str, ...] = ()) -> Iterator[str]:
    """``table.key`` for every value field of the config's dataclasses, nested tables included."""
    for field in dataclasses.fields(obj):
        if not field.metadata.get("config_key", True):  # copied from another table (grid)
            continue
        value = getattr(obj, field.name)
        if dataclasses.is_dataclass(value):
            yield from _config_keys(value, (*path, field.name))
        elif (
            isinstance(value, tuple)
            and value
            and all(
                isinstance(v, tuple) and len(v) == 2 and dataclasses.is_dataclass(v[1])
                for v in value
            )
        ):  # ((name, settings), ...): the families' own tables [sampler.NAME]
            for name, sub in value:
                yield from _config_keys(sub, (*path, str(name)))
        elif (
            isinstance(value, Mapping)
            and value
            and all(dataclasses.is_dataclass(v) for v in value.values())
        ):
            for name, sub in value.items():
                yield from _config_keys(sub, (*path, field.name, str(name)))
        else:
            yield ".".join((*path, field.name))


def _toml_keys(table: Mapping[str, Any], path: tuple[str, ...] = ()) -> Iterator[str]:
    for key, value in table.items():
        if isinstance(value, dict):
            yield from _toml_keys(value, (*path, key))
        else:
            yield ".".join((*path, key))


def test_config_reference_lists_every_key(site: Path) -> None:
    page = (site / "reference" / "config" / "index.html").read_text()
    listed = set(re.findall(r'<span id="([\w.-]+)"></span>', page))
    fields = set(_config_keys(load_config()))
    assert fields, "the config has no fields?"
    assert fields - listed == set(), "config keys missing from the reference"
    assert listed - fields == set(), "the reference lists keys the config does not have"
    documented = set(_toml_keys(tomllib.loads(default_config_text())))
    assert documented - listed == set(), "keys of default_config.toml missing from the reference"


def _section(text: str, title: str) -> str:
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.S | re.M)
    assert match, f"README has no '## {title}' section"
    return match[1]


def _ci_command() -> str:
    """The command .ci/run runs: its one line that creates .venv."""
    lines = (ROOT / ".ci" / "run").read_text().splitlines()
    commands = [line.strip() for line in lines if line.strip().startswith("python3 -m venv")]
    assert len(commands) == 1, commands
    return commands[0]


def test_readme_is_short() -> None:
    lines = README.read_text().splitlines()
    assert len(lines) <= MAX_README_LINES, f"README.md has {len(lines)} lines"


def test_quick_start_is_two_commands_and_ci_runs_the_second() -> None:
    quick = _section(README.read_text(), "Quick start")
    blocks = re.findall(r"```bash\n(.*?)```", quick, re.S)
    assert len(blocks) == 1, "the Quick start has one block of commands"
    commands = [line for line in blocks[0].splitlines() if line.strip()]
    assert len(commands) == 2, commands
    assert "pip install ." in commands[0]
    assert "surfgen sample --n 1000 --seed 7" in commands[0]
    assert commands[1] == _ci_command()


def test_readme_links_resolve() -> None:
    text = README.read_text()
    targets = re.findall(r"\]\(([^)\s]+)\)", text)
    local = [t.split("#")[0] for t in targets if not re.match(r"[a-z]+:", t) and t[0] != "#"]
    assert local, "README links nothing?"
    missing = [t for t in local if not (ROOT / t).exists()]
    assert missing == [], missing


def test_readme_python_examples_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), re.S)
    assert blocks, "README has no Python example"
    monkeypatch.chdir(tmp_path)
    for number, code in enumerate(blocks, 1):
        exec(compile(code, f"README.md, python block {number}", "exec"), {"__name__": "__readme__"})
