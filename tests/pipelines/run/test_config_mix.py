"""The mix and the family tables at config load: one-line errors naming what is wrong and what
is allowed; the run's grid reaches the sampler (its priors are bounded by the cell size)."""

from __future__ import annotations

from pathlib import Path

import pytest

from surfgen.generator.errors import SpecError
from surfgen.generator.model.families import family_names
from surfgen.pipelines.run.config import load_config


def load(tmp_path: Path, text: str):
    path = tmp_path / "c.toml"
    path.write_text(text)
    return load_config(path)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "[sampler]\nmix_weights = [0.5, -0.1, 0.2, 0.2, 0.1, 0.1]",
            "mix_weights must be non-negative",
        ),
        ("[sampler]\nmix_weights = [0, 0, 0, 0, 0, 0]", "not all zero"),
        ('[sampler]\nmix = ["sculpture", "statue"]\nmix_weights = [1, 1]', "unknown 'statue'"),
        ('[sampler]\nmix = ["sculpture", "twist"]\nmix_weights = [1]', "the same length"),
        ('[sampler]\nmix = ["twist", "twist"]\nmix_weights = [1, 1]', "lists a name twice"),
        ("[sampler]\nmix = []\nmix_weights = []", "non-empty lists"),
        ('[sampler]\nmix_weights = [1, 1, 1, 1, 1, "a"]', "mix_weights must be"),
        ('[sampler]\nfamily = "statue"', "family must be one of"),
        ("[sampler]\ngrid = 32", "unknown key 'grid' in [sampler] (the grid is [run] grid)"),
        ("[sampler]\nperiod_cells = -1", "period_cells must be from 0 to 64"),
        ("[sampler]\nresolve_tries = 0", "resolve_tries must be from 1 to 100"),
        ("[sampler.infill]\nstrut_cells = 40", "strut_cells must be from 0 to 32"),
        (
            '[sampler.infill]\npatterns = ["gyroid", "lidinoid"]\npattern_weights = [1, 1]',
            "unknown 'lidinoid'",
        ),
        ("[sampler.infill]\nlevel = [0.7, 0.2]", "level must be [low, high]"),
        ("[sampler.assembly]\njoin_weights = [1, -1, 1]", "join_weights must be non-negative"),
        (
            '[sampler.assembly]\narrangements = ["pair", "ring"]\narrangement_weights = [1, 1]',
            "unknown 'ring'",
        ),
        ("[sampler.assembly]\ntube = [0.2, 0.95]", "tube must be from 0.05 to 0.9"),
        ("[sampler.twist]\nlobes = [2, 13]\nlobe_weights = [1, 1]", "lobes must be from 2 to 12"),
        ("[sampler.twist]\nbulge = [-0.5, 0.5]", "bulge must be from 0 to 3"),
        ("[sampler.twist]\nspin = 2", "unknown key 'spin' in [sampler.twist]"),
        ("[sampler.twist]\nbraid_prob = 1.5", "braid_prob must be a probability"),
    ],
)
def test_bad_mixes_and_tables_are_one_line_errors(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(SpecError) as err:
        load(tmp_path, text)
    assert message in str(err.value)
    assert "\n" not in str(err.value)


def test_the_default_mix_has_every_built_in_family_none_above_half() -> None:
    cfg = load_config()
    assert set(cfg.sampler.mix) == set(family_names())
    total = sum(cfg.sampler.mix_weights)
    assert max(cfg.sampler.mix_weights) / total < 0.5
    assert all(cfg.sampler.settings(name) is not None for name in ("infill", "assembly", "twist"))


def test_the_run_grid_reaches_the_sampler(tmp_path: Path) -> None:
    assert load_config().sampler.grid == 64
    cfg = load(tmp_path, "[run]\ngrid = 32")
    assert cfg.sampler.grid == 32
    assert cfg.with_grid(128).sampler.grid == 128
    assert cfg.with_grid(128).with_family("twist").sampler.grid == 128
    assert cfg.hash != cfg.with_grid(128).hash
    # the grid is [run]'s: not written in [sampler], and read back from the TOML the same
    assert "grid" not in cfg.sampler.to_dict() and "grid" not in cfg.sampler.canonical_dict()
    again = load(tmp_path, cfg.to_toml())
    assert again == cfg and again.hash == cfg.hash


def test_a_mix_of_new_families_loads(tmp_path: Path) -> None:
    cfg = load(tmp_path, '[sampler]\nmix = ["infill", "twist"]\nmix_weights = [2, 1]')
    assert cfg.sampler.mix == ("infill", "twist") and cfg.sampler.mix_weights == (2.0, 1.0)
