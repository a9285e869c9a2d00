"""`surfgen dataset export|verify`: WebDataset shards, Parquet metadata, determinism, verify."""

from __future__ import annotations

import hashlib
import io
import json
import shutil
import tarfile
import zipfile
from pathlib import Path

import numpy as np
import pytest

from surfgen.pipelines.catalogue.store import open_catalogue
from surfgen.pipelines.cli.main import main
from surfgen.pipelines.export.dataset import (
    ZIP_GUARD,
    split_of,
    surface_points,
    tar_bytes,
    tar_file_bytes,
)
from surfgen.pipelines.export.dataset_features import sample_features
from surfgen.pipelines.studies.report import report_stats
from tests.pipelines.export.conftest import DATASET_SHAPES, export_args

pa = pytest.importorskip("pyarrow")  # the `dataset` extra, part of `test`
pq = pytest.importorskip("pyarrow.parquet")
N = DATASET_SHAPES


@pytest.fixture
def catalogue(dataset_catalogue: Path) -> Path:
    return dataset_catalogue


@pytest.fixture
def exported(dataset_export: Path) -> Path:
    return dataset_export


def export(catalogue: Path, out: Path, *extra: str) -> int:
    return main(export_args(catalogue, out, *extra))


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
    assert {p.name for p in first} >= {
        "README.md", "metadata.parquet", "runs.json", "croissant.json", "features.json"
    }  # fmt: skip


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
    assert "metric genus is" in out and "in metadata.parquet" in out and "2 disagreement" in out
    assert "metadata.parquet: its size differs from croissant.json's" in out  # the file changed
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
    out = capsys.readouterr().out
    assert ".ply does not match its sha256" in out
    assert "shards/shard-000000.tar: its size differs from croissant.json" in out  # no guard now


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--where", "genus >"], "error: --where: "),
        (["--where", "colour = red"], "unknown field 'colour'"),
        (["--where", "genus > 100000"], "matches --where 'genus > 100000': nothing written"),
        (["--shard-size", "0"], "--shard-size must be at least 1"),
        (["--format", "stl"], "unknown mesh format 'stl' (allowed: ply, glb)"),
        (["--shard-size", "5", "--max-shard-bytes", "1G"], "exclude each other: give one"),
        (["--max-shard-bytes", "lots"], "--max-shard-bytes must be a positive size such as"),
        (["--max-shard-bytes", "79K"], "--max-shard-bytes must be at least 81920"),
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


def test_croissant_describes_the_export(catalogue: Path, exported: Path) -> None:
    doc = json.loads((exported / "croissant.json").read_text())
    assert doc["conformsTo"] == "http://mlcommons.org/croissant/1.1"
    assert doc["isLiveDataset"] is False and doc["license"] == "https://spdx.org/licenses/MIT.html"
    assert "A wide diversity of {3D} surfaces Generator" in doc["citeAs"]
    files = {d["contentUrl"]: d for d in doc["distribution"] if d["@type"] == "cr:FileObject"}
    on_disk = {
        p.relative_to(exported).as_posix()
        for p in exported.rglob("*")
        if p.is_file() and p.name != "croissant.json"
    }
    assert set(files) == on_disk  # every file but itself, the shards included
    for name, node in files.items():
        data = (exported / name).read_bytes()
        assert node["sha256"] == sha(data) and node["contentSize"] == f"{len(data)} B"
    sets = {
        d["includes"]: d["encodingFormat"]
        for d in doc["distribution"]
        if d["@type"] == "cr:FileSet"
    }
    assert set(sets) == {"*.json", "*.ply", "*.png", "*.points.npy", "*.sdf.npz"}
    assert sets["*.json"] == "application/json" and sets["*.png"] == "image/png"
    assert sets["*.points.npy"].startswith("https://numpy.org/")
    assert files["metadata.parquet"]["encodingFormat"] == "application/x-parquet"
    assert files["shards/shard-000000.tar"]["encodingFormat"] == "application/x-tar"
    columns = pq.read_schema(exported / "metadata.parquet")
    fields = {f["name"]: f for f in doc["recordSet"][0]["field"]}
    assert list(fields) == columns.names
    assert fields["genus"]["dataType"] == "sc:Integer" and fields["d"]["dataType"] == "sc:Float"
    assert fields["tags"]["isArray"] is True and fields["watertight"]["dataType"] == "sc:Boolean"
    # provenance: the run's recipe and its rejection rates, as `surfgen report` counts them
    with open_catalogue(catalogue, must_exist=True) as cat:
        stats = report_stats(cat)
        run = dict(cat.conn.execute("SELECT * FROM runs").fetchone())
    (activity,) = doc["prov:wasGeneratedBy"]
    props = {p["name"]: p["value"] for p in activity["additionalProperty"]}
    assert props["seed"] == 5 and props["config_hash"] == run["config_hash"]
    assert props["drawn"] == stats["drawn"] and props["accepted"] == stats["accepted"]
    assert props["sampler_version"] == run["sampler_version"]
    assert json.loads(props["filters"]) == json.loads(run["config"])["filters"]
    rates = {k.split("/", 1)[1]: v for k, v in props.items() if k.startswith("rejection_rate/")}
    assert rates == {r: round(c / stats["drawn"], 6) for r, c in stats["reasons"].items()}
    for reason, count in stats["reasons"].items():
        assert (
            f"{reason}: {count} of {stats['drawn']} draws" in doc["rai:dataPreprocessingProtocol"]
        )
    # dates come from the catalogue, not the clock
    assert doc["dateCreated"] == run["started"] and doc["datePublished"] >= run["ended"]


