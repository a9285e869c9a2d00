"""The catalogue as a machine-learning dataset: ``surfgen dataset export`` and ``verify``.

``export_dataset`` writes, for the accepted shapes a ``--where`` selects (ordered by key)::

    DIR/shards/shard-000000.tar   WebDataset shards: KEY.json, KEY.ply|glb, KEY.png,
                                  KEY.points.npy, KEY.sdf.npz (members sharing KEY are a sample)
    DIR/metadata.parquet          one row per shape: recipe, every metric, curation, files, sha256
    DIR/runs.json                 the sampling runs the shapes come from (seed, grid, config)
    DIR/README.md                 a dataset card (YAML header) saying how to make it again

Everything is deterministic: the same catalogue and options give the same bytes (tar members
with fixed times, owners and order; zip members of ``.npz`` with a fixed date; Parquet written
by one pyarrow version; no clock anywhere). The output is built in a temporary folder beside
``DIR`` and renamed into place, so a failed export leaves nothing behind.

``verify_dataset`` regenerates sampled rows from their provenance (seed, index, the run's
config) and compares the key, spec, metrics and the hashes of mesh, points and SDF samples.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import logging
import os
import shlex
import shutil
import tarfile
import tempfile
import zipfile
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
import typer

from surfgen.generator.errors import SurfgenError
from surfgen.generator.eval.reference import evaluate_points
from surfgen.generator.files import renaming, write_atomic
from surfgen.generator.mesh.formats import DATASET_FORMATS
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.curation import CatalogueOption, select_shapes
from surfgen.pipelines.catalogue.store import DEFAULT_CATALOGUE, open_catalogue

if TYPE_CHECKING:  # the mesh module (trimesh, scikit-image, numba) loads when a mesh does
    from surfgen.generator.mesh.mesh import Mesh

log = logging.getLogger(__name__)

MESH_FORMATS = DATASET_FORMATS
SPLITS = (("train", 0.8), ("val", 0.9), ("test", 1.0))  # cumulative fractions
POINTS_SALT, SDF_SALT = 1, 2  # one random stream per kind of sample, both derived from the key
TAR_MTIME = 946684800  # 2000-01-01: a fixed time for every member (0 upsets some tools)
ZIP_DATE = (1980, 1, 1, 0, 0, 0)  # the earliest date a zip member can have
FIXED_COLUMNS = (
    "key", "formula", "family", "split", "run", "seed", "index", "grid", "box", "level", "d",
    "config_hash", "sampler_version", "spec", "curation", "stars", "tags", "rejected", "note",
    "duplicate_of", "shard",
)  # fmt: skip
MEMBERS = ("json", "mesh", "thumb", "points", "sdf")


class DatasetError(SurfgenError):
    """A dataset that cannot be exported as asked, or a folder that is not an export."""


@dataclass(frozen=True)
class DatasetOptions:
    """What to export: shapes matching ``where``, ``shard_size`` per tar, ``points`` surface
    points and ``sdf`` field samples per shape (0: none), meshes as ``format``."""

    where: str | None = None
    shard_size: int = 1000
    points: int = 0
    sdf: int = 0
    format: str = "ply"
    license: str = "mit"

    def __post_init__(self) -> None:
        if self.shard_size < 1:
            raise DatasetError(f"--shard-size must be at least 1, got {self.shard_size}")
        for name in ("points", "sdf"):
            if getattr(self, name) < 0:
                raise DatasetError(f"--{name} must be 0 or more, got {getattr(self, name)}")
        if self.format not in MESH_FORMATS:
            raise DatasetError(
                f"unknown mesh format '{self.format}' (allowed: {', '.join(MESH_FORMATS)})"
            )


@dataclass
class ExportSummary:
    out: Path
    shapes: int
    shards: int
    bytes: int
    splits: dict[str, int]


def _need_pyarrow() -> None:
    import importlib.util

    if importlib.util.find_spec("pyarrow") is None:
        raise DatasetError("surfgen dataset needs pyarrow: pip install 'surfgen[dataset]'")


# ----------------------------------------------------------------------------- samples


def split_of(key: str) -> str:
    """``train``/``val``/``test`` (80/10/10) from a hash of the key: stable, and independent of
    the key order the shards follow."""
    u = int(hashlib.sha256(f"split:{key}".encode()).hexdigest()[:16], 16) / 2**64
    return next(name for name, upto in SPLITS if u < upto)


def _rng(key: str, salt: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(key, 16), salt]))


def surface_points(mesh: Mesh, n: int, key: str) -> np.ndarray:
    """``n`` points uniform by area on ``mesh`` with their unit face normals: float32
    ``(n, 6)`` (x, y, z, nx, ny, nz). The normals point out of the shape (towards F > level).
    Seeded from ``key``, so the same shape always gives the same points."""
    rng = _rng(key, POINTS_SALT)
    tri = mesh.vertices[mesh.faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    doubled = np.linalg.norm(cross, axis=1)
    faces = np.minimum(
        np.searchsorted(np.cumsum(doubled), rng.random(n) * doubled.sum(), side="right"),
        len(doubled) - 1,
    )
    r1, r2 = rng.random((2, n))
    s = np.sqrt(r1)
    a, b, c = tri[faces, 0], tri[faces, 1], tri[faces, 2]
    points = (1 - s)[:, None] * a + (s * (1 - r2))[:, None] * b + (s * r2)[:, None] * c
    normals = cross[faces] / np.maximum(doubled[faces], np.finfo(np.float64).tiny)[:, None]
    return np.hstack([points, normals]).astype(np.float32)


def field_samples(spec: SurfaceSpec, n: int, key: str) -> dict[str, np.ndarray]:
    """``n`` points uniform in the spec's box and the implicit function there.

    ``points`` float32 (n, 3); ``f`` float64: F(p) - level, **the implicit function, not a
    distance** (NaN/inf where F is not finite); ``sign`` int8: -1 inside (F < level), +1
    outside (non-finite counts as outside, as in meshing); ``f_normalised`` float64:
    (F - level) / |grad F| with the gradient by central differences, a first-order distance
    estimate that is only meaningful near the surface (NaN where the gradient vanishes or
    is not finite). F is evaluated at the float32 points exactly as stored.
    """
    rng = _rng(key, SDF_SALT)
    lo = np.array(spec.box[0::2])
    hi = np.array(spec.box[1::2])
    points = (lo + rng.random((n, 3)) * (hi - lo)).astype(np.float32)
    p = points.astype(np.float64)
    tree = spec.tree()

    def f(q: np.ndarray) -> np.ndarray:
        return evaluate_points(tree, q[:, 0], q[:, 1], q[:, 2], spec.params) - spec.level

    values = f(p)
    h = 1e-6 * float(np.max(hi - lo))
    grad = np.empty_like(p)
    with np.errstate(all="ignore"):  # poles: inf - inf is NaN here, and that is the answer
        for k in range(3):
            step = np.zeros(3)
            step[k] = h
            grad[:, k] = (f(p + step) - f(p - step)) / (2 * h)
        norm = np.linalg.norm(grad, axis=1)
        normalised = np.where((norm > 0) & np.isfinite(norm), values / norm, np.nan)
    sign = np.where(values < 0, -1, 1).astype(np.int8)
    return {"points": points, "f": values, "sign": sign, "f_normalised": normalised}


def npy_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array, allow_pickle=False)
    return buf.getvalue()


def npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """An ``.npz`` that ``np.load`` reads, with fixed member dates (``np.savez`` stamps the
    current time, so two exports would differ)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_STORED) as z:
        for name, array in arrays.items():
            info = zipfile.ZipInfo(f"{name}.npy", date_time=ZIP_DATE)
            info.external_attr = 0o644 << 16
            z.writestr(info, npy_bytes(array))
    return buf.getvalue()


