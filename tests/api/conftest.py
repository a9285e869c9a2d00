"""One small sampling run made twice, through the API and through the CLI, shared by the API's
tests: seed 7 on a 24^3 grid, 6 accepted shapes, with a near-duplicate threshold low enough
that the run rejects some shapes as near duplicates (so :func:`surfgen.shapes` must too)."""

from __future__ import annotations

from pathlib import Path

import pytest

import surfgen
from surfgen.pipelines.cli.main import main

SEED, GRID, N = 7, 24, 6
# Descriptor distances between the first accepted shapes of seed 7 on 24^3 (sampler 10) run
# from about 3 to 8: at 3.5 draw 8 (accepted without the check, 3.0 from draw 6) is a near
# duplicate of one.
CONFIG = "[run]\ndedupe_threshold = 3.5\n"


@pytest.fixture(scope="session")
def run_config_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("config") / "dedupe.toml"
    path.write_text(CONFIG)
    return path


@pytest.fixture(scope="session")
def api_catalogue(
    tmp_path_factory: pytest.TempPathFactory, run_config_file: Path
) -> surfgen.Catalogue:
    out = tmp_path_factory.mktemp("api") / "catalogue"
    return surfgen.sample(N, SEED, grid=GRID, config=run_config_file, out=out, workers=2)


@pytest.fixture(scope="session")
def cli_catalogue(tmp_path_factory: pytest.TempPathFactory, run_config_file: Path) -> Path:
    out = tmp_path_factory.mktemp("cli") / "catalogue"
    args = ["sample", "--n", str(N), "--seed", str(SEED), "--grid", str(GRID)]
    args += ["--config", str(run_config_file), "--workers", "1", "--out", str(out)]
    assert main(args) == 0
    return out
