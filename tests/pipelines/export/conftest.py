"""A small sampled catalogue and its dataset export, shared by the dataset tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from surfgen.pipelines.catalogue.store import open_catalogue
from surfgen.pipelines.cli.main import main
from surfgen.pipelines.run.config import load_config
from surfgen.pipelines.run.sampling import run_sample

DATASET_SHAPES = 3


@pytest.fixture(scope="session")
def dataset_catalogue(tmp_path_factory) -> Path:
    """A catalogue of :data:`DATASET_SHAPES` accepted shapes with thumbnails, one of them
    starred and tagged."""
    root = tmp_path_factory.mktemp("ds")
    cfg = load_config().with_grid(20)
    run_sample(n=DATASET_SHAPES, seed=5, config=cfg, catalogue=root / "cat", workers=2)
    with open_catalogue(root / "cat", must_exist=True) as cat:
        key = cat.shapes(verdict="accepted")[0]["key"]
    assert main(["catalogue", "star", key, "4", "-C", str(root / "cat")]) == 0
    assert main(["catalogue", "tag", key, "lattice", "-C", str(root / "cat")]) == 0
    return root / "cat"


def export_args(catalogue: Path, out: Path, *extra: str) -> list[str]:
    """``surfgen dataset export`` of ``catalogue`` into ``out``: 2 samples a shard, 64 surface
    points and 50 field samples a shape, unless ``extra`` says otherwise."""
    shards = [] if "--max-shard-bytes" in extra else ["--shard-size", "2"]
    return ["dataset", "export", "-C", str(catalogue), "-o", str(out), *shards,
            "--points", "64", "--sdf", "50", *extra]  # fmt: skip


@pytest.fixture(scope="session")
def dataset_export(dataset_catalogue: Path, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("export") / "ds"
    assert main(export_args(dataset_catalogue, out)) == 0
    return out
