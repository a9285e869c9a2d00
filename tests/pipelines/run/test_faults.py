"""Faults as tests: workers die with their parent, a full disk stops `sample` cleanly and
`--resume` ends identical to an uninterrupted run, `serve` and `sample` share a catalogue."""

from __future__ import annotations

import errno
import os
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from surfgen.pipelines.cli.main import main
from surfgen.pipelines.run.config import load_config
from surfgen.pipelines.run.sampling import run_sample

GRID = 20


def children_of(pid: int) -> list[int]:
    """Live (not zombie) processes whose parent is ``pid``."""
    out = []
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            stat = Path(f"/proc/{name}/stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2 :].split()
        if int(fields[1]) == pid and fields[0] != "Z":
            out.append(int(name))
    return out


def alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2] != "Z"  # a zombie is dead, only not yet reaped


def start_sample(tmp_path: Path, n: int = 500) -> subprocess.Popen:
    cfg = tmp_path / "cfg.toml"
    cfg.write_text("[run]\nthumbnails = false\n")
    code = "from surfgen.pipelines.cli.main import main; raise SystemExit(main())"
    args = ["sample", "--n", str(n), "--seed", "5", "--grid", str(GRID), "--workers", "2"]
    args += ["--config", str(cfg), "--out", str(tmp_path / "cat")]
    return subprocess.Popen(
        [sys.executable, "-c", code, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )


def wait_for_workers(proc: subprocess.Popen, count: int = 2, seconds: float = 60) -> list[int]:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        kids = children_of(proc.pid)
        if len(kids) >= count:
            return kids
        assert proc.poll() is None, proc.stderr.read().decode()
        time.sleep(0.2)
    raise AssertionError("the workers never started")


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_workers_die_with_their_parent(tmp_path: Path, sig: int) -> None:
    proc = start_sample(tmp_path)
    try:
        workers = wait_for_workers(proc)
        time.sleep(1.0)  # let them take a shape each
        proc.send_signal(sig)
        proc.wait(timeout=30)
        deadline = time.monotonic() + 5
        while any(alive(w) for w in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(alive(w) for w in workers), "a worker outlived its parent"
        # `surfgen sample | cat` ends: no worker keeps the pipe open
        out = proc.stdout.read()
        assert isinstance(out, bytes)
    finally:
        if proc.poll() is None:
            proc.kill()
    if sig == signal.SIGTERM:  # a plain kill ends the run like Ctrl-C, marked interrupted
        assert proc.returncode == 130
        con = sqlite3.connect(tmp_path / "cat" / "catalogue.sqlite")
        assert con.execute("SELECT status FROM runs").fetchone()[0] == "interrupted"
        con.close()
        err = proc.stderr.read().decode()
        assert "Traceback" not in err and "interrupted" in err


# ----------------------------------------------------------------------------- disk full


def small_config(tmp_path: Path):
    cfg = tmp_path / "cfg.toml"
    cfg.write_text("[run]\nthumbnails = false\n")
    return load_config(cfg).with_grid(GRID)


def table(root: Path) -> list[tuple]:
    con = sqlite3.connect(root / "catalogue.sqlite")
    rows = con.execute(
        "SELECT idx, key, spec, formula, d, model, verdict, reasons, metrics, mesh_path "
        "FROM shapes ORDER BY idx"
    ).fetchall()
    runs = con.execute(
        "SELECT seed, n, grid, config_hash, status, next_index, accepted, counts FROM runs"
    ).fetchall()
    con.close()
    return rows + runs


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("full") / "cat"
    summary = run_sample(n=4, seed=11, config=small_config(root.parent), catalogue=root, workers=2)
    assert summary.status == "complete"
    return root


def test_disk_full_during_sample_stops_then_resume_is_identical(
    uninterrupted: Path, tmp_path: Path, monkeypatch, capsys
) -> None:
    import surfgen.pipelines.run.shapes as one_shape

    accepted = [r for r in table(uninterrupted) if len(r) == 10 and r[6] == "accepted"]
    victim = accepted[2][1]  # the disk fills up when the third accepted shape is written
    real = one_shape.write_atomic

    def full_disk(path, data):
        if Path(path).name.startswith(victim):
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, data)

    monkeypatch.setattr(one_shape, "write_atomic", full_disk)  # the workers fork with it
    cat = tmp_path / "cat"
    cfg = tmp_path / "cfg.toml"
    cfg.write_text("[run]\nthumbnails = false\n")
    args = ["sample", "--n", "4", "--seed", "11", "--grid", str(GRID), "--workers", "2"]
    args += ["--config", str(cfg), "--out", str(cat)]
    assert main(args) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: cannot write "), err
    assert "No space left on device" in err[0] and "--resume" in err[0]
    rows = table(cat)
    shapes = [r for r in rows if len(r) == 10]
    # a prefix of the uninterrupted run, without the shape that could not be written
    assert shapes == [r for r in table(uninterrupted) if len(r) == 10][: len(shapes)]
    assert victim not in {r[1] for r in shapes}
    assert all("crashed" not in r[7] for r in shapes)
    assert rows[-1][4] == "interrupted"
    # space is freed: --resume ends exactly as the uninterrupted run
    monkeypatch.setattr(one_shape, "write_atomic", real)
    assert main([*args, "--resume"]) == 0
    capsys.readouterr()
    assert table(cat) == table(uninterrupted)
    assert sorted(p.name for p in (cat / "meshes").iterdir()) == sorted(
        p.name for p in (uninterrupted / "meshes").iterdir()
    )
    assert not (cat / ".staging").exists()


def test_sqlite_disk_full_in_the_parent_stops_then_resume_is_identical(
    uninterrupted: Path, tmp_path: Path, monkeypatch, capsys
) -> None:
    """The catalogue's database cannot grow (SQLite's own SQLITE_FULL, made real with
    ``PRAGMA max_page_count`` on the sampler's connection) when the third accepted shape is
    committed: one line, the catalogue opens and passes `catalogue check`, holds exactly the
    shapes before it (no row without files, no file without row), and --resume ends as an
    uninterrupted run."""
    from surfgen.pipelines.catalogue.store import Catalogue

    want = table(uninterrupted)
    accepted = [r for r in want if len(r) == 10 and r[6] == "accepted"]
    victim = accepted[2][1]
    real = Catalogue.record_shape
    full: list[str] = []

    def record_on_a_full_disk(self, run_id, index, row, accepted, counts):
        if row["key"] == victim:  # from here on the database has no room for a new page
            pages = self.conn.execute("PRAGMA page_count").fetchone()[0]
            self.conn.execute(f"PRAGMA max_page_count = {pages}")
            try:
                return real(self, run_id, index, row, accepted, counts)
            except sqlite3.OperationalError as exc:
                full.append(str(exc))
                raise
        return real(self, run_id, index, row, accepted, counts)

    monkeypatch.setattr(Catalogue, "record_shape", record_on_a_full_disk)
    cat = tmp_path / "cat"
    cfg = tmp_path / "cfg.toml"
    cfg.write_text("[run]\nthumbnails = false\n")
    args = ["sample", "--n", "4", "--seed", "11", "--grid", str(GRID), "--workers", "2"]
    args += ["--config", str(cfg), "--out", str(cat)]
    assert main(args) == 1
    assert full == ["database or disk is full"]  # the fault was SQLite's own
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: cannot write catalogue "), err
    assert str(cat / "catalogue.sqlite") in err[0] and "database or disk is full" in err[0]
    assert "--resume" in err[0] and "Traceback" not in err[0]
    shapes = [r for r in table(cat) if len(r) == 10]
    assert shapes == [r for r in want if len(r) == 10][: len(shapes)]  # a prefix
    assert victim not in {r[1] for r in shapes} and len(shapes) >= 2  # two accepted before it
    # every row's mesh is there and every mesh has its row; nothing staged is left
    named = {Path(r[9]).name for r in shapes if r[9]}
    assert {p.name for p in (cat / "meshes").iterdir()} == named
    assert not (cat / ".staging").exists()
    assert main(["catalogue", "check", "-C", str(cat)]) == 0
    assert "orphan files (no row names them): 0" in capsys.readouterr().out
    monkeypatch.setattr(Catalogue, "record_shape", real)  # space is freed
    assert main([*args, "--resume"]) == 0
    capsys.readouterr()
    assert table(cat) == want


# ----------------------------------------------------------------------------- serve + sample


def test_serve_and_sample_share_a_catalogue_under_200_requests(
    uninterrupted: Path, tmp_path: Path
) -> None:
    import shutil

    from surfgen.pipelines.web.app import create_app

    cat = tmp_path / "cat"
    shutil.copytree(uninterrupted, cat)
    con = sqlite3.connect(cat / "catalogue.sqlite")
    keys = [r[0] for r in con.execute("SELECT key FROM shapes WHERE verdict='accepted'")]
    con.close()
    cfg = tmp_path / "cfg.toml"
    cfg.write_text("[run]\nthumbnails = false\n")
    code = "from surfgen.pipelines.cli.main import main; raise SystemExit(main())"
    args = ["sample", "--n", "400", "--seed", "11", "--grid", str(GRID), "--workers", "2"]
    args += ["--config", str(cfg), "--out", str(cat), "--resume"]
    proc = subprocess.Popen(
        [sys.executable, "-c", code, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    client = create_app(cat).test_client()
    statuses: list[int] = []
    errors: list[str] = []

    def hammer(worker: int) -> None:
        for i in range(50):
            key = keys[(worker + i) % len(keys)]
            action, body = [
                ("star", {"stars": i % 6}),
                ("tag", {"tags": [f"t{worker}-{i}"]}),
                ("note", {"note": f"note {worker} {i}"}),
            ][i % 3]
            res = client.post(f"/api/shapes/{key}/{action}", json=body)
            statuses.append(res.status_code)
            if res.status_code != 200:
                errors.append(res.get_data(as_text=True))

    def drawn() -> int:
        c = sqlite3.connect(f"file:{cat / 'catalogue.sqlite'}?mode=ro", uri=True)
        try:
            return c.execute("SELECT next_index FROM runs").fetchone()[0]
        finally:
            c.close()

    start = drawn()
    try:
        wait_for_workers(proc)
        deadline = time.monotonic() + 60
        while drawn() == start and time.monotonic() < deadline:  # the run is writing now
            time.sleep(0.1)
        threads = [threading.Thread(target=hammer, args=(w,)) for w in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=60)
    assert errors == [] and statuses == [200] * 200
    con = sqlite3.connect(cat / "catalogue.sqlite")
    assert con.execute("SELECT count(*) FROM curation").fetchone()[0] == 200  # none lost
    tag_actions = 4 * len([i for i in range(50) if i % 3 == 1])  # each a distinct new tag
    assert con.execute("SELECT count(*) FROM tags").fetchone()[0] == tag_actions
    con.close()
    err = proc.stderr.read().decode()
    assert "locked" not in err and "Traceback" not in err, err
    assert drawn() > start + 1  # sampling went on while the requests were served