def mesh_bytes(mesh_file: Path, fmt: str) -> bytes:
    """The mesh in ``fmt``: the catalogue's PLY as it is, or converted (without wall labels)."""
    if fmt == "ply":
        return mesh_file.read_bytes()
    from surfgen.generator.mesh.exchange import encode_mesh, load_mesh
    from surfgen.generator.mesh.mesh import Mesh

    mesh = load_mesh(mesh_file)
    return encode_mesh(Mesh(mesh.vertices, mesh.faces), fmt)


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _curation(rec: dict[str, Any]) -> str:
    if rec["rejected"]:
        return "rejected"
    if rec["duplicate_of"]:
        return "duplicate"
    return "starred" if rec["stars"] else "unreviewed"


def _members(
    rec: dict[str, Any], root: Path, options: DatasetOptions, row: dict[str, Any]
) -> dict[str, tuple[str, bytes]]:
    """The files of one sample: ``{kind: (member name, bytes)}``, in member order."""
    key = rec["key"]
    if not rec["mesh"] or not (root / rec["mesh"]).is_file():
        raise DatasetError(
            f"{key}: the mesh file {root / (rec['mesh'] or f'meshes/{key}.ply')} is missing "
            "(regenerate it with `surfgen render --from`, or leave the shape out with --where)"
        )
    mesh_file = root / rec["mesh"]
    out: dict[str, tuple[str, bytes]] = {}
    sidecar = {k: v for k, v in row.items() if k != "spec"} | {
        "spec": rec["spec"],
        "metrics": rec["metrics"],
    }
    out["json"] = (
        f"{key}.json",
        json.dumps(sidecar, sort_keys=True, separators=(",", ":")).encode(),
    )
    out["mesh"] = (f"{key}.{options.format}", mesh_bytes(mesh_file, options.format))
    if rec["thumb"] and (root / rec["thumb"]).is_file():
        out["thumb"] = (f"{key}.png", (root / rec["thumb"]).read_bytes())
    if options.points or options.sdf:
        from surfgen.generator.mesh.exchange import load_mesh

        mesh = load_mesh(mesh_file)
        if options.points:
            data = npy_bytes(surface_points(mesh, options.points, key))
            out["points"] = (f"{key}.points.npy", data)
        if options.sdf:
            spec = SurfaceSpec.from_dict(rec["spec"])
            out["sdf"] = (f"{key}.sdf.npz", npz_bytes(field_samples(spec, options.sdf, key)))
    return out


