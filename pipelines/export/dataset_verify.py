"""``surfgen dataset verify``: regenerate sampled rows of an export of
:mod:`surfgen.pipelines.export.dataset` from their provenance (seed, index, the run's config) and
compare the key, spec, metrics and the hashes of mesh, points and SDF samples; check that every
file ``croissant.json`` lists has its size and sha256."""

from __future__ import annotations

import contextlib
import io
import json
import tarfile
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from surfgen.generator.mesh.exchange import load_mesh
from surfgen.generator.model.spec import SurfaceSpec
from surfgen.pipelines.export.croissant import check_croissant
from surfgen.pipelines.export.dataset import (
    FIXED_COLUMNS,
    MEMBERS,
    DatasetError,
    field_samples,
    mesh_bytes,
    need_pyarrow,
    npy_bytes,
    sha256_hex,
    surface_points,
)
from surfgen.pipelines.run.config import config_from_dict
from surfgen.pipelines.run.shapes import make_shape


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
    """Check an export: every file ``croissant.json`` lists has its size and sha256, every
    row's members exist with their hashes (for ``sample`` rows drawn with ``seed``), and those
    rows regenerate to the same key, spec, metrics, mesh, points and SDF samples. Raises
    :class:`DatasetError` when ``root`` is not an export."""
    need_pyarrow()
    import pyarrow.parquet as pq  # optional: the dataset extra

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
    report.problems += check_croissant(root)
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
    key = row["key"]
    problems: list[str] = []
    files = _read_members(root, row)
    for kind, data in files.items():
        if sha256_hex(data) != row[f"{kind}_sha256"]:
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
            if sha256_hex(regenerated) != row["mesh_sha256"]:
                problems.append(f"{key}: regenerated mesh differs from {row['mesh_file']}")
            mesh = load_mesh(out.mesh_file)
            if "points" in files:
                n = np.load(io.BytesIO(files["points"])).shape[0]
                if sha256_hex(npy_bytes(surface_points(mesh, n, key))) != row["points_sha256"]:
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
