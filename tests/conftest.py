"""Shared test fixtures: the canonical shapes, sampled on small grids.

Each shape is data (:class:`Shape`): formula, box, grid size and the properties tests check
(genus, components, analytic volume and area).  Fields and meshes are built once per session.
Fixtures:

- ``shapes``: the :data:`SHAPES` table (name -> :class:`Shape`);
- ``shape_field(name) -> Field`` and ``shape_mesh(name, cap=False) -> Mesh``;
- ``sphere_mesh``, ``torus_mesh``, ``genus2_mesh``, ``two_spheres_mesh`` for the common ones.

Add new canonical shapes to :data:`SHAPES`, new fixtures below the existing ones.
"""

from __future__ import annotations

import contextlib
import fcntl
import math
import os
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass

import pytest

from surfgen.generator.eval.grid import Box, Field, Grid
from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.formula.parser import parse
from surfgen.generator.mesh.mesh import Mesh, extract_mesh
from tests.support import kernel_warmup

# fixtures shared by the picture and gallery tests (template, keys, renders)
pytest_plugins = ["tests.support.gallery"]


@dataclass(frozen=True)
class Shape:
    """A canonical closed shape and what is true of it (``volume``/``area`` analytic, or None)."""

    formula: str
    half: float  # box is [-half, half]^3
    n: int  # grid n^3 (<= 48 keeps tests fast)
    genus: int
    components: int
    volume: float | None = None
    area: float | None = None

    @property
    def grid(self) -> Grid:
        return Grid(Box.cube(self.half), (self.n,) * 3)


SHAPES: dict[str, Shape] = {
    "sphere": Shape(
        "x^2+y^2+z^2-1", 1.5, 40, genus=0, components=1, volume=4 / 3 * math.pi, area=4 * math.pi
    ),
    # R = 1, r = 0.4: V = 2 pi^2 R r^2, A = 4 pi^2 R r.
    "torus": Shape(
        "(sqrt(x^2+y^2)-1)^2+z^2-0.16",
        1.6,
        40,
        genus=1,
        components=1,
        volume=2 * math.pi**2 * 0.16,
        area=4 * math.pi**2 * 0.4,
    ),
    # A thick tube around the figure eight x^2 (1 - x^2) = y^2: genus 2.  (The classic
    # 2y(y^2-3x^2)(1-z^2)+(x^2+y^2)^2-(9z^2-1)(1-z^2) is cut open by every box we tried.)
    "genus2": Shape("(x^2*(1-x^2)-y^2)^2+z^2-0.04", 1.3, 40, genus=2, components=1),
    # Radius 0.5 at x = -0.8 and x = 0.8.
    "two_spheres": Shape(
        "min((x-0.8)^2+y^2+z^2-0.25, (x+0.8)^2+y^2+z^2-0.25)",
        1.5,
        40,
        genus=0,
        components=2,
        volume=2 * 4 / 3 * math.pi * 0.125,
        area=2 * 4 * math.pi * 0.25,
    ),
}


@pytest.fixture(scope="session")
def shapes() -> dict[str, Shape]:
    return SHAPES


@pytest.fixture(scope="session")
def shape_field() -> Callable[[str], Field]:
    """``shape_field(name)``: the named :data:`SHAPES` entry sampled by the reference evaluator."""
    cache: dict[str, Field] = {}

    def get(name: str) -> Field:
        if name not in cache:
            shape = SHAPES[name]
            cache[name] = evaluate_reference(parse(shape.formula), shape.grid)
        return cache[name]

    return get


@pytest.fixture(scope="session")
def shape_mesh(shape_field: Callable[[str], Field]) -> Callable[..., Mesh]:
    """``shape_mesh(name, cap=False)``: the named shape's surface at level 0."""
    cache: dict[tuple[str, bool], Mesh] = {}

    def get(name: str, cap: bool = False) -> Mesh:
        if (name, cap) not in cache:
            cache[name, cap] = extract_mesh(shape_field(name), 0.0, cap=cap)
        return cache[name, cap]

    return get


@pytest.fixture(scope="session")
def sphere_mesh(shape_mesh: Callable[..., Mesh]) -> Mesh:
    return shape_mesh("sphere")