def _base_row(rec: dict[str, Any], raw: dict[str, Any]) -> dict[str, Any]:
    """The recipe and curation columns of one shape (no files yet)."""
    spec = rec["spec"]
    prov = spec.get("provenance", {})
    family = raw.get("family") or prov.get("family") or rec["metrics"].get("family")
    return {
        "key": rec["key"],
        "formula": rec["formula"],
        "family": family,
        "split": split_of(rec["key"]),
        "run": rec["run"],
        "seed": prov.get("seed"),
        "index": prov.get("index"),
        "grid": list(spec.get("grid", [])),
        "box": list(spec.get("box", [])),
        "level": spec.get("level", 0.0),
        "d": rec["d"],
        "config_hash": prov.get("config"),
        "sampler_version": prov.get("sampler"),
        "spec": json.dumps(spec, sort_keys=True, separators=(",", ":")),
        "curation": _curation(rec),
        "stars": rec["stars"],
        "tags": list(rec["tags"]),
        "rejected": rec["rejected"],
        "note": rec["note"],
        "duplicate_of": rec["duplicate_of"],
    }


# ----------------------------------------------------------------------------- export


def export_dataset(
    catalogue: Path,
    out_dir: Path,
    options: DatasetOptions | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> ExportSummary:
    """Export the accepted shapes matching ``options.where`` into ``out_dir`` (see the module
    docstring). Raises :class:`DatasetError` for a non-empty ``out_dir``, bad options or no
    matching shape, ``CatalogueError``/``WhereError`` for a missing catalogue or bad ``where``.
    Nothing is written unless the whole export succeeds."""
    _need_pyarrow()
    options = options or DatasetOptions()
    out_dir = Path(out_dir)
    if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
        raise DatasetError(f"{out_dir} exists and is not an empty folder: choose a new -o")
    with open_catalogue(catalogue, must_exist=True) as cat:
        records = select_shapes(cat, options.where, sort="key")
        if not records:
            raise DatasetError(
                f"no accepted shape in {catalogue} matches --where {options.where!r}: nothing written"
                if options.where
                else f"{catalogue} has no accepted shapes: nothing written"
            )
        raw = {
            r["key"]: dict(r)
            for r in cat.conn.execute("SELECT * FROM shapes WHERE verdict='accepted' ORDER BY key")
        }
        run_ids = sorted({r["run"] for r in records})
        runs = [
            dict(r)
            for r in cat.conn.execute(
                f"SELECT * FROM runs WHERE id IN ({','.join('?' * len(run_ids))}) ORDER BY id",
                run_ids,
            )
        ]
        from surfgen.pipelines.studies.report import report_stats

        stats = report_stats(cat)
        root = cat.root
    parent = out_dir.absolute().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        work = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=parent))
    except OSError as exc:
        raise DatasetError(f"cannot create {out_dir}: {exc.strerror}") from None
    try:
        summary = _write_export(work, records, raw, runs, stats, root, options, progress)
        (work / "README.md").write_text(
            dataset_card(summary, records, runs, stats, options, catalogue, out_dir)
        )
        os.chmod(work, 0o755)  # mkdtemp makes it 0700; a dataset is for handing on
        with renaming() as tx:  # an empty folder already there is put back if this fails
            tx.move(work, out_dir)
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise
    summary.out = out_dir
    return summary


