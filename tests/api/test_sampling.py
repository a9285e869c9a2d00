"""surfgen.draw, surfgen.sample and surfgen.shapes: the sampler's shapes, the CLI's catalogue
byte for byte, and the same accepted shapes streamed in memory."""

from __future__ import annotations

import itertools
import json
import pickle
import sqlite3
from pathlib import Path

import numpy as np
import pytest

import surfgen
from surfgen.generator.mesh.exchange import load_mesh
from surfgen.generator.model.families import family_names
from surfgen.pipelines.run.config import load_config
from tests.api.conftest import GRID, SEED, N
from tools.same_catalogue import differences, rows


def _accepted(root: Path) -> list[tuple[int, str, str]]:
    con = sqlite3.connect(f"file:{root / 'catalogue.sqlite'}?mode=ro", uri=True)
    try:
        return con.execute(
            "SELECT idx, key, metrics FROM shapes WHERE verdict = 'accepted' ORDER BY idx"
        ).fetchall()
    finally:
        con.close()


def test_sample_makes_the_cli_s_catalogue_byte_for_byte(
    api_catalogue: surfgen.Catalogue, cli_catalogue: Path
) -> None:
    api = api_catalogue.path
    assert differences(rows(api), rows(cli_catalogue)) == []
    assert len(rows(api)) > N  # some draws were rejected...
    reasons = [json.loads(r[8]) for r in rows(api)]
    assert ["duplicate"] in reasons  # ...some as near duplicates
    for folder in ("meshes", "thumbs"):
        ours = sorted(p.name for p in (api / folder).iterdir())
        assert ours == sorted(p.name for p in (cli_catalogue / folder).iterdir()) and ours
        for name in ours:
            assert (api / folder / name).read_bytes() == (
                cli_catalogue / folder / name
            ).read_bytes()
    summary = api_catalogue.summary
    assert summary is not None and summary.accepted == N and summary.status == "complete"
    assert [r["config"] for r in api_catalogue.runs()] == [
        r["config"] for r in surfgen.Catalogue(cli_catalogue).runs()
    ]


def test_sample_refuses_to_redo_a_run(api_catalogue: surfgen.Catalogue, run_config_file) -> None:
    with pytest.raises(surfgen.CatalogueError, match="already has run 1 with seed 7"):
        surfgen.sample(N, SEED, grid=GRID, config=run_config_file, out=api_catalogue.path)
    with pytest.raises(surfgen.LimitError, match="--n must be a whole number from 1"):
        surfgen.sample(0, SEED, out=api_catalogue.path)


def test_an_exhausted_run_returns_its_catalogue(tmp_path: Path) -> None:
    catalogue = surfgen.sample(3, SEED, grid=GRID, max_draws=2, out=tmp_path / "c", workers=1)
    summary = catalogue.summary
    assert summary is not None and summary.status == "exhausted" and summary.drawn == 2
    assert len(catalogue) == summary.accepted < 3


def test_shapes_yields_what_sample_accepts_in_its_order(
    api_catalogue: surfgen.Catalogue, run_config_file: Path
) -> None:
    stream = surfgen.shapes(SEED, grid=GRID, config=run_config_file)
    got = list(itertools.islice(stream, N))
    catalogued = _accepted(api_catalogue.path)
    assert [(s.index, s.key) for s in got] == [(i, k) for i, k, _ in catalogued]
    assert [s.metrics for s in got] == [json.loads(m) for _, _, m in catalogued]
    # and without the near-duplicate check, the duplicates come back in between
    plain = surfgen.shapes(SEED, grid=GRID, config=run_config_file, dedupe=False)
    indices = [s.index for s in itertools.islice(plain, N)]
    ours = [s.index for s in got]
    assert indices != ours and indices[0] == ours[0]
    assert all(i in indices for i in ours if i <= indices[-1])


def test_a_streamed_shape_is_the_catalogued_one(
    api_catalogue: surfgen.Catalogue, run_config_file
) -> None:
    shape = next(surfgen.shapes(SEED, grid=GRID, config=run_config_file))
    record = api_catalogue[shape.key]
    assert shape.surface.spec == record.spec and shape.family == record.family
    assert shape.descriptor is not None and shape.formula == record.formula
    mesh = shape.mesh()
    stored = load_mesh(api_catalogue.path / record.to_dict()["mesh"])
    np.testing.assert_allclose(mesh.vertices, stored.vertices, rtol=0, atol=1e-6)  # PLY: float32
    np.testing.assert_array_equal(mesh.faces, stored.faces)
    assert shape.surface.check().metrics == shape.metrics  # the run's cascade, the run's config
    assert repr(shape).startswith(f"Shape(index={shape.index}, key='{shape.key}'")
    copy = pickle.loads(pickle.dumps(shape))  # a data loader's workers send shapes so
    assert copy.key == shape.key and copy.surface == shape.surface and copy.metrics == shape.metrics
    assert copy.surface.config == shape.surface.config and copy.family == shape.family
    assert shape.key in shape._repr_html_() and shape._repr_png_() is not None


def test_shapes_stops_at_max_draws_and_checks_its_arguments() -> None:
    assert list(surfgen.shapes(2, grid=GRID, max_draws=1)) == []  # its draw 0 is rejected
    assert len(list(surfgen.shapes(SEED, grid=GRID, max_draws=1))) == 1  # this one's is kept
    with pytest.raises(surfgen.LimitError, match="--seed must be a whole number"):
        surfgen.shapes(-1)
    with pytest.raises(surfgen.SpecError, match="--family must be one of"):
        surfgen.shapes(SEED, family="statue")


def test_draw_is_the_run_s_shape(api_catalogue: surfgen.Catalogue, run_config_file: Path) -> None:
    index, key, _ = _accepted(api_catalogue.path)[0]
    drawn = surfgen.draw(SEED, index, grid=GRID, config=run_config_file)
    assert drawn.key == key and drawn.cap and drawn.family in family_names()
    assert drawn.provenance["index"] == index and drawn.provenance["seed"] == SEED
    assert drawn.check().accepted
    assert surfgen.draw(SEED, index, grid=GRID, config=run_config_file) == drawn  # pure
    # the family option is the CLI's --family: a free draw of the same index is another shape
    free = surfgen.draw(SEED, index, grid=GRID, family="free")
    assert free.family == "free" and free.key != drawn.key
    assert free.config == load_config().with_grid(GRID).with_family("free")


def test_draw_errors() -> None:
    with pytest.raises(surfgen.LimitError, match="index must be a whole number from 0"):
        surfgen.draw(7, -1)
    with pytest.raises(surfgen.SpecError, match="--family must be one of sculpture"):
        surfgen.draw(7, 3, family="statue")
    with pytest.raises(surfgen.LimitError, match="--grid must be a whole number from"):
        surfgen.draw(7, 3, grid=1)
    with pytest.raises(surfgen.SpecError, match="cannot read config /nonexistent/c.toml"):
        surfgen.draw(7, 3, config="/nonexistent/c.toml")


def test_resume_returns_a_finished_run_as_it_is(
    api_catalogue: surfgen.Catalogue, run_config_file
) -> None:
    before = rows(api_catalogue.path)
    again = surfgen.sample(
        N, SEED, grid=GRID, config=run_config_file, out=api_catalogue.path, resume=True
    )
    assert again.summary is not None and again.summary.status == "complete"
    assert rows(api_catalogue.path) == before
