"""The same faults on real file systems: a tiny tmpfs that fills up (in a private mount
namespace, `unshare --mount --map-root-user`) and a read-only catalogue used by a user who
cannot write it (`setpriv` to uid 65534). Skipped, with the reason, where the kernel or the
container does not allow them (the monkeypatched versions in test_bad_input/test_faults run
everywhere)."""

from __future__ import annotations

import json
import os
import shutil
import sqlite3
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from surfgen.generator.eval.reference import evaluate_reference
from surfgen.generator.mesh.mesh import extract_mesh
from surfgen.generator.model.spec import SurfaceSpec
from tests.support.catalogues import catalogue_shapes

CLI = [
    sys.executable,
    "-c",
    "from surfgen.pipelines.cli.main import main; raise SystemExit(main())",
]


def _can(cmd: list[str]) -> bool:
    try:
        return subprocess.run(cmd, capture_output=True, timeout=20).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


UNSHARE = shutil.which("unshare") and _can(
    ["unshare", "--mount", "--map-root-user", "sh", "-c", "mount -t tmpfs none /mnt"]
)
# Acting as another user needs root, setpriv, and a Python that user may run (not so for an
# interpreter built under root's home, as pyenv's, whose libpython nobody may read).
SETPRIV = (
    os.geteuid() == 0
    and shutil.which("setpriv")
    and _can(
        ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", sys.executable, "-c", ""]
    )
)


def in_tmpfs(folder: Path, size: str, script: str) -> subprocess.CompletedProcess:
    """Run the shell ``script`` with a ``size`` tmpfs mounted on ``folder`` (private)."""
    folder.mkdir(parents=True, exist_ok=True)
    body = f"mount -t tmpfs -o size={size} tmpfs '{folder}' && {script}"
    return subprocess.run(
        ["unshare", "--mount", "--map-root-user", "sh", "-c", body],
        capture_output=True,
        text=True,
        timeout=300,
    )


def cli(*args: str) -> str:
    import shlex

    return shlex.join([*CLI, *args])


@pytest.mark.skipif(not UNSHARE, reason="no private mount namespaces (unshare) here")
def test_render_on_a_full_tmpfs_leaves_nothing(tmp_path: Path) -> None:
    disk = tmp_path / "disk"
    out = in_tmpfs(
        disk,
        "96k",
        cli("render", "--preset", "torus", "--grid", "32", "-o", f"{disk}/ok.ply", "--png",
            f"{disk}/x.png") + f"; echo rc=$?; ls -A '{disk}'",
    )  # fmt: skip
    lines = out.stderr.strip().splitlines()
    assert "rc=1" in out.stdout and len(lines) == 1, (out.stdout, out.stderr)
    assert "No space left on device" in lines[0] and "Traceback" not in out.stderr
    assert out.stdout.strip().splitlines()[-1] == "rc=1"  # `ls -A` printed nothing: no file


@pytest.mark.skipif(not UNSHARE, reason="no private mount namespaces (unshare) here")
def test_sample_on_a_disk_that_fills_up_then_resume(tmp_path: Path) -> None:
    from surfgen.pipelines.run.config import load_config
    from surfgen.pipelines.run.sampling import run_sample

    cfg = tmp_path / "cfg.toml"
    cfg.write_text("[run]\nthumbnails = false\n")
    common = ["sample", "--n", "4", "--seed", "11", "--grid", "20", "--workers", "2"]
    common += ["--config", str(cfg)]
    ref = tmp_path / "ref"  # the uninterrupted run, in this process (numba already warm)
    run_sample(n=4, seed=11, config=load_config(cfg).with_grid(20), catalogue=ref, workers=2)
    disk = tmp_path / "disk"
    dump = tmp_path / "dump.json"
    query = (
        "import json, sqlite3, sys; c = sqlite3.connect(sys.argv[1]); "
        "json.dump(c.execute('SELECT idx, key, spec, verdict, reasons, metrics FROM shapes "
        "ORDER BY idx').fetchall(), open(sys.argv[2], 'w'))"
    )
    import shlex

    script = (
        cli(*common, "--out", f"{disk}/cat")
        + "; echo first=$?; "
        + f"mount -o remount,size=64m '{disk}'; "
        + cli(*common, "--out", f"{disk}/cat", "--resume")
        + "; echo second=$?; "
        + shlex.join([sys.executable, "-c", query, f"{disk}/cat/catalogue.sqlite", str(dump)])
    )
    # A disk with room for about 85 % of the finished catalogue (database and meshes) fills up
    # part-way through the run, whatever the sampler draws (a fixed size went stale once).
    size = sum(p.stat().st_size for p in ref.rglob("*") if p.is_file())
    out = in_tmpfs(disk, f"{max(64, int(0.85 * size) // 1024)}k", script)
    assert "first=1" in out.stdout and "second=0" in out.stdout, (out.stdout, out.stderr)
    errors = [ln for ln in out.stderr.splitlines() if ln.startswith("error: ")]
    assert len(errors) == 1 and "Traceback" not in out.stderr, out.stderr
    assert "space" in errors[0] and "--resume" in errors[0] or "disk is full" in errors[0]
    con = sqlite3.connect(ref / "catalogue.sqlite")
    want = con.execute(
        "SELECT idx, key, spec, verdict, reasons, metrics FROM shapes ORDER BY idx"
    ).fetchall()
    con.close()
    assert [tuple(r) for r in json.loads(dump.read_text())] == want


@pytest.mark.skipif(
    not SETPRIV, reason="needs root, setpriv and a Python that another user may run"
)
def test_a_read_only_catalogue_can_be_read_not_written() -> None:
    base = Path(tempfile.mkdtemp(prefix="surfgen-ro-"))
    try:
        base.chmod(0o755)
        root = base / "cat"
        spec = SurfaceSpec("x^2+y^2+z^2-1", (-1.5, 1.5) * 3, (16,) * 3)
        mesh = extract_mesh(evaluate_reference(spec.tree(), spec.to_grid()), 0.0)
        catalogue_shapes(root, [(spec, mesh)])
        for p in [root, *root.rglob("*")]:
            p.chmod(0o555 if p.is_dir() else 0o444)
        names = sorted(p.name for p in root.iterdir())
        as_nobody = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"]
        (base / "numba").mkdir()
        (base / "numba").chmod(0o777)  # numba compiles at import: nobody needs a cache folder
        env = {**os.environ, "HOME": str(base), "NUMBA_CACHE_DIR": str(base / "numba")}
        listing = subprocess.run(
            [*as_nobody, *CLI, "catalogue", "list", "-C", str(root), "--json"],
            capture_output=True, text=True, env=env,
        )  # fmt: skip
        assert listing.returncode == 0, listing.stderr
        key = json.loads(listing.stdout)[0]["key"]
        star = subprocess.run(
            [*as_nobody, *CLI, "catalogue", "star", key, "-C", str(root)],
            capture_output=True, text=True, env=env,
        )  # fmt: skip
        err = star.stderr.strip().splitlines()
        assert star.returncode == 1 and len(err) == 1 and "read-only" in err[0], star.stderr
        assert sorted(p.name for p in root.iterdir()) == names  # no -wal, no -shm
    finally:
        for p in [base, *base.rglob("*")]:
            p.chmod(0o755 if p.is_dir() else 0o644)
        shutil.rmtree(base)
