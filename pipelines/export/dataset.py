"""The catalogue as a machine-learning dataset: ``surfgen dataset export`` (its card:
:mod:`surfgen.pipelines.export.dataset_card`; ``verify``: :mod:`surfgen.pipelines.export.dataset_verify`).

``export_dataset`` writes, for the accepted shapes a ``--where`` selects (ordered by key)::

    DIR/shards/shard-000000.tar   WebDataset shards: KEY.json, KEY.ply|glb, KEY.png,
                                  KEY.points.npy, KEY.sdf.npz (members sharing KEY are a sample)
    DIR/metadata.parquet          one row per shape: recipe, every metric, curation, files, sha256
    DIR/runs.json                 the sampling runs the shapes come from (seed, grid, config)
    DIR/README.md                 a dataset card (YAML header) saying how to make it again
    DIR/features.json             the samples' Hugging Face ``datasets`` features
                                  (:mod:`surfgen.pipelines.export.dataset_features`)
    DIR/croissant.json            MLCommons Croissant 1.1 metadata of all the above
                                  (:mod:`surfgen.pipelines.export.croissant`)

A shard closes at ``shard_size`` samples or, with ``max_shard_bytes``, before the sample that
would make its tar file larger than that (a sample larger than the limit alone gets a shard of
its own, the only case where a shard exceeds it).

Everything is deterministic: the same catalogue and options give the same bytes (tar members
with fixed times, owners and order; zip members of ``.npz`` with a fixed date; Parquet written
by one pyarrow version; no clock anywhere). The output is built in a temporary folder beside
``DIR`` and renamed into place, so a failed export leaves nothing behind.

:func:`~surfgen.pipelines.export.dataset_verify.verify_dataset` regenerates sampled rows from their provenance (seed, index, the run's
config) and compares the key, spec, metrics and the hashes of mesh, points and SDF samples.
"""

from __future__ import annotations

import hashlib
import importlib.util
import io
import json
import logging
import os
import shutil
import tarfile
import tempfile
import zipfile
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from surfgen.filters.geometry import surface_samples
from surfgen.generator.errors import SurfgenError
from surfgen.generator.eval.reference import evaluate_points
from surfgen.generator.files import renaming, write_atomic
from surfgen.generator.mesh.exchange import encode_mesh, load_mesh
from surfgen.generator.mesh.formats import DATASET_FORMATS
from surfgen.generator.mesh.mesh import Mesh
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.catalogue.curation import select_shapes
from surfgen.pipelines.catalogue.store import open_catalogue
from surfgen.pipelines.export.croissant import write_croissant
from surfgen.pipelines.export.croissant_provenance import collect_runs, latest_curation
from surfgen.pipelines.export.dataset_card import dataset_card
from surfgen.pipelines.export.dataset_features import sample_features, write_features
from surfgen.pipelines.studies.report import report_stats

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
DEFAULT_SHARD_SIZE = 1000  # samples per shard when neither limit is given
TAR_BLOCK, TAR_RECORD = 512, 10240  # tarfile's block, and the record its files are padded to
# Zero records after the end of every shard. zipfile.is_zipfile looks for a zip's end record
# in a file's last 65,557 bytes, so a tar ending with a stored zip (an .npz member) passes for
# a zip, and tools that try zip before tar (mlcroissant's extraction) read only that .npz.
# Zero blocks after a tar's end are ignored by tar readers.
ZIP_GUARD = 7 * TAR_RECORD  # 71,680 bytes: with tarfile's own end, more than 65,557 zeros


class DatasetError(SurfgenError):
    """A dataset that cannot be exported as asked, or a folder that is not an export."""


