"""The dataset card (``README.md``) of an export of :mod:`surfgen.pipelines.export.dataset`:
a YAML header (license, size, features) in Hugging Face's form, then how the data was made."""

from __future__ import annotations

import json
import shlex
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # types only: the export module imports this one
    from surfgen.pipelines.export.dataset import DatasetOptions, ExportSummary


def _size_category(n: int) -> str:
    for limit, name in ((1_000, "n<1K"), (10_000, "1K<n<10K"), (100_000, "10K<n<100K")):
        if n < limit:
            return name
    return "100K<n<1M" if n < 1_000_000 else "1M<n<10M"


def _hf_dtype(arrow_type) -> str:
    import pyarrow as pa  # optional: the dataset extra

    if pa.types.is_integer(arrow_type):
        return "int64"
    if pa.types.is_floating(arrow_type):
        return "float64"
    if pa.types.is_boolean(arrow_type):
        return "bool"
    return "string"


def _shard_limit(options: DatasetOptions) -> str:
    if options.max_shard_bytes is not None:
        return f"at most {options.max_shard_bytes} bytes each (unless one sample alone is larger)"
    return f"up to {options.samples_per_shard} samples"


def dataset_card(
    summary: ExportSummary,
    records: list[dict[str, Any]],
    runs: list[dict[str, Any]],
    stats: dict[str, Any],
    options: DatasetOptions,
    catalogue: Path,
    out_dir: Path,
) -> str:
    """The ``README.md`` of an export: YAML header (license, size, features) and the story."""
    import pyarrow as pa  # optional: the dataset extra
    import pyarrow.parquet as pq

    schema = pq.read_schema(summary.out / "metadata.parquet")
    features = []
    for f in schema:
        if pa.types.is_list(f.type):
            features.append(f"  - name: {f.name}\n    list: {_hf_dtype(f.type.value_type)}")
        else:
            features.append(f"  - name: {f.name}\n    dtype: {_hf_dtype(f.type)}")
    genus = [r["genus"] for r in records if r["genus"] is not None]
    faces = sorted(r["faces"] for r in records if r["faces"] is not None)
    export_cmd = ["surfgen", "dataset", "export", "-C", str(catalogue), "-o", str(out_dir)]
    if options.where:
        export_cmd += ["--where", options.where]
    if options.max_shard_bytes is not None:
        export_cmd += ["--max-shard-bytes", str(options.max_shard_bytes)]
    else:
        export_cmd += ["--shard-size", str(options.samples_per_shard)]
    export_cmd += ["--points", str(options.points)]
    export_cmd += ["--sdf", str(options.sdf), "--format", options.format]
    if options.license != "mit":
        export_cmd += ["--license", options.license]
    sample_cmds = []
    for r in runs:
        sample_cmds.append(
            f"# run {r['id']}: config {r['config_hash']} (in runs.json; save it as run-{r['id']}.toml)\n"
            + shlex.join(
                [
                    "surfgen",
                    "sample",
                    "--n",
                    str(r["n"]),
                    "--seed",
                    str(r["seed"]),
                    "--grid",
                    str(r["grid"]),
                    "--config",
                    f"run-{r['id']}.toml",
                    "--out",
                    str(catalogue),
                ]
            )  # fmt: skip
        )
    versions = sorted({json.loads(r["versions"]).get("surfgen", "?") for r in runs})
    members = [
        ("KEY.json", "key, formula, spec, metrics, curation (the Parquet row as JSON)"),
        (f"KEY.{options.format}", "the closed (capped) triangle mesh, in the box's units"),
        ("KEY.png", "256 x 256 thumbnail (when the catalogue has one)"),
    ]
    if options.points:
        members.append(
            (
                "KEY.points.npy",
                f"float32 ({options.points}, 6): points uniform by area on the surface and their "
                "outward unit normals (x, y, z, nx, ny, nz); seeded from the key",
            )
        )
    if options.sdf:
        members.append(
            (
                "KEY.sdf.npz",
                f"{options.sdf} points uniform in the box: `points` float32 (N, 3); `f` float64 = "
                "F - level, **the implicit function, not a signed distance**; `sign` int8 "
                "(-1 inside, F < level; +1 outside, non-finite F included); `f_normalised` = "
                "f / |grad F| (central differences), a first-order distance estimate that only "
                "holds near the surface",
            )
        )
    member_rows = "\n".join(f"| `{m}` | {what} |" for m, what in members)
    near = stats.get("nearest_distance_median")
    return f"""---
license: {options.license}
pretty_name: surfgen implicit surfaces
size_categories:
- {_size_category(summary.shapes)}
task_categories:
- other
tags:
- 3d
- mesh
- implicit-surface
- procedural
- synthetic
- webdataset
configs:
- config_name: default
  data_files:
  - split: full
    path: metadata.parquet
dataset_info:
- config_name: default
  features:
{chr(10).join(features)}
---

# surfgen implicit surfaces

{summary.shapes} closed 3D surfaces F(x, y, z) = 0 drawn at random from equation (13) of
El Mesbahi et al., *A wide diversity of 3D surfaces Generator using implicit functions*, by
surfgen {", ".join(versions)}, each one regenerable from its recipe (`spec`: formula, box, grid,
level, and the seed and index it was drawn with).

## Files

- `shards/shard-NNNNNN.tar`: {summary.shards} WebDataset shard(s) of {_shard_limit(options)},
  ordered by key; the members of one sample share its key:

| member | content |
| --- | --- |
{member_rows}

- `metadata.parquet`: one row per shape — key, formula, family (when the sampler records one),
  split, run, seed, index, grid, box, level, d, config hash, sampler version, the spec as JSON,
  every metric of the catalogue as a column, curation (state, stars, tags, curator's rejection,
  note, duplicate), the shard and member names, and the sha256 of every member.
- `runs.json`: the sampling runs (seed, n, grid, the whole config, versions).
- `features.json`: the samples' Hugging Face `datasets` features, typed over every sample.
- `croissant.json`: MLCommons Croissant 1.1 metadata (files with their sha256, record sets,
  provenance and responsible-AI fields).

## Loading

```python
import json
from pathlib import Path

from datasets import Features, load_dataset

metadata = load_dataset("parquet", data_files="metadata.parquet", split="train")
features = Features.from_dict(json.loads(Path("features.json").read_text()))
shards = [str(p) for p in sorted(Path("shards").glob("*.tar"))]
samples = load_dataset("webdataset", data_files={{"train": shards}}, split="train", features=features)
```

`samples[i]["{options.format}"]` is a `trimesh.Trimesh`. With `webdataset`:
`wds.WebDataset(shards, shardshuffle=False).decode()`; with mlcroissant:
`mlcroissant.Dataset(jsonld="croissant.json").records("metadata")` (or `"meshes"`, ...).

Splits are fixed by a hash of the key: train {summary.splits["train"]}, val {summary.splits["val"]},
test {summary.splits["test"]} (80/10/10).

## How it was made

Each shape is a pure function of (seed, index, config): surfgen draws the formula, evaluates it
on the grid, extracts the surface with marching cubes (capped where the box cuts it, so every
mesh is closed) and keeps it only if it passes the filters (manifold, watertight, not noise,
not a box with carvings, not a convex blob, ...). The catalogue was made with

```bash
{chr(10).join(sample_cmds)}
```

and this folder with

```bash
{shlex.join(export_cmd)}
```

(stars, tags and curators' rejections come from people, not from the generator).
`surfgen dataset verify DIR --sample K` regenerates K rows and checks their keys, metrics and
file hashes.

## Diversity (the whole catalogue)

| figure | value |
| --- | --- |
| accepted shapes / draws | {stats["accepted"]} / {stats["drawn"]} ({100 * stats["acceptance"]:.0f} %) |
| distinct genera | {stats["distinct_genus"]} (entropy {stats["genus_entropy_bits"]:.2f} bits) |
| distinct (genus, components) | {stats["distinct_genus_components"]} |
| median distance to the nearest shape's descriptor | {"–" if near is None else f"{near:.3f}"} |
| exported: genus | {f"{min(genus)} to {max(genus)}" if genus else "–"} |
| exported: faces | {f"{faces[0]} to {faces[-1]} (median {faces[len(faces) // 2]})" if faces else "–"} |
| rejection reasons | {", ".join(f"{k} {v}" for k, v in stats["reasons"].items()) or "–"} |
"""
