"""`surfgen dataset export|verify`: WebDataset shards, Parquet metadata, determinism, verify."""

from __future__ import annotations

import hashlib
import io
import json
import shutil
import tarfile
from pathlib import Path

import numpy as np
import pytest

from surfgen.pipelines.catalogue.store import open_catalogue
from surfgen.pipelines.cli.main import main
from surfgen.pipelines.export.dataset import split_of, surface_points
from surfgen.pipelines.run.config import load_config
from surfgen.pipelines.run.sampling import run_sample

pa = pytest.importorskip("pyarrow")  # the `dataset` extra, part of `test`
pq = pytest.importorskip("pyarrow.parquet")
N = 3


@pytest.fixture(scope="module")
def catalogue(tmp_path_factory) -> Path:
    """A small sampled catalogue with thumbnails, one shape starred and tagged."""
    root = tmp_path_factory.mktemp("ds")
    cfg = load_config().with_grid(20)
    run_sample(n=N, seed=5, config=cfg, catalogue=root / "cat", workers=2)
    with open_catalogue(root / "cat", must_exist=True) as cat:
        key = cat.shapes(verdict="accepted")[0]["key"]
    assert main(["catalogue", "star", key, "4", "-C", str(root / "cat")]) == 0
    assert main(["catalogue", "tag", key, "lattice", "-C", str(root / "cat")]) == 0
    return root / "cat"


def export(catalogue: Path, out: Path, *extra: str) -> int:
    return main(
        ["dataset", "export", "-C", str(catalogue), "-o", str(out), "--shard-size", "2",
         "--points", "64", "--sdf", "50", *extra]
    )  # fmt: skip


