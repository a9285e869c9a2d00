"""A dataset export as the ML ecosystem reads it: mlcroissant (Croissant 1.1), Hugging Face
``datasets`` and ``webdataset``, each called as its documentation shows (docs/guide/datasets.md
has the same code)."""

from __future__ import annotations

import io
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import trimesh

from surfgen.pipelines.catalogue.store import open_catalogue
from surfgen.pipelines.cli.main import main
from tests.pipelines.export.conftest import DATASET_SHAPES, export_args

mlc = pytest.importorskip("mlcroissant")
datasets = pytest.importorskip("datasets")
wds = pytest.importorskip("webdataset")
# mlcroissant's private cache folders: it extracts each tar into CROISSANT_CACHE/extract/
# sha256(contentUrl), read once at import; our contentUrls are relative, so two exports would
# share one extraction. Each test gets fresh ones.
mlc_extract = pytest.importorskip("mlcroissant._src.operation_graph.operations.extract")
mlc_constants = pytest.importorskip("mlcroissant._src.core.constants")
epath = pytest.importorskip("etils.epath")  # mlcroissant's paths (a pathlib.Path lacks .walk)
hf_webdataset = pytest.importorskip("datasets.packaged_modules.webdataset.webdataset")
# mlcroissant 1.1.1's own deprecated calls (rdflib's ConjunctiveGraph, pandas' inplace)
pytestmark = [
    pytest.mark.filterwarnings("ignore:ConjunctiveGraph is deprecated:DeprecationWarning"),
    pytest.mark.filterwarnings("ignore:The inplace keyword:Warning"),
]


@pytest.fixture
def croissant_cache(tmp_path: Path, monkeypatch) -> Path:
    cache = epath.Path(tmp_path / "croissant")
    monkeypatch.setattr(mlc_extract, "EXTRACT_PATH", cache / "extract")
    monkeypatch.setattr(mlc_constants, "DOWNLOAD_PATH", cache / "download")
    return tmp_path / "croissant"


def catalogue_meshes(catalogue: Path) -> dict[str, bytes]:
    with open_catalogue(catalogue, must_exist=True) as cat:
        return {
            r["key"]: (catalogue / r["mesh_path"]).read_bytes()
            for r in cat.shapes(verdict="accepted")
        }


def test_mlcroissant_validates_and_reads_every_record_set(
    dataset_export: Path, dataset_catalogue: Path, croissant_cache: Path
) -> None:
    ds = mlc.Dataset(jsonld=str(dataset_export / "croissant.json"))
    issues = ds.metadata.ctx.issues
    assert not issues.errors and not issues.warnings, issues.report()
    assert ds.metadata.ctx.is_v1_1()  # read as Croissant 1.1
    rows = pq.read_table(dataset_export / "metadata.parquet").to_pylist()
    # metadata: one record per Parquet row, every column, with its type
    records = list(ds.records("metadata"))
    assert [r["metadata/key"].decode() for r in records] == [r["key"] for r in rows]
    for record, row in zip(records, rows, strict=True):
        assert record["metadata/genus"] == row["genus"] and record["metadata/grid"] == row["grid"]
        assert record["metadata/d"] == pytest.approx(row["d"])
        assert [t.decode() for t in record["metadata/tags"]] == row["tags"]  # sc:Text: bytes
        assert record["metadata/watertight"] is True
    # the WebDataset samples: one record per member, keyed like the metadata
    meshes = catalogue_meshes(dataset_catalogue)
    records = list(ds.records("meshes"))
    got = {r["meshes/key"].decode(): r["meshes/content"] for r in records}
    assert got == meshes  # the catalogue's PLY files, byte for byte
    by_key = {r["key"]: r for r in rows}
    for r in records:  # the labels joined from metadata.parquet by key
        row = by_key[r["meshes/key"].decode()]
        assert r["meshes/genus"] == row["genus"] and r["meshes/faces"] == row["faces"]
        assert r["meshes/split"].decode() == row["split"]
    for key, data in got.items():
        mesh = trimesh.load(io.BytesIO(data), file_type="ply", process=False)
        assert len(mesh.faces) == next(r["faces"] for r in rows if r["key"] == key)
    sidecars = [json.loads(r["sidecars/content"]) for r in ds.records("sidecars")]
    assert sorted(s["key"] for s in sidecars) == sorted(meshes)
    thumbs = list(ds.records("thumbnails"))
    assert len(thumbs) == DATASET_SHAPES and all(
        t["thumbnails/content"].size == (256, 256) for t in thumbs
    )
    points = [
        np.load(io.BytesIO(r["surface_points/content"])) for r in ds.records("surface_points")
    ]
    assert [p.shape for p in points] == [(64, 6)] * DATASET_SHAPES
    for r in ds.records("field_samples"):
        with np.load(io.BytesIO(r["field_samples/content"])) as z:
            assert z["f"].shape == (50,)
    assert any((croissant_cache / "extract").iterdir())  # it read our cache, not ~/.cache


def test_mlcroissant_rejects_a_changed_file(
    dataset_export: Path, tmp_path: Path, croissant_cache: Path
) -> None:
    bad = shutil.copytree(dataset_export, tmp_path / "bad")
    table = pq.read_table(bad / "metadata.parquet")
    pq.write_table(table.slice(1), bad / "metadata.parquet")  # one row less
    ds = mlc.Dataset(jsonld=str(bad / "croissant.json"))
    with pytest.raises(mlc.GenerationError, match=r"Download\(metadata.parquet\)") as caught:
        list(ds.records("metadata"))
    assert "Hash of downloaded file" in str(caught.value.__cause__)  # the sha256 it lists


