"""Sampling runs: determinism across workers, resume after kill -9, filters, bad options."""

from __future__ import annotations

import json
import re
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from surfgen.filters.verdict import FilterConfig, judge, shape_metrics
from surfgen.generator.errors import SpecError
from surfgen.generator.mesh.exchange import load_mesh
from surfgen.generator.model.sampler import SamplerConfig, draw_equation
from surfgen.pipelines.catalogue.store import CatalogueError, open_catalogue
from surfgen.pipelines.cli.main import main
from surfgen.pipelines.run.config import default_config_text, load_config
from surfgen.pipelines.run.sampling import run_sample
from surfgen.pipelines.run.shapes import make_shape
from tests.support.catalogue_rows import computed_rows, mesh_bytes
from tests.support.processes import python_env

GRID = 20
N = 4


def small_config(tmp_path: Path, extra: str = ""):
    cfg = tmp_path / "cfg.toml"
    cfg.write_text("[run]\nthumbnails = false\n" + extra)
    return load_config(cfg).with_grid(GRID)


def sample_args(cfg_file: Path, cat: Path, workers: int = 2) -> list[str]:
    """The reference run's options."""
    return [
        "sample", "--n", str(N), "--seed", "11", "--grid", str(GRID), "--workers", str(workers),
        "--config", str(cfg_file), "--out", str(cat),
    ]  # fmt: skip


def sample_command(cfg_file: Path, cat: Path) -> list[str]:
    """The reference run, as a command line for a child process."""
    run_cli = "from surfgen.pipelines.cli.main import main; raise SystemExit(main())"
    return [sys.executable, "-c", run_cli, *sample_args(cfg_file, cat)]


def table(root: Path) -> list[tuple]:
    """What must be identical between equivalent runs: everything but timings and files."""
    con = sqlite3.connect(root / "catalogue.sqlite")
    rows = con.execute(
        "SELECT idx, key, spec, formula, d, model, verdict, reasons, metrics FROM shapes ORDER BY idx"
    ).fetchall()
    con.close()
    return rows


