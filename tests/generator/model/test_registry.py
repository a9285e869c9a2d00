"""The registry of sampler families: a family is one module and one entry (the toy family of
``toy_family.py`` is added here and nowhere else), the per-family config tables, configs
written before the tables, and the config hash they all keep."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

from surfgen.generator.errors import SpecError
from surfgen.generator.model.families import (
    FREE,
    describe_families,
    family_choices,
    family_help,
    family_names,
    register_family,
    registered,
    unregister_family,
)
from surfgen.generator.model.sampler import SamplerConfig, draw_equation, pick_family
from surfgen.pipelines.catalogue.query import FIELDS
from surfgen.pipelines.run.config import default_config_text, load_config
from surfgen.pipelines.run.shapes import make_shape
from tests.generator.model import toy_family

ROOT = Path(__file__).resolve().parents[3]

# Config hashes of the default config, each family alone, and OLD_STYLE (keys of the flat
# layout) with and without --grid 32. First recorded from the code before the family tables
# (commit 32af889); recorded again for sampler version 6 (branch families: new [sampler] keys
# period_cells and resolve_tries, three new family tables, the resolution filter's keys, plain_max_curvature, max_resolution_singular), which
# changes every hash: a catalogue of version 5 is not resumed by version 6, as it should not be;
# and for version 7 (keys chain_links, chain_weights, alternate_prob in [sampler.assembly],
# taper_prob, taper, swell_prob, swell in [sampler.twist], min_inside_fraction 0.003, the
# assembly's arrangement and join weights, [filters] min_body_fraction); and for version 8
# (bend_prob, bend in [sampler.twist]; hollow_prob, shell in [sampler.infill], the infill's
# envelope weights and periods, the assembly's body weights); and for version 9 (a hollow
# torus of infill left uncut: the version is hashed); and for version 10 (aspect_prob, aspect
# in [sampler]: proportions; [filters] max_pieces); and for version 11 (pole planes redrawn:
# the version is hashed); and for version 12 ([filters] min_piece_fraction, plain_min_outline,
# plain_outline_max_genus; the mix's and the assembly's body weights, the infill's periods).
DEFAULT_HASH = "1e632179d729"
FAMILY_HASHES = {"sculpture": "68056f619fd9", "lattice": "ce6b1202fb37", "free": "27c6fee3beda"}
OLD_STYLE = """[sampler]
family = "sculpture"
sculpture_exponent = [2.0, 3.0]
lattice_periods = [1.5, 2.0]
abs_prob = 0.4
"""
OLD_STYLE_HASHES = ("2ad9f9d357f3", "e15ab46f7bff")
NEW_STYLE = """[sampler]
family = "sculpture"
abs_prob = 0.4

[sampler.sculpture]
exponent = [2.0, 3.0]

