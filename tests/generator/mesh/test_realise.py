"""realise: the one path from a spec to its mesh, step by step the same as the steps alone."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.generator.errors import EmptySurface, SpecError
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.mesh.mesh import Mesh, extract_mesh
from surfgen.generator.mesh.realise import realise
from surfgen.generator.mesh.walls import extract_labelled
from surfgen.generator.model.spec import SurfaceSpec

TORUS = SurfaceSpec("(sqrt(x^2+y^2)-1)^2+z^2-0.16", (-1.5, 1.5) * 3, (20, 20, 20))
WALLED = SurfaceSpec("tan(2*x)+y^2+z^2-1", (-1.5, 1.5) * 3, (16, 16, 16))
NOTHING = SurfaceSpec("x^2+y^2+z^2+1", (-1.0, 1.0) * 3, (8, 8, 8))


def same(a: Mesh, b: Mesh) -> bool:
    return (
        np.array_equal(a.vertices, b.vertices)
        and np.array_equal(a.faces, b.faces)
        and (a.face_kinds is None) == (b.face_kinds is None)
        and (a.face_kinds is None or np.array_equal(a.face_kinds, b.face_kinds))
    )


@pytest.mark.parametrize("cap", [False, True])
def test_realise_is_evaluate_then_extract(cap: bool) -> None:
    field = evaluate(TORUS.tree(), TORUS.to_grid(), TORUS.params)
    made = realise(TORUS, cap=cap)
    assert same(made.mesh, extract_mesh(field, TORUS.level, cap=cap))
    assert np.array_equal(made.field.values, field.values)
    assert made.walls is None and made.empty is None
    assert set(made.seconds) == {"evaluate", "mesh"}


@pytest.mark.parametrize("walls", ["keep", "mark", "remove"])
def test_realise_with_walls_is_extract_labelled(walls: str) -> None:
    tree = WALLED.tree()
    field = evaluate(tree, WALLED.to_grid(), WALLED.params)
    want, report = extract_labelled(field, tree, WALLED.params, WALLED.level, True, walls)
    made = realise(WALLED, cap=True, walls=walls)
    assert same(made.mesh, want) and made.walls == report


def test_realise_on_another_grid_and_a_given_field() -> None:
    grid = Grid(Box.from_bounds(TORUS.box), (12, 12, 12))
    field = evaluate(TORUS.tree(), grid, TORUS.params)
    on_grid = realise(TORUS, grid=grid, cap=True)
    assert on_grid.field.grid.shape == (12, 12, 12)
    assert same(on_grid.mesh, extract_mesh(field, TORUS.level, cap=True))
    given = realise(TORUS, field=field, cap=True)
    assert given.field is field and same(given.mesh, on_grid.mesh)


def test_an_empty_surface_raises_unless_allowed() -> None:
    with pytest.raises(EmptySurface, match="no surface: all 512 samples are outside") as info:
        realise(NOTHING)
    made = realise(NOTHING, allow_empty=True)
    assert made.mesh is None and made.empty == str(info.value)
    assert made.field.values.shape == (8, 8, 8)


def test_an_unknown_walls_mode_is_refused_before_evaluating() -> None:
    with pytest.raises(SpecError, match="unknown --walls mode 'hide'"):
        realise(TORUS, walls="hide")


def test_progress_names_each_stage_and_the_share_sampled() -> None:
    spec = SurfaceSpec("x^2+y^2+z^2-1", (-1.5, 1.5) * 3, (40, 40, 40))
    seen: list = []
    realise(spec, evaluator="sparse", cap=True, progress=lambda s, d: seen.append((s, d)))
    stages = [s for s, _ in seen]
    assert stages[0] == "bounding" and stages[-1] == "meshing"
    shares = [d for s, d in seen if s == "sampling"]
    assert shares and shares == sorted(shares) and shares[-1] == 1.0
    assert all(d is None for s, d in seen if s != "sampling")
    seen.clear()
    realise(spec, evaluator="fast", progress=lambda s, d: seen.append((s, d)))
    assert seen == [("evaluating", None), ("meshing", None)]