@pytest.fixture(scope="module")
def reference_run(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("ref")
    cfg = small_config(root)
    summary = run_sample(n=N, seed=11, config=cfg, catalogue=root / "cat", workers=1)
    assert summary.accepted == N and summary.status == "complete"
    return root / "cat"


def test_same_catalogue_with_one_and_two_workers(reference_run: Path, tmp_path: Path) -> None:
    run_sample(n=N, seed=11, config=small_config(tmp_path), catalogue=tmp_path / "cat", workers=2)
    a, b = table(reference_run), table(tmp_path / "cat")
    assert a == b
    assert sum(r[6] == "accepted" for r in a) == N
    assert a[-1][6] == "accepted"  # the run stops at the n-th accepted index


# The child makes numpy's transcendentals inexact (numpy_maths.py) before surfgen is imported, by
# 1 + 2^-26: enough to show through the 10 significant digits of the stored metrics.
SHIFT_NUMPY = """
import numpy as np
from tests.support.numpy_maths import shift_numpy
plain_arccos = np.arccos
shift_numpy(2.0**-26)
assert np.arccos(0.5) == plain_arccos(0.5) * (1.0 + 2.0**-26)
"""


def test_same_catalogue_when_numpys_maths_differ(reference_run: Path, tmp_path: Path) -> None:
    """The catalogue (specs, verdicts, metrics) depends on no numpy transcendental, so on no
    CPU's SIMD maths: a run whose numpy computes every one of them off gives the same rows."""
    cfg_file = tmp_path / "cfg.toml"
    cfg_file.write_text("[run]\nthumbnails = false\n")
    run_cli = "from surfgen.pipelines.cli.main import main; raise SystemExit(main())"
    code = SHIFT_NUMPY + run_cli
    args = sample_args(cfg_file, tmp_path / "cat", workers=1)
    proc = subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True, env=python_env()
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert computed_rows(tmp_path / "cat") == computed_rows(reference_run)
    assert mesh_bytes(tmp_path / "cat") == mesh_bytes(reference_run)


def test_the_rate_leaves_the_setup_out(monkeypatch, tmp_path: Path, capsys) -> None:
    """A first run compiles before it samples: the summary says how long that took, and the
    rate counts the sampling only."""
    from surfgen.pipelines.cli import sample as cli
    from surfgen.pipelines.run import sampling

    real = sampling.warm_shape_kernels

    def compiling(**kwargs):  # a first run's compile, shortened
        time.sleep(1.0)
        return real(**kwargs)

    monkeypatch.setattr(sampling, "warm_shape_kernels", compiling)
    shown = cli.SHOWN_SETUP
    monkeypatch.setattr(cli, "SHOWN_SETUP", 0.5)  # instead of 5 s
    summary = run_sample(n=N, seed=11, config=small_config(tmp_path), catalogue=tmp_path / "a")
    assert 1.0 <= summary.setup_seconds < summary.seconds
    sampling_minutes = (summary.seconds - summary.setup_seconds) / 60.0
    assert summary.shapes_per_minute == pytest.approx(N / sampling_minutes)

    cfg_file = tmp_path / "cfg.toml"
    cfg_file.write_text("[run]\nthumbnails = false\n")
    assert main(sample_args(cfg_file, tmp_path / "b", workers=1)) == 0
    out = capsys.readouterr().out
    assert re.search(r" in \d+ s \((\d+) s of it getting the workers ready\) — \d+ shapes/min", out)
    monkeypatch.setattr(sampling, "warm_shape_kernels", lambda **kwargs: 0.0)  # nothing to do
    monkeypatch.setattr(cli, "SHOWN_SETUP", shown)
    assert main(sample_args(cfg_file, tmp_path / "c", workers=1)) == 0
    assert "getting the workers ready" not in capsys.readouterr().out


def test_rejected_draws_are_recorded_with_reasons(reference_run: Path) -> None:
    rows = table(reference_run)
    assert [r[0] for r in rows] == list(range(len(rows)))
    for r in rows:
        reasons = json.loads(r[7])
        assert (r[6] == "accepted") == (reasons == [])
    with open_catalogue(reference_run, must_exist=True) as cat:
        (run,) = cat.runs()
        counts = json.loads(run["counts"])
        assert sum(counts.values()) >= len(rows) - N


def test_accepted_meshes_pass_the_filters_again(reference_run: Path) -> None:
    cfg = FilterConfig()
    with open_catalogue(reference_run, must_exist=True) as cat:
        for row in cat.shapes(verdict="accepted"):
            mesh = load_mesh(reference_run / row["mesh_path"])
            spec = json.loads(row["spec"])
            m = shape_metrics(mesh, tuple(spec["box"]))
            assert judge(m, cfg, capped=True).accepted, row["key"]
            assert m["faces"] == row["faces"] and m["genus"] == row["genus"]


def test_shape_is_a_pure_function_of_seed_and_index(tmp_path: Path) -> None:
    cfg = small_config(tmp_path)
    a = make_shape(5, seed=3, config=cfg)
    b = make_shape(5, seed=3, config=cfg)
    assert {k: v for k, v in a.row.items() if k != "timings"} == {
        k: v for k, v in b.row.items() if k != "timings"
    }
    assert draw_equation(3, 5, SamplerConfig()) == draw_equation(3, 5, SamplerConfig())
    assert draw_equation(3, 5, SamplerConfig()) != draw_equation(3, 6, SamplerConfig())


def test_resume_after_kill_gives_the_identical_catalogue(
    reference_run: Path, tmp_path: Path
) -> None:
    cfg_file = tmp_path / "cfg.toml"
    cfg_file.write_text("[run]\nthumbnails = false\n")
    cat = tmp_path / "cat"
    args = sample_command(cfg_file, cat)
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    db = cat / "catalogue.sqlite"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if db.exists():
            try:
                con = sqlite3.connect(db)
                done = con.execute(
                    "SELECT count(*) FROM shapes WHERE verdict='accepted'"
                ).fetchone()[0]
                con.close()
            except sqlite3.Error:
                done = 0
            if done >= 1:
                break
        time.sleep(0.01)
    if proc.poll() is None:
        proc.send_signal(signal.SIGKILL)  # kill -9: no chance to clean up
    proc.wait()
    partial = table(cat)
    # Whatever a kill leaves is exactly the first rows of the uninterrupted run (the run may
    # also have committed its last row just before the kill landed: still a prefix).
    reference = table(reference_run)
    assert 0 < len(partial) <= len(reference) and partial == reference[: len(partial)]
    # Re-running without --resume refuses and leaves the catalogue alone.
    assert main([*sample_args(cfg_file, cat, workers=1)]) == 1
    assert table(cat) == partial
    assert main([*sample_args(cfg_file, cat, workers=2), "--resume"]) == 0
    assert table(cat) == table(reference_run)
    with open_catalogue(cat, must_exist=True) as c:
        files = sorted(p.name for p in c.meshes.glob("*.ply"))
        assert files == sorted(r["key"] + ".ply" for r in c.shapes(verdict="accepted"))
        assert not (cat / ".staging").exists()


def test_impossible_thresholds_end_after_max_draws(tmp_path: Path, capsys) -> None:
    cfg_file = tmp_path / "impossible.toml"
    cfg_file.write_text("[run]\nthumbnails = false\n[filters]\nmin_faces = 100000000\n")
    code = main(
        [
            "sample",
            "--n",
            "2",
            "--seed",
            "1",
            "--grid",
            "16",
            "--workers",
            "1",
            "--config",
            str(cfg_file),
            "--out",
            str(tmp_path / "cat"),
            "--max-draws",
            "6",
        ]
    )
    assert code == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "only 0 of 2 shapes accepted after 6 draws" in err[0]
    assert len(table(tmp_path / "cat")) == 6


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--n", "0"], "--n must be a whole number from 1"),
        (["--n", "-3"], "--n must be a whole number from 1"),
        (["--grid", "3"], "--grid must be a whole number from 4 to 2048"),
        (["--workers", "0"], "--workers must be a whole number from 1"),
        (["--config", "/nonexistent/cfg.toml"], "cannot read config /nonexistent/cfg.toml"),
        (["--n", "abc"], "Invalid value for '--n'"),
    ],
)
def test_bad_options_get_one_line_errors(args, message, tmp_path: Path, capsys) -> None:
    code = main(["sample", "--out", str(tmp_path / "cat"), *args])
    assert code != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


