"""surfgen.settings: a run's config as ``surfgen sample`` composes it from its options."""

from __future__ import annotations

from pathlib import Path

import pytest

import surfgen
from surfgen.pipelines.run.config import load_config
from surfgen.settings import mesh_walls, run_config


def test_run_config_applies_the_sample_options(tmp_path: Path) -> None:
    path = tmp_path / "c.toml"
    path.write_text("[run]\ncap = false\nwalls = 'mark'\n")
    cfg = run_config(path, grid=40, family="lattice", dedupe=False, thumbnails=False)
    expected = load_config(path).with_grid(40).with_family("lattice")
    assert cfg == expected.with_run(dedupe=False, thumbnails=False)
    assert cfg.hash == expected.with_run(dedupe=False).hash  # thumbnails decide no shape
    assert run_config(cfg) is cfg and run_config(str(path)) == load_config(path)
    assert run_config(None, thumbnails=True) == load_config()  # True: the config's own


def test_run_config_errors_are_the_cli_s() -> None:
    with pytest.raises(surfgen.LimitError, match="--grid must be a whole number from"):
        run_config(grid=100_000)
    with pytest.raises(surfgen.SpecError, match="--family must be one of sculpture"):
        run_config(family="statue")


@pytest.mark.parametrize(
    ("walls", "mesh"), [("keep", None), ("remove", "remove"), ("mark", "mark")]
)
def test_mesh_walls(walls: str, mesh: str | None) -> None:
    assert mesh_walls(load_config().with_run(walls=walls)) == mesh