[sampler.lattice]
periods = [1.5, 2.0]
"""


@pytest.fixture
def toy():
    with registered(toy_family.FAMILY) as family:
        yield family


def config_file(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "c.toml"
    path.write_text(text)
    return path


# ----------------------------------------------------------------------------- the registry


def test_everything_that_lists_families_reads_the_registry() -> None:
    names = ("sculpture", "lattice", "infill", "assembly", "twist", "free")
    assert family_names() == names
    assert family_choices() == (*names, "mix")
    assert family_help() == (
        "sculpture, lattice, infill, assembly, twist, free or mix (default from the config: mix)."
    )
    assert FIELDS["family"].help == (
        "sampler family: sculpture, lattice, infill, assembly, twist or free"
    )
    assert describe_families().splitlines()[0].startswith("sculpture: ")
    cfg = SamplerConfig()
    assert cfg.mix == names and cfg.mix_weights == (0.49, 0.1, 0.17, 0.13, 0.06, 0.05)
    assert [name for name, _ in cfg.tables] == list(names[:-1])  # free has no table


def test_families_build_on_the_sampler_s_base_not_on_the_sampler() -> None:
    """No cycle: the families import ``draw`` (the shared base), never ``sampler``."""
    folder = ROOT / "generator" / "model"
    for path in [folder / "draw.py", *sorted((folder / "families").glob("*.py"))]:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                assert node.module != "surfgen.generator.model.sampler", path.name
                if path.name == "draw.py":
                    assert ".families" not in node.module, path.name


def test_reading_the_registry_loads_no_kernel_library() -> None:
    code = (
        "import sys\n"
        "import surfgen.generator.model.sampler, surfgen.pipelines.catalogue.query\n"
        "print([m for m in ('numba', 'llvmlite', 'scipy') if m in sys.modules])\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.stdout.strip() == "[]", done.stderr


# ----------------------------------------------------------------------------- a new family


def test_a_family_is_one_module_and_one_entry(toy) -> None:
    """The toy family, registered by this test alone, draws pure functions of (seed, index,
    config) that record their structure, and is a choice of ``family`` and ``mix``."""
    assert "toy" in family_choices() and "toy" in family_help()
    cfg = SamplerConfig(family="toy")
    draws = [draw_equation(3, i, cfg) for i in (4, 0, 9)]
    assert [d.model_dict() for d in draws] == [
        draw_equation(3, i, cfg).model_dict() for i in (4, 0, 9)
    ]
    assert draws[0].model_dict() != draw_equation(4, 4, cfg).model_dict()
    model = json.loads(json.dumps(draws[0].model_dict()))
    assert model["family"] == "toy" and 0.5 <= model["structure"]["radius"] <= 1.5
    mix = SamplerConfig(mix=("toy", "free"), mix_weights=(1.0, 1.0))
    picks = {pick_family(5, i, mix) for i in range(40)}
    assert picks == {"toy", "free"}
    assert all(draw_equation(5, i, mix).family == pick_family(5, i, mix) for i in range(8))


def test_a_new_family_reads_its_own_config_table(toy, tmp_path: Path) -> None:
    cfg = load_config(
        config_file(
            tmp_path,
            '[sampler]\nfamily = "toy"\naspect_prob = 0.0\n\n[sampler.toy]\nradius = [1.2, 1.2]\n',
        )
    )
    assert cfg.sampler.settings("toy") == toy_family.ToySettings(radius=(1.2, 1.2))
    draw = draw_equation(7, 0, cfg.sampler)
    assert draw.structure == {"radius": 1.2} and draw.d == 1.44
    assert "[sampler.toy]" in cfg.to_toml()
    assert load_config(config_file(tmp_path, cfg.to_toml())) == cfg
    # the layout before tables works for it too, and its messages name its table
    flat = load_config(config_file(tmp_path, "[sampler]\ntoy_radius = [1.2, 1.2]\n"))
    assert flat.sampler.settings("toy") == cfg.sampler.settings("toy")
    with pytest.raises(SpecError, match=r"^config \[sampler.toy\]: margin must be > 1, got 0.5$"):
        load_config(config_file(tmp_path, "[sampler.toy]\nmargin = 0.5\n"))
    # and a shape of it goes through the pipeline like any other
    out = make_shape(0, seed=7, config=cfg.with_grid(24))
    assert json.loads(out.row["model"])["family"] == "toy"
    assert cfg.with_family("free").sampler.family == "free"


def test_an_unregistered_family_is_an_unknown_one(tmp_path: Path) -> None:
    with registered(toy_family.FAMILY):
        assert SamplerConfig(family="toy").family == "toy"
    with pytest.raises(
        SpecError,
        match="family must be one of sculpture, lattice, infill, assembly, twist, free, mix",
    ):
        SamplerConfig(family="toy")
    with pytest.raises(SpecError, match=r"unknown key 'toy' in \[sampler\]"):
        load_config(config_file(tmp_path, "[sampler.toy]\nmargin = 2.0\n"))
    assert "toy" not in family_choices()
    with pytest.raises(SpecError, match="family 'free' is registered already"):
        register_family(FREE)
    with pytest.raises(SpecError, match="family 'free' is built in"):
        unregister_family("free")


# ----------------------------------------------------------------------------- the tables


def test_config_show_prints_one_table_per_family() -> None:
    import tomllib

    data = tomllib.loads(default_config_text())
    sampler = data["sampler"]
    assert set(sampler["sculpture"]) == set(SamplerConfig().to_dict()["sculpture"])
    assert set(sampler["lattice"]) == set(SamplerConfig().to_dict()["lattice"])
    assert not [k for k in sampler if k.startswith(("sculpture_", "lattice_"))]
    assert load_config().sampler == SamplerConfig()


def test_the_config_hash_is_the_same_in_either_layout(tmp_path: Path) -> None:
    """The catalogue stores the canonical (flat) form and hashes it: the default config, each
    family, and a config in either layout hash to the pinned values (the tables changed no
    hash; sampler version 6 changed them all, see above), so ``--resume`` finds runs made
    with either layout."""
    base = load_config()
    assert base.hash == DEFAULT_HASH
    assert {f: base.with_family(f).hash for f in FAMILY_HASHES} == FAMILY_HASHES
    old = load_config(config_file(tmp_path, OLD_STYLE))
    new = load_config(config_file(tmp_path, NEW_STYLE))
    assert old == new
    assert (old.hash, old.with_grid(32).hash) == OLD_STYLE_HASHES
    assert (new.hash, new.with_grid(32).hash) == OLD_STYLE_HASHES
    flat = base.to_dict()["sampler"]
    assert flat["sculpture_exponent"] == [1.6, 4.0] and flat["lattice_periods"] == [1.0, 2.5]
    assert "sculpture" not in flat and "tables" not in flat


def test_a_catalogue_s_stored_config_reads_back() -> None:
    from surfgen.pipelines.run.config import config_from_dict

    cfg = load_config().with_family("lattice")
    stored = json.loads(json.dumps(cfg.to_dict(), sort_keys=True))
    assert config_from_dict(stored) == cfg


@pytest.mark.parametrize(
    ("toml", "message"),
    [
        (
            "[sampler]\nsculpture_depth = [0.2, 0.3]\n[sampler.sculpture]\ndepth = [0.2, 0.3]\n",
            "config [sampler]: sculpture_depth and [sampler.sculpture] depth both given",
        ),
        ("[sampler]\nsculpture_bogus = 1\n", "unknown key 'sculpture_bogus' in [sampler]"),
        ("[sampler.sculpture]\nbogus = 1\n", "unknown key 'bogus' in [sampler.sculpture]"),
        ("[sampler]\nsculpture = 1\n", "'sampler.sculpture' must be a table"),
        ("[sampler]\nsculpture_exponent = [0.5, 2.0]\n", "[sampler.sculpture]: exponent must"),
        ("[sampler.lattice]\nperiods = [0, 1]\n", "[sampler.lattice]: periods must be > 0"),
        ("[sampler.sculpture]\ndepth = 3\n", "depth must be a list of 2 finite numbers, got 3"),
    ],
)
def test_bad_tables_are_one_line_errors(toml: str, message: str, tmp_path: Path) -> None:
    with pytest.raises(SpecError) as info:
        load_config(config_file(tmp_path, toml))
    assert message in str(info.value) and "\n" not in str(info.value)