def _write_export(
    work: Path,
    records: list[dict[str, Any]],
    raw: dict[str, dict[str, Any]],
    runs: list[dict[str, Any]],
    stats: dict[str, Any],
    root: Path,
    options: DatasetOptions,
    progress: Callable[[int, int], None] | None,
) -> ExportSummary:
    (work / "shards").mkdir()
    rows: list[dict[str, Any]] = []
    total = 0
    starts = range(0, len(records), options.shard_size)
    for shard_no, start in enumerate(starts):
        name = f"shards/shard-{shard_no:06d}.tar"
        with tarfile.open(work / name, "x", format=tarfile.USTAR_FORMAT) as tar:
            for rec in records[start : start + options.shard_size]:
                row = _base_row(rec, raw.get(rec["key"], {}))
                row["shard"] = name
                members = _members(rec, root, options, row)
                for kind in MEMBERS:
                    member, data = members.get(kind, (None, None))
                    row[f"{kind}_file"] = member
                    row[f"{kind}_sha256"] = None if data is None else _sha(data)
                    if data is not None:
                        _add(tar, member, data)
                        total += len(data)
                row["metrics"] = rec["metrics"]
                rows.append(row)
                if progress is not None:
                    progress(len(rows), len(records))
    shards = len(starts)
    _write_parquet(work / "metadata.parquet", rows)
    runs_json = [
        {
            k: (json.loads(r[k]) if k in ("config", "versions", "counts") else r[k])
            for k in (
                "id",
                "seed",
                "n",
                "grid",
                "config",
                "config_hash",
                "sampler_version",
                "versions",
                "status",
                "next_index",
                "accepted",
                "counts",
            )  # fmt: skip
        }
        for r in runs
    ]
    write_atomic(
        work / "runs.json", (json.dumps(runs_json, indent=1, sort_keys=True) + "\n").encode()
    )
    splits = Counter(r["split"] for r in rows)
    return ExportSummary(work, len(rows), shards, total, {s: splits.get(s, 0) for s, _ in SPLITS})


def _add(tar: tarfile.TarFile, name: str, data: bytes) -> None:
    info = tarfile.TarInfo(name)
    info.size = len(data)
    info.mtime = TAR_MTIME
    info.mode = 0o644
    info.uid = info.gid = 0
    info.uname = info.gname = ""
    tar.addfile(info, io.BytesIO(data))


def _metric_column(values: list[Any]):
    """A pyarrow array for one metric, typed from its values (JSON text if they are mixed)."""
    import pyarrow as pa

    try:
        return pa.array(values)
    except (pa.ArrowInvalid, pa.ArrowTypeError, TypeError):
        return pa.array([None if v is None else json.dumps(v) for v in values], pa.string())