@pytest.fixture(scope="session")
def torus_mesh(shape_mesh: Callable[..., Mesh]) -> Mesh:
    return shape_mesh("torus")


@pytest.fixture(scope="session")
def genus2_mesh(shape_mesh: Callable[..., Mesh]) -> Mesh:
    return shape_mesh("genus2")


@pytest.fixture(scope="session")
def two_spheres_mesh(shape_mesh: Callable[..., Mesh]) -> Mesh:
    return shape_mesh("two_spheres")


@pytest.fixture
def cat_dir(template, tmp_path):
    """A fresh copy of the test module's ``template`` catalogue ``(root, keys)``, to write to."""
    import shutil

    root = tmp_path / "cat"
    shutil.copytree(template[0], root)
    return root


#: An xdist worker's background parts to start (module -> the selected tests it names).
_BACKGROUND_LATER: dict = {}


@pytest.hookimpl(trylast=True)  # after -k/-m deselection: only tests that will run
def pytest_collection_modifyitems(config, items) -> None:
    """On a cold numba cache, compile the kernels on both CPUs first (``kernel_warmup``); then
    start the slow background parts of the selected tests (a test module's
    ``start_in_background``, for the tests it names in ``BACKGROUND_TESTS``), so they overlap
    the rest of the suite.

    Under pytest-xdist every worker collects every test: one worker compiles while the other
    waits for it (a lock), and a worker starts the background parts when the first of them
    runs there (``xdist_group`` keeps a module's on one worker), not at collection, where it
    cannot know which worker will run them."""
    _warm_kernels(config, len(items))
    worker = hasattr(config, "workerinput")
    for item in items:
        module = getattr(item, "module", None)
        if item.name in getattr(module, "BACKGROUND_TESTS", ()):
            if worker:
                _BACKGROUND_LATER.setdefault(module, []).append(item.name)
            else:
                module.start_in_background(item.name)  # once however often it is called


def _warm_kernels(config, selected: int) -> None:
    switch = os.environ.get("SURFGEN_TEST_WARMUP", "")
    if switch == "0" or (switch != "1" and selected < kernel_warmup.MIN_TESTS):
        return
    run = getattr(config, "workerinput", {}).get("testrunuid")
    if run is None:
        _warm_now(config)
        return
    # xdist's workers: the first to take the lock compiles, the others then find the cache
    # warm (a worker that comes after the file is gone makes another: it finds it warm too)
    path = os.path.join(tempfile.gettempdir(), f"surfgen-warmup-{run}.lock")
    with open(path, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            _warm_now(config)
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
    with contextlib.suppress(OSError):
        os.unlink(path)


def _warm_now(config) -> None:
    if not kernel_warmup.needed():
        return
    say = config.pluginmanager.get_plugin("terminalreporter")
    if say is not None:
        say.write_line("numba's cache is cold: compiling the kernels on two processes first ...")
    seconds = kernel_warmup.warm_for_suite()
    if say is not None:
        say.write_line(f"kernels compiled in {seconds:.0f} s")
    global _SPARSE_CHILD
    _SPARSE_CHILD = kernel_warmup.start_sparse_child()  # meanwhile, the first folders run


_SPARSE_CHILD = None


def pytest_runtest_setup(item) -> None:
    """An xdist worker's background parts start with the first of them; the first test past
    the folders that mesh densely waits for the sparse kernels' child."""
    module = getattr(item, "module", None)
    if item.name in _BACKGROUND_LATER.get(module, ()):
        for name in _BACKGROUND_LATER.pop(module):
            module.start_in_background(name)
    global _SPARSE_CHILD
    if _SPARSE_CHILD is None:
        return
    if not item.nodeid.startswith(kernel_warmup.BEFORE_SPARSE):
        child, _SPARSE_CHILD = _SPARSE_CHILD, None
        child.wait()


def pytest_sessionfinish(session, exitstatus) -> None:
    """Stop background parts no test collected (an interrupted or failed-early session)."""
    if _SPARSE_CHILD is not None:  # a session that never got past the first folders
        _SPARSE_CHILD.kill()
        _SPARSE_CHILD.wait()

    for module in list(sys.modules.values()):
        stop = getattr(module, "stop_background", None)
        if stop is not None and getattr(module, "__file__", "").startswith(
            str(session.config.rootpath)
        ):
            stop()
