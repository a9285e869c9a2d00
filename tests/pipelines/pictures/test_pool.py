"""surfgen.pipelines.pictures.pool: pictures drawn on several processes are the same bytes as
on one, a bad mesh or a dying worker costs only its own job, and progress reaches the total."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from surfgen.generator.mesh.exchange import save_mesh
from surfgen.pipelines.pictures import pool as picture_pool
from surfgen.pipelines.pictures.pool import Job, draw, draw_all


@pytest.fixture(scope="module")
def jobs(tmp_path_factory, shape_mesh) -> list[Job]:
    folder = tmp_path_factory.mktemp("pool")
    out = []
    for name in ("sphere", "torus", "genus2", "two_spheres"):
        path = save_mesh(shape_mesh(name), folder / f"{name}.ply")
        out.append(Job(name, str(path), ("thumb", "turntable")))
    return out


def _by_key(drawn) -> dict[str, dict[str, bytes]]:
    return {d.job.key: d.pictures for d in drawn}


def test_several_processes_draw_the_same_bytes_as_one(jobs) -> None:
    calls: list[tuple[int, int]] = []
    one = _by_key(draw_all(jobs, workers=1))
    two = _by_key(draw_all(jobs, workers=2, progress=lambda d, n: calls.append((d, n))))
    assert one == two and set(one) == {j.key for j in jobs}
    assert all(p["thumb"].startswith(b"\x89PNG") and p["turntable"] for p in one.values())
    assert sorted(calls) == [(i, 4) for i in range(1, 5)]


def test_a_bad_mesh_costs_its_own_job(jobs, tmp_path: Path) -> None:
    broken = tmp_path / "broken.ply"
    broken.write_bytes(b"ply\nformat nonsense\n")
    bad = [
        Job("missing", str(tmp_path / "none.ply"), ("thumb",)),
        Job("broken", str(broken), ("thumb",)),
    ]
    drawn = {d.job.key: d for d in draw_all([jobs[0], *bad, jobs[1]], workers=2)}
    assert drawn["missing"].error and "no mesh file" in drawn["missing"].error
    assert drawn["broken"].error and drawn["broken"].pictures == {}
    assert drawn["sphere"].error is None and drawn["torus"].error is None


def _dies_on_torus(job: Job):
    if job.key == "torus":
        os._exit(3)
    return draw(job)


def test_a_worker_that_dies_costs_its_own_job(jobs, monkeypatch) -> None:
    monkeypatch.setattr(picture_pool, "draw", _dies_on_torus)  # the forked workers run it
    drawn = {d.job.key: d for d in draw_all(jobs, workers=2)}
    assert "died" in drawn["torus"].error and drawn["torus"].pictures == {}
    assert all(drawn[k].error is None for k in ("sphere", "genus2", "two_spheres"))
