"""The package itself: what ``import surfgen`` offers and loads, its type hints (mypy, strict,
on the API's modules) and how it is installed (api/ mapped to surfgen, py.typed shipped)."""

from __future__ import annotations

import inspect
import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import surfgen
from tests.support.commands import HEAVY_MODULES

ROOT = Path(__file__).resolve().parents[2]
API = ROOT / "api"
# The API's modules are checked strictly; the layers beneath are read for their types only.
MYPY_CONFIG = """
[mypy]
python_version = 3.11
strict = True
follow_imports = silent
[mypy-surfgen.generator.*,surfgen.filters.*,surfgen.pipelines.*]
ignore_errors = True
[mypy-trimesh.*,skimage.*,numba.*,pymeshlab.*,scipy.*,dask.*,distributed.*,pyarrow.*]
ignore_missing_imports = True
"""


def test_import_surfgen_loads_no_kernel_library() -> None:
    # every public name loaded (they load on first use), and still none of them
    code = (
        "import json, sys, surfgen; [getattr(surfgen, n) for n in surfgen.__all__]; "
        f"print(json.dumps([m for m in {HEAVY_MODULES!r} if m in sys.modules]))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == []


def test_import_surfgen_loads_only_itself() -> None:
    """``import surfgen`` runs first in every import of its layers: it loads none of its own
    modules until a name is asked for (then only that name's)."""
    code = (
        "import json, sys, surfgen; before = sorted(m for m in sys.modules if m.startswith('surfgen.') and m.count('.') == 1); "
        "surfgen.Surface; after = sorted(m for m in sys.modules if m.startswith('surfgen.') and m.count('.') == 1); "
        "print(json.dumps([before, after]))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    before, after = json.loads(done.stdout)
    assert before == ["surfgen.generator"]
    assert "surfgen.surface" in after and "surfgen.sampling" not in after


def test_all_is_the_public_surface() -> None:
    assert sorted(surfgen.__all__) == sorted(set(surfgen.__all__))
    for name in surfgen.__all__:
        assert hasattr(surfgen, name), name
    public = {
        n
        for n in vars(surfgen)
        if not n.startswith("_") and not inspect.ismodule(getattr(surfgen, n))
    }
    assert public - set(surfgen.__all__) == set()  # nothing public left out of __all__
    assert issubclass(surfgen.CatalogueError, surfgen.SurfgenError)
    assert issubclass(surfgen.LimitError, surfgen.SurfgenError)


def test_every_public_function_and_method_is_typed_and_documented() -> None:
    missing = []
    for name in surfgen.__all__:
        obj = getattr(surfgen, name)
        members = [(name, obj)]
        if inspect.isclass(obj) and obj.__module__.startswith("surfgen."):
            members += [
                (f"{name}.{m}", v)
                for m, v in vars(obj).items()
                if not m.startswith("_")
                and (inspect.isfunction(v) or isinstance(v, property | classmethod))
            ]
        for label, member in members:
            func = (
                member.fget if isinstance(member, property) else getattr(member, "__func__", member)
            )
            if not (inspect.isfunction(func) or inspect.isclass(func)):
                continue
            if not (func.__doc__ or "").strip():
                missing.append(f"{label}: no docstring")
            if inspect.isfunction(func) and "return" not in func.__annotations__:
                missing.append(f"{label}: no return type")
    assert missing == []


def test_the_api_folder_is_the_surfgen_package_and_ships_py_typed() -> None:
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert setuptools["package-dir"]["surfgen"] == "api" and "surfgen" in setuptools["packages"]
    assert "py.typed" in setuptools["package-data"]["surfgen"]
    assert (API / "py.typed").is_file()
    # no folder named surfgen at the root: it would shadow the mapping when tests run from here
    assert not (ROOT / "surfgen").exists()
    assert (
        Path(surfgen.__file__).resolve().parent == API.resolve()
        or "site-packages" in surfgen.__file__
    )


def _checkout(tmp: Path, extra: str = "") -> Path:
    """A tree laid out as the installed package (``surfgen/`` = api/ plus the three layers,
    linked), for mypy, which cannot follow an editable install's import hook."""
    package = tmp / "src" / "surfgen"
    package.mkdir(parents=True)
    for path in API.iterdir():
        if path.suffix in (".py", ".typed"):
            if extra and path.name == "sampling.py":
                continue
            (package / path.name).symlink_to(path)
    if extra:  # a copy of sampling.py with a type error added
        (package / "sampling.py").write_text((API / "sampling.py").read_text() + extra)
    for layer in ("generator", "filters", "pipelines"):
        (package / layer).symlink_to(ROOT / layer)
    return tmp


def _mypy(tree: Path) -> subprocess.CompletedProcess[str]:
    config = tree / "mypy.ini"
    config.write_text(MYPY_CONFIG)
    cache = ROOT / "out" / ".mypy_cache"  # out/ holds generated files (not committed)
    return subprocess.run(
        [sys.executable, "-m", "mypy", "--config-file", str(config), "--cache-dir", str(cache)]
        + ["-p", "surfgen"],
        cwd=tree,
        env={**os.environ, "MYPYPATH": str(tree / "src")},
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_the_api_is_mypy_clean(tmp_path: Path) -> None:
    done = _mypy(_checkout(tmp_path))
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Success: no issues found" in done.stdout


def test_mypy_finds_a_type_error_in_the_api(tmp_path: Path) -> None:
    bad = "\n\ndef _wrong() -> int:\n    return draw(7, 3).key\n"
    done = _mypy(_checkout(tmp_path, extra=bad))
    assert done.returncode == 1
    assert (
        "sampling.py" in done.stdout
        and 'Incompatible return value type (got "str", expected "int")' in done.stdout
    )


@pytest.mark.parametrize("module", ["surfgen.surface", "surfgen.sampling", "surfgen.catalogue"])
def test_api_modules_are_short(module: str) -> None:
    path = API / f"{module.split('.')[-1]}.py"
    assert len(path.read_text().splitlines()) <= 600