@dataclass(frozen=True)
class DatasetOptions:
    """What to export: shapes matching ``where``; at most ``shard_size`` samples or
    ``max_shard_bytes`` bytes per tar (one or the other; neither: :data:`DEFAULT_SHARD_SIZE`
    samples); ``points`` surface points and ``sdf`` field samples per shape (0: none); meshes
    as ``format``; ``license`` an identifier as the Hugging Face Hub spells it (``mit``,
    ``cc-by-4.0``, ...)."""

    where: str | None = None
    shard_size: int | None = None
    points: int = 0
    sdf: int = 0
    format: str = "ply"
    license: str = "mit"
    max_shard_bytes: int | None = None

    def __post_init__(self) -> None:
        if self.shard_size is not None and self.max_shard_bytes is not None:
            raise DatasetError(
                "--shard-size (samples) and --max-shard-bytes (bytes) exclude each other: give one"
            )
        if self.shard_size is not None and self.shard_size < 1:
            raise DatasetError(f"--shard-size must be at least 1, got {self.shard_size}")
        if self.max_shard_bytes is not None and self.max_shard_bytes < tar_file_bytes(0):
            raise DatasetError(
                f"--max-shard-bytes must be at least {tar_file_bytes(0)} (80K: an empty "
                f"shard's end blocks and zero guard), got {self.max_shard_bytes}"
            )
        for name in ("points", "sdf"):
            if getattr(self, name) < 0:
                raise DatasetError(f"--{name} must be 0 or more, got {getattr(self, name)}")
        if self.format not in MESH_FORMATS:
            raise DatasetError(
                f"unknown mesh format '{self.format}' (allowed: {', '.join(MESH_FORMATS)})"
            )

    @property
    def samples_per_shard(self) -> int | None:
        """The sample limit of a shard (None when shards are limited by bytes)."""
        if self.max_shard_bytes is not None:
            return None
        return DEFAULT_SHARD_SIZE if self.shard_size is None else self.shard_size


@dataclass
class ExportSummary:
    """What an export wrote: ``shapes`` samples in ``shards`` tars, ``bytes`` of members,
    the size of each shard file (``shard_bytes``) and the samples per split."""

    out: Path
    shapes: int
    shards: int
    bytes: int
    splits: dict[str, int]
    shard_bytes: list[int]
    member_kinds: tuple[str, ...] = ()


def need_pyarrow() -> None:
    """Raise :class:`DatasetError` unless pyarrow, an optional dependency, is installed."""
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
    points, faces = surface_samples(mesh.vertices, mesh.faces, doubled, doubled.sum(), rng, n)
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
    mesh = load_mesh(mesh_file)
    return encode_mesh(Mesh(mesh.vertices, mesh.faces), fmt)


