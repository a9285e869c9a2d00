"""The benchmarks' shared harness (``benchmarks/harness.py``): timing, ratios, the machine
line, JSON output and the children a baseline comparison runs."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from benchmarks import harness


def fake_clock(durations: list[float]):
    """A clock whose successive start/stop pairs are ``durations`` apart."""
    ticks: Iterator[float] = iter(np.cumsum([0.0] + [d for t in durations for d in (t, 1.0)]))
    return lambda: float(next(ticks))


def test_best_of_picks_the_minimum_after_the_warm_up():
    calls = []
    timing = harness.best_of(
        lambda: calls.append(1) or len(calls), 4, warmup=2, clock=fake_clock([3.0, 1.5, 2.0, 4.0])
    )
    assert len(calls) == 6  # two untimed warm-up calls, then four timed ones
    assert timing.times == (3.0, 1.5, 2.0, 4.0)
    assert timing.best == 1.5 and timing.median == 2.5
    assert timing.result == 6  # the last call's result


def test_best_of_needs_one_run():
    with pytest.raises(ValueError):
        harness.best_of(lambda: None, 0)


def test_candidates_take_turns_abba():
    order: list[str] = []
    fns = {name: (lambda name=name: order.append(name) or name) for name in ("a", "b")}
    timings = harness.take_turns(fns, 4, clock=fake_clock([5.0, 1.0, 2.0, 3.0, 4.0, 6.0, 7.0, 8.0]))
    assert order == ["a", "b", "b", "a", "a", "b", "b", "a"]
    assert timings["a"].times == (5.0, 3.0, 4.0, 8.0) and timings["a"].best == 3.0
    assert timings["b"].times == (1.0, 2.0, 6.0, 7.0) and timings["b"].best == 1.0
    assert timings["b"].result == "b"


def test_ratio_is_baseline_over_now():
    assert harness.ratio(3.0, 1.5) == 2.0  # above 1: now is faster
    assert harness.ratio(1.0, 4.0) == 0.25
    with pytest.raises(ValueError):
        harness.ratio(1.0, 0.0)
    summary = harness.ratio_summary([2.0, 4.0, 6.0], [1.0, 2.0, 2.0])
    assert summary == "median 2.000x (quartiles 2.000x / 2.500x), total time 2.400x"


def test_the_machine_line_names_the_cpu_simd_cores_and_versions():
    m = harness.machine()
    assert set(m) >= {"cpu", "simd", "cores", "usable_cores", "load", "python", "numpy", "numba"}
    assert m["simd"] in ("AVX-512", "AVX2", "no AVX2")
    assert m["cores"] >= m["usable_cores"] >= 1
    assert m["numpy"] == np.__version__ and m["python"] == ".".join(map(str, sys.version_info[:3]))
    line = harness.machine_line(m)
    assert line.startswith("machine: ") and m["cpu"] in line and m["simd"] in line
    assert f"numpy {m['numpy']}" in line and f"numba {m['numba']}" in line


def test_the_parser_adds_json_repeats_and_baseline():
    ap = harness.parser("A benchmark.\n\nMore text.", repeats=3, baseline="required")
    args = ap.parse_args(["--baseline", "HEAD~1", "--repeat", "5", "--json", "out.json"])
    assert (args.baseline, args.repeats, args.json) == ("HEAD~1", 5, Path("out.json"))
    assert harness.parser(None).parse_args([]).json is None
    with pytest.raises(SystemExit):
        ap.parse_args([])  # --baseline is required here


def test_json_output_round_trips(tmp_path: Path, capsys):
    args = harness.parser(None, repeats=2).parse_args(["--json", str(tmp_path / "r" / "x.json")])
    run = harness.Run("example", args)
    assert capsys.readouterr().out.startswith("machine: ")
    timing = harness.Timing((0.5, 0.25))
    run.record(seconds=timing, ratios=np.array([1.5, 2.0]), count=np.int64(3), path=tmp_path)
    data = run.save()
    assert json.loads((tmp_path / "r" / "x.json").read_text()) == data
    assert data["benchmark"] == "example" and data["options"] == {"repeats": 2}
    assert data["machine"] == run.machine
    assert data["results"] == {
        "seconds": {"best": 0.25, "median": 0.375, "times": [0.5, 0.25]},
        "ratios": [1.5, 2.0],
        "count": 3,
        "path": str(tmp_path),
    }


def test_without_json_nothing_is_written(tmp_path: Path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    run = harness.Run("example", harness.parser(None).parse_args([]), show_machine=False)
    run.record(x=1)
    assert run.save()["results"] == {"x": 1}
    assert list(tmp_path.iterdir()) == []


def test_a_child_sees_the_checkout_and_reports_json():
    code = "import json, sys, benchmarks.harness as h; print(json.dumps({'code': h.__file__, 'a': sys.argv[1:]}))"
    result, seconds = harness.timed_child(None, code, 1, "x")
    assert result["a"] == ["1", "x"] and seconds > 0
    with pytest.raises(SystemExit, match="expected code under"):
        harness.run_child(Path("/nowhere"), code.replace("h.__file__", "'/elsewhere'"))
    with pytest.raises(subprocess.CalledProcessError):
        harness.run_child(None, "raise SystemExit(3)")


def test_child_env_puts_the_baseline_first(tmp_path: Path, monkeypatch):
    monkeypatch.setenv("PYTHONPATH", "/somewhere")
    monkeypatch.setenv("PYTHONDONTWRITEBYTECODE", "1")
    env = harness.child_env(tmp_path, NUMBA_CACHE_DIR="/cache")
    assert env["PYTHONPATH"].split(":") == [str(tmp_path), str(harness.ROOT), "/somewhere"]
    assert env["NUMBA_CACHE_DIR"] == "/cache" and env["PYTHONDONTWRITEBYTECODE"] == "1"
    bare = harness.child_env(None, with_root=False, write_bytecode=True)
    assert bare["PYTHONPATH"] == "/somewhere" and "PYTHONDONTWRITEBYTECODE" not in bare


def test_a_revision_is_exported_as_an_importable_surfgen(tmp_path: Path):
    path = harness.export_revision("HEAD", tmp_path)
    for name in harness.PACKAGES:
        assert (path / "surfgen" / name / "__init__.py").is_file()
    with harness.revisions(None) as versions:
        assert versions == {"now": None}