def shard_files(folder: Path) -> list[str]:
    return [str(p) for p in sorted((folder / "shards").glob("*.tar"))]


def test_datasets_reads_metadata_and_shards(
    dataset_export: Path, dataset_catalogue: Path, tmp_path: Path
) -> None:
    cache = str(tmp_path / "hf")
    metadata = datasets.load_dataset(
        "parquet", data_files=str(dataset_export / "metadata.parquet"), split="train",
        cache_dir=cache,
    )  # fmt: skip
    rows = pq.read_table(dataset_export / "metadata.parquet").to_pylist()
    assert metadata["key"] == [r["key"] for r in rows] and metadata["genus"] == [
        r["genus"] for r in rows
    ]
    features = datasets.Features.from_dict(
        json.loads((dataset_export / "features.json").read_text())
    )
    samples = datasets.load_dataset(
        "webdataset", data_files={"train": shard_files(dataset_export)}, split="train",
        features=features, cache_dir=cache,
    )  # fmt: skip
    assert samples.num_rows == DATASET_SHAPES
    meshes = catalogue_meshes(dataset_catalogue)
    for sample in samples:
        key = sample["__key__"]
        assert isinstance(sample["ply"], trimesh.Trimesh)  # datasets.Mesh decodes .ply
        original = trimesh.load(io.BytesIO(meshes[key]), file_type="ply", process=False)
        assert np.allclose(sample["ply"].vertices, original.vertices)
        assert np.array_equal(sample["ply"].faces, original.faces)
        assert sample["json"]["key"] == key and sample["json"]["metrics"]["genus"] == next(
            r["genus"] for r in rows if r["key"] == key
        )
        assert sample["png"].size == (256, 256)
        assert np.asarray(sample["points.npy"]).shape == (64, 6)
        assert len(sample["sdf.npz"]["f"]) == 50
    # the folder itself: the card's default config is metadata.parquet
    card = datasets.load_dataset(str(dataset_export), split="full", cache_dir=cache)
    assert card["key"] == [r["key"] for r in rows]


def test_datasets_needs_the_features_when_later_samples_differ(
    dataset_catalogue: Path, tmp_path: Path, monkeypatch
) -> None:
    """datasets infers a sample's types from the first samples (five; one here, so three
    shapes show it): a tag on a later shape breaks that inference, features.json does not."""
    catalogue = shutil.copytree(dataset_catalogue, tmp_path / "cat")
    last = max(catalogue_meshes(catalogue))
    assert main(["catalogue", "note", last, "a later note", "-C", str(catalogue)]) == 0
    out = tmp_path / "ds"
    assert main(export_args(catalogue, out)) == 0
    monkeypatch.setattr(hf_webdataset.WebDataset, "NUM_EXAMPLES_FOR_FEATURES_INFERENCE", 1)
    files = {"train": shard_files(out)}
    with pytest.raises(datasets.exceptions.DatasetGenerationError):
        datasets.load_dataset(
            "webdataset", data_files=files, split="train", cache_dir=str(tmp_path / "hf1")
        )
    features = datasets.Features.from_dict(json.loads((out / "features.json").read_text()))
    samples = datasets.load_dataset(
        "webdataset", data_files=files, split="train", features=features,
        cache_dir=str(tmp_path / "hf2"),
    )  # fmt: skip
    notes = {s["__key__"]: s["json"]["note"] for s in samples}
    assert notes[last] == "a later note" and sum(n is None for n in notes.values()) == 2


def test_webdataset_reads_and_decodes_the_shards(
    dataset_export: Path, dataset_catalogue: Path
) -> None:
    meshes = catalogue_meshes(dataset_catalogue)
    dataset = wds.WebDataset(shard_files(dataset_export), shardshuffle=False).decode("rgb8")
    seen = []
    for sample in dataset:
        key = sample["__key__"]
        seen.append(key)
        assert sample["json"]["key"] == key  # decoded from JSON
        assert sample["ply"] == meshes[key]  # no decoder for .ply: the bytes
        mesh = trimesh.load(io.BytesIO(sample["ply"]), file_type="ply", process=False)
        assert mesh.is_watertight and len(mesh.faces) == sample["json"]["metrics"]["faces"]
        assert sample["png"].shape == (256, 256, 3)  # "rgb8": a uint8 array
        assert sample["points.npy"].shape == (64, 6) and sample["points.npy"].dtype == np.float32
        assert sample["sdf.npz"]["f"].shape == (50,)
    assert seen == sorted(meshes)  # shards in order, samples by key


def guide_snippets() -> list[str]:
    """The Python blocks of the datasets guide's "Loading" section."""
    guide = Path(__file__).parents[3] / "docs" / "guide" / "datasets.md"
    loading = guide.read_text().split("\n## Loading\n", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```python\n(.*?)```", loading, flags=re.S)


def test_the_guide_code_runs(
    dataset_export: Path, tmp_path: Path, monkeypatch, croissant_cache: Path
) -> None:
    snippets = guide_snippets()
    assert len(snippets) == 3  # mlcroissant, datasets, webdataset
    monkeypatch.setattr(datasets.config, "HF_DATASETS_CACHE", str(tmp_path / "hf"))
    for code in snippets:
        assert "out/dataset" in code
        namespace: dict = {}
        exec(code.replace("out/dataset", str(dataset_export)), namespace)
    assert isinstance(namespace["mesh"], trimesh.Trimesh)  # the last block's last mesh