def sha256_hex(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _curation(rec: dict[str, Any]) -> str:
    if rec["rejected"]:
        return "rejected"
    if rec["duplicate_of"]:
        return "duplicate"
    return "starred" if rec["stars"] else "unreviewed"


def _sidecar(rec: dict[str, Any], row: dict[str, Any]) -> tuple[str, bytes]:
    """The ``KEY.json`` member: the sample's row (with its shard) plus its spec and metrics."""
    sidecar = {k: v for k, v in row.items() if k != "spec"} | {
        "spec": rec["spec"],
        "metrics": rec["metrics"],
    }
    return f"{rec['key']}.json", json.dumps(sidecar, sort_keys=True, separators=(",", ":")).encode()


def _members(
    rec: dict[str, Any], root: Path, options: DatasetOptions
) -> dict[str, tuple[str, bytes]]:
    """The files of one sample but its ``KEY.json`` (which names the shard, see
    :func:`_sidecar`): ``{kind: (member name, bytes)}``, in member order."""
    key = rec["key"]
    if not rec["mesh"] or not (root / rec["mesh"]).is_file():
        raise DatasetError(
            f"{key}: the mesh file {root / (rec['mesh'] or f'meshes/{key}.ply')} is missing "
            "(regenerate it with `surfgen render --from`, or leave the shape out with --where)"
        )
    mesh_file = root / rec["mesh"]
    out: dict[str, tuple[str, bytes]] = {}
    out["mesh"] = (f"{key}.{options.format}", mesh_bytes(mesh_file, options.format))
    if rec["thumb"] and (root / rec["thumb"]).is_file():
        out["thumb"] = (f"{key}.png", (root / rec["thumb"]).read_bytes())
    if options.points or options.sdf:
        mesh = load_mesh(mesh_file)
        if options.points:
            data = npy_bytes(surface_points(mesh, options.points, key))
            out["points"] = (f"{key}.points.npy", data)
        if options.sdf:
            spec = SurfaceSpec.from_dict(rec["spec"])
            out["sdf"] = (f"{key}.sdf.npz", npz_bytes(field_samples(spec, options.sdf, key)))
    return out


def tar_bytes(sizes: list[int]) -> int:
    """The bytes that members of ``sizes`` take in a USTAR tar: a header block each, the data
    padded to whole blocks (names under 100 characters need no extra header)."""
    return sum(TAR_BLOCK + -(-n // TAR_BLOCK) * TAR_BLOCK for n in sizes)


def tar_file_bytes(members: int) -> int:
    """The size of a shard whose members take ``members`` bytes: two zero blocks end the
    archive, Python's tarfile pads the file to whole records, then :data:`ZIP_GUARD`."""
    return -(-(members + 2 * TAR_BLOCK) // TAR_RECORD) * TAR_RECORD + ZIP_GUARD


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
    need_pyarrow()
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
        stats = report_stats(cat)
        run_records = collect_runs(cat, runs)
        keys = [r["key"] for r in records]
        curated = latest_curation(cat, keys)
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
        write_croissant(
            work,
            schema=_parquet_schema(work / "metadata.parquet"),
            member_kinds=summary.member_kinds,
            mesh_format=options.format,
            shards=[_shard_name(i) for i in range(summary.shards)],
            runs=run_records,
            shapes=summary.shapes,
            license_id=options.license,
            where=options.where,
            curated=curated,
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
    shard_bytes: list[int] = []  # the size of each closed shard
    sidecars: list[dict[str, Any]] = []  # the KEY.json members, for their features
    total = 0
    tar: tarfile.TarFile | None = None
    in_shard = payload = 0  # samples and member bytes in the open shard

    def close_shard() -> None:
        if tar is not None:
            tar.close()
            path = work / _shard_name(len(shard_bytes))
            with path.open("ab") as f:
                f.write(bytes(ZIP_GUARD))
            shard_bytes.append(path.stat().st_size)

    try:
        for rec in records:
            row = _base_row(rec, raw.get(rec["key"], {}))
            row["shard"] = _shard_name(len(shard_bytes))
            members = _members(rec, root, options)
            # shard names have a fixed width: the sidecar's size does not depend on which one
            need = tar_bytes([len(_sidecar(rec, row)[1])] + [len(d) for _, d in members.values()])
            if tar is None or _full(options, in_shard, payload + need):
                close_shard()
                tar = tarfile.open(  # noqa: SIM115 (open across samples, closed below)
                    work / _shard_name(len(shard_bytes)), "x", format=tarfile.USTAR_FORMAT
                )
                in_shard = payload = 0
            row["shard"] = _shard_name(len(shard_bytes))
            members = {"json": _sidecar(rec, row)} | members
            sidecars.append(json.loads(members["json"][1]))
            for kind in MEMBERS:
                member, data = members.get(kind, (None, None))
                row[f"{kind}_file"] = member
                row[f"{kind}_sha256"] = None if data is None else sha256_hex(data)
                if data is not None:
                    _add(tar, member, data)
                    total += len(data)
            in_shard += 1
            payload += need
            row["metrics"] = rec["metrics"]
            rows.append(row)
            if progress is not None:
                progress(len(rows), len(records))
        close_shard()
        tar = None
    finally:
        if tar is not None:
            tar.close()
    shards = len(shard_bytes)
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
    kinds = tuple(k for k in MEMBERS if any(r[f"{k}_file"] for r in rows))
    features = sample_features(sidecars, kinds, options.format)
    if features is not None:
        write_features(work, features)
    return ExportSummary(
        work, len(rows), shards, total, {s: splits.get(s, 0) for s, _ in SPLITS}, shard_bytes, kinds
    )


def _parquet_schema(path: Path):
    import pyarrow.parquet as pq  # optional: the dataset extra

    return pq.read_schema(path)


def _shard_name(number: int) -> str:
    return f"shards/shard-{number:06d}.tar"


def _full(options: DatasetOptions, samples: int, payload: int) -> bool:
    """Whether a shard holding ``samples`` samples must close rather than grow to
    ``payload`` member bytes (a first sample always goes in, however large)."""
    if options.max_shard_bytes is not None:
        return samples > 0 and tar_file_bytes(payload) > options.max_shard_bytes
    return samples >= (options.samples_per_shard or DEFAULT_SHARD_SIZE)


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
    import pyarrow as pa  # optional: the dataset extra

    try:
        return pa.array(values)
    except (pa.ArrowInvalid, pa.ArrowTypeError, TypeError):
        return pa.array([None if v is None else json.dumps(v) for v in values], pa.string())


def _write_parquet(path: Path, rows: list[dict[str, Any]]) -> None:
    import pyarrow as pa  # optional: the dataset extra
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
