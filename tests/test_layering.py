"""The data flows one way: generator ← filters ← pipelines ← the API (``api/``, installed as
``surfgen``), the CLI is the only package that speaks typer and the only one beneath the API
that calls it, and no module imports itself back through others (see the README's
"Architecture" section)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("generator", "filters", "pipelines", "api")
# The folder of each package and its dotted name (pyproject.toml's package-dir).
DOTTED = {"generator": "surfgen.generator", "filters": "surfgen.filters"}
DOTTED |= {"pipelines": "surfgen.pipelines", "api": "surfgen"}
FORBIDDEN = {
    "generator": ("surfgen.filters", "surfgen.pipelines"),
    "filters": ("surfgen.pipelines",),
}
CLI = "surfgen.pipelines.cli"


def imported_modules(path: Path) -> set[str]:
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
    return out


def module_name(path: Path) -> str:
    """``surfgen.pipelines.cli.main`` for ``pipelines/cli/main.py`` (a package: its folder)."""
    folder, *parts = path.relative_to(ROOT).with_suffix("").parts
    if parts and parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join((DOTTED[folder], *parts))


def source_files() -> dict[str, Path]:
    """Every module of surfgen by its dotted name."""
    return {
        module_name(p): p for package in PACKAGES for p in sorted((ROOT / package).rglob("*.py"))
    }


def _type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _import_nodes(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement, at the top or inside functions, but not the ones under
    ``if TYPE_CHECKING:`` (read by type checkers only, never run)."""
    found: list[ast.Import | ast.ImportFrom] = []
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and _type_checking(node):
            stack.extend(node.orelse)
            continue
        if isinstance(node, ast.Import | ast.ImportFrom):
            found.append(node)
        stack.extend(ast.iter_child_nodes(node))
    return found


def import_graph() -> dict[str, set[str]]:
    """Module → the surfgen modules it imports (``from P import M`` counts as importing the
    module ``P.M`` when there is one, else ``P``)."""
    modules = source_files()
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in _import_nodes(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join([*up, base] if base else up)
                targets = [
                    f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base
                    for a in node.names
                ]
            graph[name].update(t for t in targets if t in modules and t != name)
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle (``a → b → … → a``) through each group of modules that import each other
    (the strongly connected components of ``graph`` with more than one module)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    groups: list[set[str]] = []

    def connect(v: str) -> None:  # Tarjan's algorithm
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.add(w)
                if w == v:
                    break
            if len(group) > 1:
                groups.append(group)

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return [_cycle_in(graph, group) for group in groups]


def _cycle_in(graph: dict[str, set[str]], group: set[str]) -> list[str]:
    """The shortest cycle through the first module of ``group`` (breadth-first)."""
    start = min(group)
    came_from: dict[str, str] = {}
    frontier = [start]
    while frontier:
        following = []
        for v in frontier:
            for w in sorted(graph[v] & group):
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(came_from[path[-1]])
                    return [*reversed(path), start]
                if w not in came_from:
                    came_from[w] = v
                    following.append(w)
        frontier = following
    raise AssertionError(f"no cycle in {sorted(group)}")


def api_modules() -> set[str]:
    """The dotted names of the API's modules (``surfgen`` and ``surfgen.<module>``)."""
    return {module_name(p) for p in (ROOT / "api").rglob("*.py")}


def test_module_names_follow_the_package_dirs() -> None:
    assert module_name(ROOT / "api" / "__init__.py") == "surfgen"
    assert module_name(ROOT / "api" / "surface.py") == "surfgen.surface"
    assert module_name(ROOT / "pipelines" / "cli" / "main.py") == "surfgen.pipelines.cli.main"
    assert {"surfgen", "surfgen.surface", "surfgen.catalogue"} <= api_modules()


def test_only_the_cli_imports_the_api() -> None:
    """The API sits on top: it may use every layer; beneath it only the CLI calls it."""
    api = api_modules()
    offenders = [
        f"{path.relative_to(ROOT)} imports {m}"
        for name, path in source_files().items()
        if name not in api and not (name == CLI or name.startswith(CLI + "."))
        for m in imported_modules(path)
        if m in api
    ]
    assert offenders == []


def test_the_api_does_not_import_the_cli() -> None:
    offenders = [
        f"{path.relative_to(ROOT)} imports {m}"
        for name, path in source_files().items()
        if name in api_modules()
        for m in imported_modules(path)
        if m == CLI or m.startswith(CLI + ".")
    ]
    assert offenders == []


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_no_upward_imports(package: str) -> None:
    offenders = [
        f"{p.relative_to(ROOT)} imports {m}"
        for p in sorted((ROOT / package).rglob("*.py"))
        for m in imported_modules(p)
        if m.startswith(FORBIDDEN[package])
    ]
    assert offenders == []


def test_only_the_cli_imports_typer() -> None:
    offenders = [
        str(path.relative_to(ROOT))
        for name, path in source_files().items()
        if not (name == CLI or name.startswith(CLI + "."))
        and any(m == "typer" or m.startswith("typer.") for m in imported_modules(path))
    ]
    assert offenders == []


def test_no_import_cycles() -> None:
    cycles = [" → ".join(c) for c in import_cycles(import_graph())]
    assert cycles == [], "import cycles:\n" + "\n".join(cycles)


def test_the_cycle_finder_finds_cycles() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"f"}, "f": {"e"}}
    assert sorted(import_cycles(graph)) == [["a", "b", "c", "a"], ["e", "f", "e"]]


def test_no_eval_of_formulas() -> None:
    for folder in PACKAGES:
        for p in (ROOT / folder).rglob("*.py"):
            for node in ast.walk(ast.parse(p.read_text())):
                if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
                    assert node.func.id not in ("eval", "exec"), f"{p}: {node.func.id}"
