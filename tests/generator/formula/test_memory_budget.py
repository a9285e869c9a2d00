"""MemoryBudget: a command's memory checked again as a sparse run learns the surface's size."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from surfgen.generator.eval.grid import Box, Grid
from surfgen.generator.eval.sparse import CHUNK_BRICKS
from surfgen.generator.formula import limits
from surfgen.generator.formula.limits import (
    SPARSE_BYTES_PER_MIXED_CELL,
    LimitError,
    MemoryBudget,
    check_step,
)
from surfgen.generator.mesh.realise import realise
from surfgen.generator.model.presets import PRESETS
from surfgen.generator.model.spec import SurfaceSpec


@dataclasses.dataclass(frozen=True)
class Recording(MemoryBudget):
    """A budget that records every step it is asked about and refuses the one named."""

    steps: list = dataclasses.field(default_factory=list)
    refuse: str = ""

    def check(self, need: int, step: str) -> None:
        self.steps.append((step, need))
        if self.refuse and self.refuse in step:
            raise LimitError(f"{self.what}: {step} refused")


def recording(refuse: str = "", copies: int = 1) -> Recording:
    return Recording(1 << 40, "test", "a test", 0, copies, [], refuse)


def test_check_refuses_past_the_limit_with_one_line(monkeypatch) -> None:
    monkeypatch.setattr(limits, "resident_memory", lambda: 300 << 20)
    budget = MemoryBudget(1 << 30, "render on a 8x8x8 grid (sparse evaluator)",
                          "--max-memory sets it", 100 << 20)  # fmt: skip
    assert budget.in_use() == 200 << 20
    budget.check((1 << 30) - (200 << 20), "meshing")  # exactly at the limit: allowed
    with pytest.raises(LimitError) as info:
        budget.check((1 << 30) - (200 << 20) + 1, "meshing the 5 cells the surface crosses")
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith("render on a 8x8x8 grid (sparse evaluator): meshing the 5 cells")
    assert "beside the 200.0 MiB in use" in message and "limit of 1.0 GiB" in message
    assert "(--max-memory sets it); use a smaller grid" in message
    monkeypatch.setattr(limits, "resident_memory", lambda: 50 << 20)  # freed below the start
    assert budget.in_use() == 0


def test_begin_takes_the_available_memory_or_the_limit_given(monkeypatch) -> None:
    monkeypatch.setattr(limits, "available_memory", lambda: 7 << 30)
    monkeypatch.setattr(limits, "resident_memory", lambda: 123)
    free = MemoryBudget.begin(None, "export", copies=4)
    assert (free.limit, free.start, free.copies) == (7 << 30, 123, 4)
    assert free.source == "the available memory; --max-memory sets it"
    given = MemoryBudget.begin(2 << 30, "render")
    assert (given.limit, given.source, given.copies) == (2 << 30, "--max-memory sets it", 1)
    assert MemoryBudget.begin(None, "meshing", setting=None).source == "the available memory"
    assert given.mesh_bytes(10) == 10 * SPARSE_BYTES_PER_MIXED_CELL
    assert free.mesh_bytes(10) == 40 * SPARSE_BYTES_PER_MIXED_CELL
    check_step(None, 1 << 60, "anything")  # no budget: nothing checked


def test_the_sparse_estimate_grows_with_the_surface() -> None:
    """What render and export check before a sparse run: about 4x per doubling of the grid
    (a surface's size), where the dense estimate grows 8x."""
    sparse = [sum(limits.estimate_memory(n**3, sparse=True).values()) for n in (256, 512, 1024)]
    dense = [sum(limits.estimate_memory(n**3).values()) for n in (256, 512, 1024)]
    for small, large in itertools.pairwise(sparse):
        assert 3.9 * small < large < 4.1 * small
    assert dense[1] == 8 * dense[0] and sparse[2] < dense[2] / 10


def test_resident_memory_is_this_process() -> None:
    before = limits.resident_memory()
    block = np.ones(64 << 17)  # 64 MiB, touched
    assert limits.resident_memory() - before > 48 << 20
    del block


def spec_of(name: str, n: int) -> SurfaceSpec:
    return dataclasses.replace(PRESETS[name].spec(), grid=(n, n, n))


def test_a_sparse_run_checks_each_step_with_what_it_learnt() -> None:
    """The samples of each run of leaves, then the offsets of the bricks kept, then the mesh
    from the count of crossed cells, each before it is made; the mesh is unchanged."""
    spec = spec_of("eqC", 48)
    budget = recording()
    made = realise(spec, evaluator="sparse", cap=True, budget=budget)
    plain = realise(spec, evaluator="sparse", cap=True)
    assert made.mesh.vertices.tobytes() == plain.mesh.vertices.tobytes()
    steps = [s for s, _ in budget.steps]
    runs = -(-made.field.stats["sampled_leaves"] // CHUNK_BRICKS)
    assert steps[:runs] == [f"sampling the {made.field.stats['sampled_leaves']:,} leaves the "
                            "surface may cross"] * runs  # fmt: skip
    assert sum(need for _, need in budget.steps[:runs]) == (
        made.field.stats["sampled_leaves"] * 9**3 * 8  # float64 bricks of 9^3 points
    )
    assert steps[runs] == f"the float32 offsets of {made.field.n_bricks:,} bricks"
    assert budget.steps[runs][1] == made.field.n_bricks * 9**3 * 4
    cells = int(steps[runs + 1].split()[2].replace(",", ""))
    assert steps[runs + 1] == f"meshing the {cells:,} cells the surface crosses"
    assert budget.steps[runs + 1][1] == cells * SPARSE_BYTES_PER_MIXED_CELL
    assert len(steps) == runs + 2
    assert 1.5 * cells < made.mesh.n_faces < 3 * cells  # about two faces a cell, caps included


@pytest.mark.parametrize("step", ["sampling", "offsets", "meshing"])
def test_a_refused_step_stops_the_run_with_its_limit_error(step: str) -> None:
    budget = recording(refuse=step)
    with pytest.raises(LimitError, match=step):
        realise(spec_of("eqC", 40), evaluator="sparse", cap=True, walls="keep", budget=budget)


def test_the_mesh_check_counts_the_copies_the_command_holds() -> None:
    budget = recording(copies=4)
    realise(spec_of("eqC", 40), evaluator="sparse", budget=budget)
    step, need = budget.steps[-1]
    assert need == 4 * int(step.split()[2].replace(",", "")) * SPARSE_BYTES_PER_MIXED_CELL


def test_the_dense_path_and_a_given_grid_are_unchanged() -> None:
    spec = spec_of("eqC", 32)
    budget = recording(refuse="meshing")
    made = realise(spec, grid=Grid(Box.from_bounds(spec.box), (30,) * 3), evaluator="fast",
                   budget=budget)  # fmt: skip
    assert made.mesh.n_faces > 0 and budget.steps == []


def test_auto_stays_sparse_where_the_bounds_leave_every_point_to_sample() -> None:
    """Equation B's foam crosses every leaf (the bounds leave 1.4 times the grid's points to
    sample): ``auto`` meshes it sparsely all the same (faster there too:
    ``benchmarks/bench_auto.py``), each step checked as the sparse path checks it."""
    budget = recording(refuse="meshing")
    with pytest.raises(LimitError, match="meshing the"):
        realise(spec_of("eqB", 160), evaluator="auto", budget=budget)
    steps = [s for s, _ in budget.steps]
    assert steps[0].startswith("sampling the ") and steps[-2].startswith("the float32 offsets")
    assert steps[-1].startswith("meshing the ") and not any("evaluating all" in s for s in steps)
