"""Sampling on a Dask cluster (127.0.0.1 only): the catalogue equals a local run's, also after a
worker process is killed mid-run and after the driver is killed and resumed."""

from __future__ import annotations

import hashlib
import os
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from surfgen.pipelines.cli.main import main
from surfgen.pipelines.run.config import load_config
from surfgen.pipelines.run.executor import ExecutorError
from surfgen.pipelines.run.sampling import run_sample
from tests.support.catalogue_rows import computed_rows

distributed = pytest.importorskip("distributed")  # the `dask` extra, part of `test`
psutil = pytest.importorskip("psutil")  # a dependency of distributed

GRID = 20
N = 4
SEED = 11


def small_config(tmp_path: Path):
    cfg = tmp_path / "cfg.toml"
    cfg.write_text("[run]\nthumbnails = false\n")
    return cfg, load_config(cfg).with_grid(GRID)


def mesh_hashes(root: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in (root / "meshes").glob("*")}


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("local")
    _, cfg = small_config(root)
    summary = run_sample(n=N, seed=SEED, config=cfg, catalogue=root / "cat", workers=2)
    assert summary.accepted == N
    return root / "cat"


@pytest.fixture(scope="module")
def cluster():
    """A two-worker cluster on 127.0.0.1 with nannies, as `dask scheduler` + `dask worker`
    make it (daemonic worker processes included)."""
    with (
        distributed.LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",  # beside the driver's cluster (see cluster.py)
        ) as c,
        distributed.Client(c) as client,
    ):
        client.wait_for_workers(2, timeout=120)  # the tests compare against the full set
        yield c.scheduler_address, client


def test_local_cluster_run_equals_local_run(reference: Path, tmp_path: Path, cluster) -> None:
    _, cfg = small_config(tmp_path)
    summary = run_sample(
        n=N,
        seed=SEED,
        config=cfg,
        catalogue=tmp_path / "cat",
        executor="dask",
        scheduler=cluster[0],
    )
    assert summary.status == "complete" and summary.accepted == N
    assert computed_rows(tmp_path / "cat") == computed_rows(reference)
    # The files came back as bytes and are the very same files.
    assert mesh_hashes(tmp_path / "cat") == mesh_hashes(reference)
    assert not (tmp_path / "cat" / ".staging").exists()


def test_killed_worker_changes_nothing(reference: Path, tmp_path: Path, cluster) -> None:
    address, client = cluster
    _, cfg = small_config(tmp_path)
    killed: list[int] = []

    def kill_a_busy_worker(accepted: int, drawn: int, n: int) -> None:
        if killed:
            return
        busy = [w for w, keys in client.processing().items() if keys]
        if busy:
            pid = client.run(os.getpid, workers=[busy[0]])[busy[0]]
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    summary = run_sample(
        n=N,
        seed=SEED,
        config=cfg,
        catalogue=tmp_path / "cat",
        executor="dask",
        scheduler=address,
        progress=kill_a_busy_worker,
    )
    assert killed, "no worker was busy when the first index committed"
    assert summary.status == "complete"
    assert computed_rows(tmp_path / "cat") == computed_rows(reference)
    assert mesh_hashes(tmp_path / "cat") == mesh_hashes(reference)


@pytest.fixture
def dashboard_port_taken():
    """Dask's default dashboard port 8787 held, as by another cluster or a Jupyter session."""
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", 8787))
            s.listen()
        except OSError:
            pass  # taken already
        yield


# The resumed driver's own cluster finds a dashboard port of its own, without distributed's
# "Port 8787 is already in use" warning on the user's terminal.
@pytest.mark.filterwarnings("error:Port .* is already in use:UserWarning")
def test_driver_killed_and_resumed(
    reference: Path, tmp_path: Path, cluster, dashboard_port_taken
) -> None:
    address, _ = cluster
    cfg_file, _ = small_config(tmp_path)
    cat = tmp_path / "cat"
    args = [
        "sample", "--n", str(N), "--seed", str(SEED), "--grid", str(GRID),
        "--config", str(cfg_file), "--out", str(cat), "--executor", "dask",
    ]  # fmt: skip
    run_cli = "from surfgen.pipelines.cli.main import main; raise SystemExit(main())"
    env = dict(os.environ, SURFGEN_SCHEDULER=address)
    proc = subprocess.Popen(
        [sys.executable, "-c", run_cli, *args],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    db = cat / "catalogue.sqlite"
    deadline = time.monotonic() + 600  # generous: a loaded machine starts Python slowly
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            con = sqlite3.connect(db)
            done = con.execute("SELECT count(*) FROM shapes").fetchone()[0]
            con.close()
        except sqlite3.Error:
            done = 0
        if done >= 1:
            break
        time.sleep(0.02)
    if proc.poll() is None:
        proc.send_signal(signal.SIGKILL)
    proc.wait()
    partial = computed_rows(cat)
    ref = computed_rows(reference)
    assert 0 < len(partial) <= len(ref) and partial == ref[: len(partial)]
    # Resumed without an address: on a LocalCluster of its own this time.
    assert "SURFGEN_SCHEDULER" not in os.environ
    assert main([*args, "--workers", "2", "--resume"]) == 0
    assert computed_rows(cat) == ref
    assert mesh_hashes(cat) == mesh_hashes(reference)


def test_timeouts_and_crashes_stay_on_the_worker(cluster) -> None:
    """A shape that overruns its timeout or kills its process is a result, not a lost worker."""
    from surfgen.pipelines.run.cluster import DaskPool

    address, client = cluster
    before = set(client.scheduler_info()["workers"])
    with DaskPool(time.sleep, 1.0, scheduler=address) as pool:
        results = {r.task: r for r in pool.run([0.0, 3.0, 0.01])}
    assert results[0.0].status == results[0.01].status == "ok"
    assert results[3.0].status == "timeout" and "longer than 1 s" in results[3.0].message
    with DaskPool(os._exit, 5.0, scheduler=address) as pool:
        (result,) = pool.run([3])
    assert result.status == "crashed" and "exit code 3" in result.message
    assert set(client.scheduler_info()["workers"]) == before  # no Dask worker was lost


def test_unreachable_scheduler_is_a_clear_error(tmp_path: Path) -> None:
    import socket

    from surfgen.pipelines.run.cluster import DaskPool

    with socket.socket() as sock:  # a port on 127.0.0.1 that is bound but never listens
        sock.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{sock.getsockname()[1]}"
        with pytest.raises(ExecutorError, match="cannot reach the Dask scheduler at"):
            DaskPool(abs, 1.0, scheduler=address, connect_timeout=1.0)


def test_bad_executor_options_get_one_line_errors(tmp_path: Path, capsys) -> None:
    out = str(tmp_path / "cat")
    assert main(["sample", "--scheduler", "tcp://127.0.0.1:1", "--out", out]) == 1
    assert capsys.readouterr().err.strip() == "error: --scheduler needs --executor dask"
    assert main(["sample", "--executor", "ray", "--out", out]) == 1
    err = capsys.readouterr().err.strip()
    assert err == "error: unknown executor 'ray' (allowed: local, dask)"
    assert not (tmp_path / "cat").exists()