@pytest.fixture(scope="module")
def exported(catalogue: Path, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("export") / "ds"
    assert export(catalogue, out) == 0
    return out


def sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def test_shards_and_parquet_agree_with_the_catalogue(catalogue: Path, exported: Path) -> None:
    with open_catalogue(catalogue, must_exist=True) as cat:
        accepted = {r["key"]: r for r in cat.shapes(verdict="accepted")}
    table = pq.read_table(exported / "metadata.parquet")
    rows = table.to_pylist()
    assert table.num_rows == N == len(accepted)
    assert [r["key"] for r in rows] == sorted(accepted)  # ordered by key
    metric_names = set(json.loads(next(iter(accepted.values()))["metrics"]))
    assert metric_names <= set(table.column_names)
    shards = sorted((exported / "shards").glob("shard-*.tar"))
    assert [p.name for p in shards] == ["shard-000000.tar", "shard-000001.tar"]
    members: dict[str, bytes] = {}
    for shard in shards:
        with tarfile.open(shard) as tar:
            for m in tar.getmembers():
                assert m.mtime == 946684800 and m.uid == 0 and m.mode == 0o644
                members[m.name] = tar.extractfile(m).read()
    assert len({name.split(".")[0] for name in members}) == N
    for r in rows:
        key, src = r["key"], accepted[r["key"]]
        assert r["split"] == split_of(key) in ("train", "val", "test")
        assert r["genus"] == src["genus"] and r["faces"] == src["faces"]
        for kind in ("json", "mesh", "thumb", "points", "sdf"):
            assert sha(members[r[f"{kind}_file"]]) == r[f"{kind}_sha256"], (key, kind)
        assert members[f"{key}.ply"] == (catalogue / src["mesh_path"]).read_bytes()
        assert members[f"{key}.png"][:8] == b"\x89PNG\r\n\x1a\n"
        sidecar = json.loads(members[f"{key}.json"])
        assert sidecar["key"] == key and sidecar["metrics"] == json.loads(src["metrics"])
        points = np.load(io.BytesIO(members[f"{key}.points.npy"]))
        assert points.shape == (64, 6) and points.dtype == np.float32
        assert np.allclose(np.linalg.norm(points[:, 3:], axis=1), 1, atol=1e-5)
        box = np.array(sidecar["spec"]["box"])
        assert (points[:, :3] >= box[0::2] - 1e-5).all() and (
            points[:, :3] <= box[1::2] + 1e-5
        ).all()
        with np.load(io.BytesIO(members[f"{key}.sdf.npz"])) as z:
            assert z["points"].shape == (50, 3) and z["f"].shape == (50,)
            assert ((z["f"] < 0) == (z["sign"] == -1)).all()
            both = np.isfinite(z["f_normalised"])
            assert (np.sign(z["f_normalised"][both]) == np.sign(z["f"][both])).all()
    starred = [r for r in rows if r["stars"]]
    assert len(starred) == 1 and starred[0]["tags"] == ["lattice"]
    assert starred[0]["curation"] == "starred"
    card = (exported / "README.md").read_text()
    assert card.startswith("---\nlicense: mit\n") and "size_categories:\n- n<1K" in card
    assert "the implicit function, not a signed distance" in card
    assert f"surfgen sample --n {N} --seed 5 --grid 20" in card


def test_webdataset_reads_the_shards(exported: Path) -> None:
    wds = pytest.importorskip("webdataset")
    urls = [str(p) for p in sorted((exported / "shards").glob("*.tar"))]
    samples = list(wds.WebDataset(urls, shardshuffle=False, empty_check=False))
    assert len(samples) == N
    for s in samples:
        assert {"json", "ply", "png", "points.npy", "sdf.npz"} <= set(s)
        assert json.loads(s["json"])["key"] == s["__key__"]


def test_surface_points_face_outwards(sphere_mesh) -> None:
    p = surface_points(sphere_mesh, 500, "0123456789abcdef")
    assert ((p[:, :3] * p[:, 3:]).sum(axis=1) > 0.9).all()
    assert np.array_equal(p, surface_points(sphere_mesh, 500, "0123456789abcdef"))
    assert not np.array_equal(p, surface_points(sphere_mesh, 500, "0123456789abcdee"))


def files(root: Path) -> dict[Path, bytes]:
    return {p.relative_to(root): p.read_bytes() for p in root.rglob("*") if p.is_file()}


def test_export_twice_gives_the_same_bytes(catalogue: Path, tmp_path: Path) -> None:
    out = tmp_path / "ds"
    assert export(catalogue, out) == 0
    first = files(out)
    shutil.rmtree(out)
    assert export(catalogue, out) == 0  # the same command again
    assert files(out) == first
    assert {p.name for p in first} >= {"README.md", "metadata.parquet", "runs.json"}


def test_verify_passes_then_catches_tampering(exported: Path, tmp_path: Path, capsys) -> None:
    assert main(["dataset", "verify", str(exported), "--sample", "10"]) == 0
    assert f"{N} of {N} rows regenerated: all agree" in capsys.readouterr().out
    # A shipped label that disagrees with the generator.
    bad = shutil.copytree(exported, tmp_path / "bad-label")
    table = pq.read_table(bad / "metadata.parquet")
    genus = table.column("genus").to_pylist()
    genus[0] += 1
    table = table.set_column(table.column_names.index("genus"), "genus", pa.array(genus))
    pq.write_table(table, bad / "metadata.parquet")
    assert main(["dataset", "verify", str(bad), "--sample", "10"]) == 1
    out = capsys.readouterr().out
    assert "metric genus is" in out and "in metadata.parquet" in out and "1 disagreement" in out
    # A mesh whose bytes changed in its shard.
    bad = shutil.copytree(exported, tmp_path / "bad-mesh")
    shard = bad / "shards" / "shard-000000.tar"
    with tarfile.open(shard) as tar:
        items = [(m, tar.extractfile(m).read()) for m in tar.getmembers()]
    with tarfile.open(shard, "w", format=tarfile.USTAR_FORMAT) as tar:
        for m, data in items:
            if m.name.endswith(".ply"):
                data = data[:-1] + bytes([data[-1] ^ 1])
            tar.addfile(m, io.BytesIO(data))
    assert main(["dataset", "verify", str(bad), "--sample", "10"]) == 1
    assert ".ply does not match its sha256" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--where", "genus >"], "error: --where: "),
        (["--where", "colour = red"], "unknown field 'colour'"),
        (["--where", "genus > 100000"], "matches --where 'genus > 100000': nothing written"),
        (["--shard-size", "0"], "--shard-size must be at least 1"),
        (["--format", "stl"], "unknown mesh format 'stl' (allowed: ply, glb)"),
    ],
)
def test_bad_exports_write_nothing(
    catalogue: Path, tmp_path: Path, capsys, args: list[str], message: str
) -> None:
    out = tmp_path / "out"
    assert main(["dataset", "export", "-C", str(catalogue), "-o", str(out), *args]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_missing_catalogue_and_busy_folder(catalogue: Path, tmp_path: Path, capsys) -> None:
    assert main(["dataset", "export", "-C", str(tmp_path / "none"), "-o", str(tmp_path / "o")]) == 1
    assert "no catalogue at" in capsys.readouterr().err
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "keep.txt").write_text("mine")
    assert main(["dataset", "export", "-C", str(catalogue), "-o", str(busy)]) == 1
    assert "exists and is not an empty folder" in capsys.readouterr().err
    assert [p.name for p in busy.iterdir()] == ["keep.txt"]
    assert main(["dataset", "verify", str(busy)]) == 1
    assert "is not a surfgen dataset export" in capsys.readouterr().err


def test_glb_export(catalogue: Path, tmp_path: Path) -> None:
    import trimesh

    out = tmp_path / "glb"
    assert main(["dataset", "export", "-C", str(catalogue), "-o", str(out), "--format", "glb"]) == 0
    rows = pq.read_table(out / "metadata.parquet").to_pylist()
    with tarfile.open(out / "shards" / "shard-000000.tar") as tar:
        data = tar.extractfile(rows[0]["mesh_file"]).read()
    mesh = trimesh.load(io.BytesIO(data), file_type="glb", force="mesh", process=False)
    assert len(mesh.faces) == rows[0]["faces"]
    assert main(["dataset", "verify", str(out), "--sample", "1"]) == 0