@pytest.mark.parametrize(
    ("toml", "message"),
    [
        ("[sampler]\nnot_a_key = 1\n", "unknown key 'not_a_key' in [sampler]"),
        ("[nonsense]\na = 1\n", "unknown table [nonsense]"),
        ("[filters]\nmax_flip_fraction = 2.0\n", "max_flip_fraction must be in [0, 1]"),
        ("[sampler]\nsum_terms = [1, 2]\n", "sum_terms and sum_terms_weights"),
        ("this is = not toml [", "is not valid TOML"),
    ],
)
def test_bad_configs_are_refused(toml: str, message: str, tmp_path: Path, capsys) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text(toml)
    assert main(["sample", "--config", str(cfg), "--out", str(tmp_path / "cat")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "cat").exists()


def test_default_toml_matches_the_dataclass_defaults() -> None:
    cfg = load_config()
    assert cfg.sampler == SamplerConfig()
    assert cfg.filters == FilterConfig()
    assert "[sampler]" in default_config_text()


def test_config_hash_changes_with_what_shapes_depend_on(tmp_path: Path) -> None:
    base = load_config()
    assert base.hash == load_config().hash
    assert base.with_grid(32).hash != base.hash
    f = tmp_path / "c.toml"
    f.write_text("[run]\ntimeout = 5.0\nthumbnails = false\n")
    assert load_config(f).hash == base.hash  # timeouts and pictures do not change shapes
    f.write_text("[sampler]\nabs_prob = 0.5\n")
    assert load_config(f).hash != base.hash


def test_config_hash_is_kept_and_follows_a_changed_copy() -> None:
    import hashlib
    import json
    import pickle

    base = load_config()
    text = json.dumps(base.shape_dict(), sort_keys=True, separators=(",", ":"))
    assert base.hash == hashlib.sha256(text.encode()).hexdigest()[:12]
    assert base.__dict__["hash"] == base.hash  # computed once, kept on the frozen config
    copied = pickle.loads(pickle.dumps(base))  # as a worker receives it
    assert copied == base and copied.hash == base.hash
    other = base.with_grid(32)  # a new config: its own hash, not the kept one
    assert "hash" not in other.__dict__ and other.hash != base.hash


def test_sampler_config_validation() -> None:
    with pytest.raises(SpecError, match="probability"):
        SamplerConfig(abs_prob=1.5)
    with (
        pytest.raises(CatalogueError, match="no catalogue"),
        open_catalogue(Path("/nonexistent/cat"), must_exist=True),
    ):
        pass


def test_render_from_catalogue_regenerates_the_shape(
    reference_run: Path, tmp_path: Path, capsys
) -> None:
    with open_catalogue(reference_run, must_exist=True) as cat:
        row = cat.shapes(verdict="accepted")[0]
    out = tmp_path / "again.ply"
    assert (
        main(
            [
                "render",
                "--from",
                str(reference_run),
                row["key"][:8],
                "--cap",
                "-o",
                str(out),
                "--json",
            ]
        )
        == 0
    )
    r = json.loads(capsys.readouterr().out)
    assert r["key"] == row["key"] and r["formula"] == row["formula"] and r["faces"] == row["faces"]
    assert main(["render", "--from", str(reference_run), "ffffffffff"]) == 1
    assert "no shape with key 'ffffffffff'" in capsys.readouterr().err
    assert main(["render", "--from", str(tmp_path / "none"), "abc"]) == 1
    assert "no catalogue at" in capsys.readouterr().err


def test_dedupe_on_the_fly_marks_what_each_duplicate_copies(tmp_path: Path, capsys) -> None:
    """With a threshold that calls everything a near duplicate, only the first shape stays."""
    cfg_file = tmp_path / "cfg.toml"
    cfg_file.write_text("[run]\nthumbnails = false\ndedupe_threshold = 100.0\n")
    cat = tmp_path / "cat"
    args = [
        "sample",
        "--n",
        "2",
        "--seed",
        "11",
        "--grid",
        str(GRID),
        "--workers",
        "1",
        "--config",
        str(cfg_file),
        "--out",
        str(cat),
        "--max-draws",
        "30",
    ]
    assert main([*args, "--dedupe"]) == 1  # only 1 of 2 accepted: the rest are duplicates
    with open_catalogue(cat, must_exist=True) as c:
        (first,) = c.shapes(verdict="accepted")
        dups = [
            r for r in c.shapes(verdict="rejected") if json.loads(r["reasons"]) == ["duplicate"]
        ]
        assert dups and all(r["duplicate_of"] == first["key"] for r in dups)
        assert first["descriptor"]
    # --no-dedupe keeps near duplicates (the default, [run] dedupe, rejects them)
    kept = [str(tmp_path / "kept") if a == str(cat) else a for a in args]
    assert main([*kept, "--no-dedupe"]) == 0
    with open_catalogue(tmp_path / "kept", must_exist=True) as c:
        assert len(c.shapes(verdict="accepted")) == 2


def test_ctrl_c_keeps_the_catalogue_and_says_how_to_resume(
    reference_run: Path, tmp_path: Path
) -> None:
    cfg_file = tmp_path / "cfg.toml"
    cfg_file.write_text("[run]\nthumbnails = false\n")
    cat = tmp_path / "cat"
    args = sample_command(cfg_file, cat)
    proc = subprocess.Popen(
        args,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    db = cat / "catalogue.sqlite"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None and not db.exists():
        time.sleep(0.02)
    # at once: the run is forking its workers then (a Ctrl-C in the fork used to be lost)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1].startswith("interrupted: ")
    assert main([*sample_args(cfg_file, cat, workers=1), "--resume"]) == 0
    assert table(cat) == table(reference_run)


def test_render_from_catalogue_takes_overrides(reference_run: Path, capsys) -> None:
    with open_catalogue(reference_run, must_exist=True) as cat:
        key = cat.shapes(verdict="accepted")[0]["key"]
    args = [
        "render",
        "--from",
        str(reference_run),
        key,
        "--grid",
        "12",
        "--level",
        "0.25",
        "--json",
    ]
    assert main(args) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["grid"] == [12, 12, 12] and r["level"] == 0.25
    assert main(["render", "--from", str(reference_run), key, "--preset", "sphere"]) == 1
    assert "exactly one of --preset, --formula, --spec or --from" in capsys.readouterr().err


def test_sample_renders_thumbnails_and_leaves_turntables_for_first_view(tmp_path: Path) -> None:
    from PIL import Image

    from surfgen.pipelines.web.app import create_app

    cat = tmp_path / "cat"
    run_sample(n=1, seed=11, config=load_config().with_grid(GRID), catalogue=cat, workers=1)
    with open_catalogue(cat, must_exist=True) as c:
        (row,) = c.shapes(verdict="accepted")
    key = row["key"]
    assert row["thumb_path"] == f"thumbs/{key}.png" and row["turntable_path"] is None
    with Image.open(cat / row["thumb_path"]) as im:
        assert im.size == (256, 256)
    assert not any((cat / "turntables").iterdir())
    res = create_app(cat).test_client().get(f"/turntables/{key}.png")
    assert res.status_code == 200 and (cat / "turntables" / f"{key}.png").is_file()


def test_workers_stop_at_a_known_duplicate_with_the_row_the_parent_gives(
    reference_run: Path, tmp_path: Path
) -> None:
    """A second run of the reference's seed into a copy of its catalogue (another config hash,
    the same shapes) meets only duplicates. Workers that know the accepted shapes stop at the
    near-duplicate check; the rows are those a worker that went on to every check would give
    (the parent judges duplicates at that point, from that point's row)."""
    import shutil

    from surfgen.pipelines.run.duplicates import AcceptedDescriptors, publish

    cat = tmp_path / "cat"
    shutil.copytree(reference_run, cat)
    con = sqlite3.connect(cat / "catalogue.sqlite")
    con.row_factory = sqlite3.Row
    drawn = con.execute("SELECT count(*) FROM shapes").fetchone()[0]
    config = small_config(tmp_path, "dedupe_threshold = 0.999\n")
    summary = run_sample(n=1, seed=11, config=config, catalogue=cat, workers=2, max_draws=drawn)
    # the workers knew run 1's shapes from the start: no duplicate got as far as its files
    assert summary.accepted == 0 and "io" not in summary.stage_seconds
    first = con.execute("SELECT * FROM shapes WHERE run = 1 AND verdict = 'accepted'").fetchall()
    rows = con.execute("SELECT * FROM shapes WHERE run = 2 ORDER BY idx").fetchall()
    dups = [r for r in rows if json.loads(r["reasons"]) == ["duplicate"]]
    # every accepted shape of run 1 meets itself; another draw may be near one of them (run 1
    # rejected it later in the cascade, on the finer grid)
    keys = {f["identity"]: f["key"] for f in first}
    assert {r["duplicate_of"] for r in dups} <= set(keys.values())
    dups = [r for r in dups if r["identity"] in keys]
    assert len(dups) == N
    seen = AcceptedDescriptors(tmp_path / "accepted.tsv", config.run.dedupe_threshold)
    assert not seen.near(np.zeros(10))  # no file: knows nothing
    publish(seen.path, [(r["key"], r["descriptor"]) for r in first])
    compared = ("key", "spec", "d", "model", "verdict", "reasons", "metrics", "descriptor")
    for r in dups:
        assert r["duplicate_of"] == keys[r["identity"]]
        # the mesh checks' metrics (topology, solidity), not the finer grid's
        metrics = json.loads(r["metrics"])
        assert r["faces"] and r["genus"] is not None and "solidity" in metrics
        assert "resolution_shift" not in metrics
        stopped = make_shape(r["idx"], seed=11, config=config, duplicates=seen)
        went_on = make_shape(r["idx"], seed=11, config=config)
        assert stopped.early_stop and not went_on.early_stop and went_on.verdict.accepted
        for outcome in (stopped, went_on):
            assert [outcome.early_row[c] for c in compared] == [r[c] for c in compared]
    con.close()


def test_a_workers_view_of_accepted_shapes_skips_what_it_cannot_read(tmp_path: Path) -> None:
    """Garbage, a record cut by a failed append and a last line still being written are
    skipped; the whole records count."""
    from surfgen.filters.descriptor import descriptor, descriptor_to_text
    from surfgen.generator.eval.evaluate import evaluate
    from surfgen.generator.eval.grid import Box, Grid
    from surfgen.generator.formula.parser import parse
    from surfgen.generator.mesh.mesh import extract_mesh
    from surfgen.pipelines.run.duplicates import AcceptedDescriptors, publish

    mesh = extract_mesh(evaluate(parse("x^2+y^2+z^2-1"), Grid(Box.cube(1.5), (20,) * 3)))
    values = descriptor(mesh)
    text = descriptor_to_text(values)
    path = tmp_path / "accepted.tsv"
    path.write_bytes(b"\xff\xfegarbage\n" + b"cut\t" + text[:100].encode())  # a cut record
    seen = AcceptedDescriptors(path, 1.0)
    assert not seen.near(values)
    publish(path, [("ball", text)])  # lands on the cut record's line: that line is lost
    assert not seen.near(values)
    with open(path, "a") as f:
        f.write(f"ball\t{text[:50]}")  # being written: not read yet
    assert not seen.near(values)
    with open(path, "a") as f:
        f.write(f"{text[50:]}\n")
    assert seen.near(values)