def _write_parquet(path: Path, rows: list[dict[str, Any]]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    metric_names = sorted({k for r in rows for k in r["metrics"]})
    has_family = any(r["family"] is not None for r in rows)
    columns: dict[str, Any] = {}
    for name in FIXED_COLUMNS:
        if name == "family" and not has_family:
            continue
        values = [r[name] for r in rows]
        if name == "tags":
            columns[name] = pa.array(values, pa.list_(pa.string()))
        elif name in ("grid",):
            columns[name] = pa.array(values, pa.list_(pa.int64()))
        elif name in ("box",):
            columns[name] = pa.array(values, pa.list_(pa.float64()))
        elif name in ("d", "level"):
            columns[name] = pa.array(values, pa.float64())
        elif name in ("run", "seed", "index", "stars", "sampler_version"):
            columns[name] = pa.array(values, pa.int64())
        else:
            columns[name] = pa.array(values, pa.string())
    for name in metric_names:
        column = name if name not in columns else f"metric_{name}"
        columns[column] = _metric_column([r["metrics"].get(name) for r in rows])
    for kind in MEMBERS:
        columns[f"{kind}_file"] = pa.array([r[f"{kind}_file"] for r in rows], pa.string())
        columns[f"{kind}_sha256"] = pa.array([r[f"{kind}_sha256"] for r in rows], pa.string())
    table = pa.table(columns)
    buf = pa.BufferOutputStream()
    pq.write_table(table, buf, compression="zstd")
    write_atomic(path, buf.getvalue().to_pybytes())


def _size_category(n: int) -> str:
    for limit, name in ((1_000, "n<1K"), (10_000, "1K<n<10K"), (100_000, "10K<n<100K")):
        if n < limit:
            return name
    return "100K<n<1M" if n < 1_000_000 else "1M<n<10M"


def _hf_dtype(arrow_type) -> str:
    import pyarrow as pa

    if pa.types.is_integer(arrow_type):
        return "int64"
    if pa.types.is_floating(arrow_type):
        return "float64"
    if pa.types.is_boolean(arrow_type):
        return "bool"
    return "string"


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
    import pyarrow as pa
    import pyarrow.parquet as pq

    schema = pq.read_schema(summary.out / "metadata.parquet")
    features = []
    for f in schema:
        if pa.types.is_list(f.type):
            features.append(f"  - name: {f.name}\n    sequence: {_hf_dtype(f.type.value_type)}")
        else:
            features.append(f"  - name: {f.name}\n    dtype: {_hf_dtype(f.type)}")
    splits = "\n".join(f"  - name: {s}\n    num_examples: {n}" for s, n in summary.splits.items())
    genus = [r["genus"] for r in records if r["genus"] is not None]
    faces = sorted(r["faces"] for r in records if r["faces"] is not None)
    export_cmd = ["surfgen", "dataset", "export", "-C", str(catalogue), "-o", str(out_dir)]
    if options.where:
        export_cmd += ["--where", options.where]
    export_cmd += ["--shard-size", str(options.shard_size), "--points", str(options.points)]
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
  - split: all
    path: shards/*.tar
dataset_info:
  features:
{chr(10).join(features)}
  splits:
{splits}
---

# surfgen implicit surfaces

{summary.shapes} closed 3D surfaces F(x, y, z) = 0 drawn at random from equation (13) of
El Mesbahi et al., *A wide diversity of 3D surfaces Generator using implicit functions*, by
surfgen {", ".join(versions)}, each one regenerable from its recipe (`spec`: formula, box, grid,
level, and the seed and index it was drawn with).

## Files

- `shards/shard-NNNNNN.tar`: {summary.shards} WebDataset shard(s) of up to {options.shard_size} samples,
  ordered by key; the members of one sample share its key:

| member | content |
| --- | --- |
{member_rows}

- `metadata.parquet`: one row per shape — key, formula, family (when the sampler records one),
  split, run, seed, index, grid, box, level, d, config hash, sampler version, the spec as JSON,
  every metric of the catalogue as a column, curation (state, stars, tags, curator's rejection,
  note, duplicate), the shard and member names, and the sha256 of every member.
- `runs.json`: the sampling runs (seed, n, grid, the whole config, versions).

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


# ----------------------------------------------------------------------------- verify


@dataclass
class VerifyReport:
    rows: int
    checked: list[str]
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems


def _shard_members(root: Path, shards: list[str]) -> Iterator[tuple[str, str]]:
    for name in shards:
        try:
            with tarfile.open(root / name) as tar:
                members = tar.getnames()
        except (OSError, tarfile.TarError) as exc:
            raise DatasetError(f"cannot read shard {root / name}: {exc}") from None
        yield from ((name, m) for m in members)


def verify_dataset(
    root: Path, sample: int = 20, seed: int = 0, progress: Callable[[str], None] | None = None
) -> VerifyReport:
    """Check an export: every row's members exist with their hashes (for ``sample`` rows drawn
    with ``seed``), and those rows regenerate to the same key, spec, metrics, mesh, points and
    SDF samples. Raises :class:`DatasetError` when ``root`` is not an export."""
    _need_pyarrow()
    import pyarrow.parquet as pq

    root = Path(root)
    if sample < 1:
        raise DatasetError(f"--sample must be at least 1, got {sample}")
    meta = root / "metadata.parquet"
    if not meta.is_file():
        raise DatasetError(f"{root} is not a surfgen dataset export (no metadata.parquet)")
    rows = pq.read_table(meta).to_pylist()
    try:
        runs = {r["id"]: r for r in json.loads((root / "runs.json").read_text())}
    except (OSError, json.JSONDecodeError) as exc:
        raise DatasetError(f"cannot read {root / 'runs.json'}: {exc}") from None
    report = VerifyReport(len(rows), [])
    names: dict[str, str] = {}
    for shard, member in _shard_members(root, sorted({r["shard"] for r in rows})):
        names[member] = shard
    expected = {r[f"{k}_file"] for r in rows for k in MEMBERS if r[f"{k}_file"]}
    for missing in sorted(expected - names.keys())[:10]:
        report.problems.append(f"{missing}: listed in metadata.parquet, not in any shard")
    for extra in sorted(names.keys() - expected)[:10]:
        report.problems.append(f"{extra}: in shard {names[extra]}, not in metadata.parquet")
    rng = np.random.default_rng(seed)
    picked = sorted(rng.choice(len(rows), size=min(sample, len(rows)), replace=False))
    for i in picked:
        row = rows[int(i)]
        report.checked.append(row["key"])
        if progress is not None:
            progress(row["key"])
        report.problems += _verify_row(root, row, runs)
    return report


def _read_members(root: Path, row: dict[str, Any]) -> dict[str, bytes]:
    out = {}
    with tarfile.open(root / row["shard"]) as tar:
        for kind in MEMBERS:
            name = row[f"{kind}_file"]
            if name:
                with contextlib.suppress(KeyError):  # a missing member is reported by hash
                    out[kind] = tar.extractfile(name).read()  # type: ignore[union-attr]
    return out


def _verify_row(root: Path, row: dict[str, Any], runs: dict[int, Any]) -> list[str]:
    from surfgen.pipelines.run.config import config_from_dict
    from surfgen.pipelines.run.shapes import make_shape

    key = row["key"]
    problems: list[str] = []
    files = _read_members(root, row)
    for kind, data in files.items():
        if _sha(data) != row[f"{kind}_sha256"]:
            problems.append(f"{key}: {row[f'{kind}_file']} does not match its sha256")
    shipped = json.loads(files["json"]) if "json" in files else {}
    spec = SurfaceSpec.from_json(row["spec"])
    if spec.key != key:
        problems.append(f"{key}: its spec hashes to key {spec.key}")
    run = runs.get(row["run"])
    if run is None or row["seed"] is None or row["index"] is None:
        return [*problems, f"{key}: no sampling run in runs.json to regenerate it from"]
    config = config_from_dict(run["config"])
    with tempfile.TemporaryDirectory(prefix="surfgen-verify-") as tmp:
        out = make_shape(row["index"], seed=row["seed"], config=config, staging=Path(tmp))
        if out.row["key"] != key:
            return [
                *problems,
                f"{key}: seed {row['seed']} index {row['index']} now gives key {out.row['key']}",
            ]
        if not out.verdict.accepted:
            problems.append(
                f"{key}: regenerated shape is rejected ({', '.join(out.verdict.reasons)})"
            )
        metrics = json.loads(out.row["metrics"])
        for source, values in (
            ("metadata.parquet", _row_metrics(row, metrics)),
            ("json", shipped.get("metrics", {})),
        ):
            diff = sorted(
                k for k in metrics.keys() | values.keys() if metrics.get(k) != values.get(k)
            )
            if diff:
                k = diff[0]
                problems.append(
                    f"{key}: metric {k} is {values.get(k)!r} in {source}, regenerated {metrics.get(k)!r}"
                    + (f" ({len(diff) - 1} more)" if len(diff) > 1 else "")
                )
        fmt = Path(row["mesh_file"]).suffix[1:]
        if out.mesh_file is not None:
            regenerated = mesh_bytes(out.mesh_file, fmt)
            if _sha(regenerated) != row["mesh_sha256"]:
                problems.append(f"{key}: regenerated mesh differs from {row['mesh_file']}")
            from surfgen.generator.mesh.exchange import load_mesh

            mesh = load_mesh(out.mesh_file)
            if "points" in files:
                n = np.load(io.BytesIO(files["points"])).shape[0]
                if _sha(npy_bytes(surface_points(mesh, n, key))) != row["points_sha256"]:
                    problems.append(f"{key}: regenerated surface points differ")
            if "sdf" in files:
                with np.load(io.BytesIO(files["sdf"])) as z:
                    shipped_f = z["f"]
                again = field_samples(spec, len(shipped_f), key)["f"]
                if not np.allclose(again, shipped_f, rtol=1e-9, atol=0, equal_nan=True):
                    problems.append(f"{key}: regenerated SDF samples differ")
    return problems


def _row_metrics(row: dict[str, Any], like: dict[str, Any]) -> dict[str, Any]:
    """The metrics of a Parquet row, by the names of ``like`` (the regenerated ones)."""
    out = {}
    for k in like:
        column = f"metric_{k}" if k in FIXED_COLUMNS else k
        v = row.get(column)
        if isinstance(v, str) and not isinstance(like[k], str):
            with contextlib.suppress(json.JSONDecodeError):
                v = json.loads(v)
        out[k] = v
    return out


# ----------------------------------------------------------------------------- commands

dataset_app = typer.Typer(
    no_args_is_help=True, help="The catalogue as a machine-learning dataset (WebDataset, Parquet)."
)


@dataset_app.command("export")
def export_cmd(
    output: Annotated[Path, typer.Option("-o", "--output", help="A new or empty folder.")],
    catalogue: CatalogueOption = DEFAULT_CATALOGUE,
    where: Annotated[
        str | None, typer.Option(help="Which accepted shapes (as `catalogue list --where`).")
    ] = None,
    shard_size: Annotated[int, typer.Option(help="Samples per tar shard.")] = 1000,
    points: Annotated[
        int, typer.Option(help="Surface points with normals per shape (0: none).")
    ] = 0,
    sdf: Annotated[int, typer.Option(help="Field samples in the box per shape (0: none).")] = 0,
    fmt: Annotated[
        str, typer.Option("--format", help=f"Mesh format: {' or '.join(DATASET_FORMATS)}.")
    ] = "ply",
    license_: Annotated[
        str, typer.Option("--license", help="License identifier for the dataset card.")
    ] = "mit",
) -> None:
    """Write WebDataset shards, metadata.parquet and a dataset card for the accepted shapes."""
    options = DatasetOptions(where, shard_size, points, sdf, fmt.lower(), license_)
    s = export_dataset(catalogue, output, options)
    typer.echo(
        f"{s.shapes} shapes in {s.shards} shard(s), {s.bytes / 1e6:.1f} MB "
        f"(train {s.splits['train']}, val {s.splits['val']}, test {s.splits['test']}) -> {s.out}"
    )


@dataset_app.command("verify")
def verify_cmd(
    folder: Annotated[Path, typer.Argument(help="A folder written by `surfgen dataset export`.")],
    sample: Annotated[int, typer.Option(help="How many rows to regenerate.")] = 20,
    seed: Annotated[int, typer.Option(help="Seed of the choice of rows.")] = 0,
) -> None:
    """Regenerate rows from their recipes; compare keys, metrics and file hashes."""
    report = verify_dataset(folder, sample, seed)
    for p in report.problems:
        typer.echo(p)
    typer.echo(
        f"{len(report.checked)} of {report.rows} rows regenerated: "
        + ("all agree" if report.ok else f"{len(report.problems)} disagreement(s)")
    )
    if not report.ok:
        raise typer.Exit(1)


def register(app: typer.Typer) -> None:
    """Add ``surfgen dataset export|verify``."""
    app.add_typer(dataset_app, name="dataset")