def test_max_shard_bytes(catalogue: Path, tmp_path: Path) -> None:
    big = tmp_path / "one"
    assert export(catalogue, big, "--max-shard-bytes", "1G") == 0
    (shard,) = sorted((big / "shards").glob("*.tar"))
    with tarfile.open(shard) as tar:
        sizes = {m.name: m.size for m in tar.getmembers()}
    assert shard.stat().st_size == tar_file_bytes(tar_bytes(list(sizes.values())))
    assert shard.read_bytes()[-ZIP_GUARD:] == bytes(ZIP_GUARD)  # not a zip to zipfile
    assert not zipfile.is_zipfile(shard)
    per_key: dict[str, int] = {}
    for name, size in sizes.items():
        per_key[name.split(".")[0]] = per_key.get(name.split(".")[0], 0) + tar_bytes([size])
    # a limit that holds the two smallest samples but not all three
    two = sorted(per_key.values())
    limit = tar_file_bytes(two[0] + two[1])
    assert tar_file_bytes(sum(two)) > limit
    out = tmp_path / "limited"
    assert export(catalogue, out, "--max-shard-bytes", str(limit)) == 0
    shards = sorted((out / "shards").glob("*.tar"))
    assert len(shards) >= 2
    keys = []
    for path in shards:
        with tarfile.open(path) as tar:
            names = tar.getnames()
        keys += sorted({n.split(".")[0] for n in names})
        alone = len({n.split(".")[0] for n in names}) == 1
        assert path.stat().st_size <= limit or alone, (path.name, path.stat().st_size)
    assert keys == sorted(per_key)  # every sample once, in key order
    card = (out / "README.md").read_text()
    assert f"--max-shard-bytes {limit}" in card and f"at most {limit} bytes each" in card
    assert main(["dataset", "verify", str(out), "--sample", "1"]) == 0


def test_a_sample_larger_than_the_limit_gets_a_shard_alone(catalogue: Path, tmp_path: Path) -> None:
    out = tmp_path / "tiny"
    assert export(catalogue, out, "--max-shard-bytes", "80K") == 0  # the least allowed
    shards = sorted((out / "shards").glob("*.tar"))
    assert len(shards) == N
    for path in shards:
        with tarfile.open(path) as tar:
            assert len({n.split(".")[0] for n in tar.getnames()}) == 1
        assert path.stat().st_size > 81920


def test_verify_checks_croissant(exported: Path, tmp_path: Path, capsys) -> None:
    bad = shutil.copytree(exported, tmp_path / "bad-runs")
    runs = bad / "runs.json"
    runs.write_text(runs.read_text().replace('"seed": 5', '"seed": 6'))
    assert main(["dataset", "verify", str(bad), "--sample", "1"]) == 1
    out = capsys.readouterr().out
    assert "runs.json: does not match its sha256 in croissant.json" in out
    gone = shutil.copytree(exported, tmp_path / "no-shard")
    (gone / "croissant.json").unlink()
    assert main(["dataset", "verify", str(gone), "--sample", "1"]) == 1
    assert "croissant.json: cannot read it" in capsys.readouterr().out


def test_features_type_every_sidecar(caplog) -> None:
    first = {"key": "a", "note": None, "tags": [], "metrics": {"genus": 1}}
    later = {"key": "b", "note": "n", "tags": ["t"], "metrics": {"genus": 2, "departure": 0.5}}
    features = sample_features([first, later], ("json", "mesh", "thumb"), "glb")
    assert features["json"]["note"] == {"dtype": "string", "_type": "Value"}
    assert features["json"]["tags"]["feature"] == {"dtype": "string", "_type": "Value"}
    assert features["json"]["metrics"]["departure"] == {"dtype": "float64", "_type": "Value"}
    assert features["glb"] == {"_type": "Mesh"} and features["png"] == {"_type": "Image"}
    assert "points.npy" not in features and list(features)[-2:] == ["__key__", "__url__"]
    mixed = [first, {**later, "metrics": {"genus": "two"}}]
    assert sample_features(mixed, ("json",), "ply") is None
    assert "fields mix types" in caplog.text
