"""The provenance and responsible-AI part of ``croissant.json``
(:mod:`surfgen.pipelines.export.croissant`): the sampling runs as PROV-O activities (seed,
draws, acceptance, config hash, sampler version, the filters' thresholds, every rejection
reason's rate, library versions), the Croissant RAI fields that apply to synthetic data, and
the dates, all read from the catalogue (never from a clock)."""

from __future__ import annotations

import json
from collections import Counter
from dataclasses import dataclass
from typing import Any

from surfgen.pipelines.catalogue.store import Catalogue


@dataclass(frozen=True)
class RunRecord:
    """One sampling run as the Croissant file describes it: its row in the catalogue's
    ``runs`` table (``config`` and ``versions`` decoded), how many shapes it drew and the
    count of each rejection reason over them (a rejected shape may have several)."""

    run: dict[str, Any]
    drawn: int
    reasons: dict[str, int]


def collect_runs(cat: Catalogue, runs: list[dict[str, Any]]) -> list[RunRecord]:
    """The runs with their draws and rejection counts, counted over the catalogue's shapes
    as ``surfgen report`` counts them."""
    out = []
    for run in runs:
        drawn = 0
        reasons: Counter[str] = Counter()
        for r in cat.conn.execute("SELECT verdict, reasons FROM shapes WHERE run=?", (run["id"],)):
            drawn += 1
            if r["verdict"] != "accepted":
                reasons.update(json.loads(r["reasons"] or "[]"))
        decoded = dict(run) | {k: json.loads(run[k]) for k in ("config", "versions", "counts")}
        out.append(RunRecord(decoded, drawn, dict(sorted(reasons.items()))))
    return out


def latest_curation(cat: Catalogue, keys: list[str]) -> str | None:
    """The time of the latest curation action on one of ``keys`` (None: there is none)."""
    wanted = set(keys)
    times = [
        r["at"] for r in cat.conn.execute("SELECT key, at FROM curation") if r["key"] in wanted
    ]
    return max(times, default=None)


def _rate(count: int, drawn: int) -> str:
    return f"{count} of {drawn} draws ({100 * count / drawn:.1f} %)" if drawn else f"{count}"


def run_activity(rec: RunRecord) -> dict[str, Any]:
    """A run as a PROV activity, its recipe and outcome as schema.org PropertyValues."""
    run = rec.run
    config = run["config"]
    props: list[tuple[str, Any]] = [
        ("seed", run["seed"]),
        ("n", run["n"]),
        ("grid", run["grid"]),
        ("config_hash", run["config_hash"]),
        ("sampler_version", run["sampler_version"]),
        ("status", run["status"]),
        ("drawn", rec.drawn),
        ("accepted", run["accepted"]),
        ("acceptance_rate", round(run["accepted"] / rec.drawn, 6) if rec.drawn else None),
        ("filters", json.dumps(config.get("filters", {}), sort_keys=True)),
    ]
    props += [
        (f"rejection_rate/{reason}", round(count / rec.drawn, 6) if rec.drawn else None)
        for reason, count in sorted(rec.reasons.items())
    ]
    versions = run["versions"]
    activity = {
        "@type": "prov:Activity",
        "@id": f"run-{run['id']}",
        "name": f"surfgen sampling run {run['id']}",
        "description": (
            f"surfgen {versions.get('surfgen', '?')} (sampler version {run['sampler_version']}) "
            f"drew {rec.drawn} shapes with seed {run['seed']} on a {run['grid']}^3 grid, "
            f"config {run['config_hash']} (its whole config is in runs.json), and kept "
            f"{run['accepted']}."
        ),
        "prov:startedAtTime": run["started"],
        "prov:endedAtTime": run["ended"],
        "prov:wasAssociatedWith": {
            "@type": "prov:SoftwareAgent",
            "name": f"surfgen {versions.get('surfgen', '?')}",
            "softwareVersion": ", ".join(f"{k} {v}" for k, v in sorted(versions.items())),
        },
        "additionalProperty": [
            {"@type": "sc:PropertyValue", "name": name, "value": value}
            for name, value in props
            if value is not None
        ],
    }
    return {k: v for k, v in activity.items() if v is not None}  # a run cut short has no end


def export_dates(runs: list[RunRecord], curated: str | None) -> tuple[str, str]:
    started = min(r.run["started"] for r in runs)
    ends = [r.run["ended"] or r.run["started"] for r in runs]
    return started, max([*ends, *([curated] if curated else [])])


def rai_fields(
    runs: list[RunRecord], shapes: int, where: str | None, started: str, ended: str
) -> dict[str, Any]:
    drawn = sum(r.drawn for r in runs)
    accepted = sum(r.run["accepted"] for r in runs)
    reasons: dict[str, int] = {}
    for r in runs:
        for reason, count in r.reasons.items():
            reasons[reason] = reasons.get(reason, 0) + count
    rates = "; ".join(
        f"{reason}: {_rate(count, drawn)}"
        for reason, count in sorted(reasons.items(), key=lambda kv: (-kv[1], kv[0]))
    )
    tools = sorted({f"{k} {v}" for r in runs for k, v in r.run["versions"].items()})
    seeds = ", ".join(str(r.run["seed"]) for r in runs)
    selection = (
        f"the accepted shapes matching --where {where!r}" if where else "every accepted shape"
    )
    return {
        "rai:dataCollection": (
            "Synthetic data: no data was collected from people or from the world. surfgen "
            "drew random implicit functions from equation (13) of the paper (sums of products "
            "of power, trigonometric and constituent functions), each a pure function of "
            f"(seed, index, config), in {len(runs)} run(s) with seed(s) {seeds}; evaluated "
            "each on its grid, extracted the surface by marching cubes (capped where the box "
            "cuts it, so every mesh is closed) and measured it."
        ),
        "rai:dataCollectionType": ["Software Collection", "Others: synthetic data"],
        "rai:dataCollectionRawData": (
            "None: every shape is regenerated from its spec (formula, box, grid, level, "
            "seed, index) by `surfgen dataset verify`."
        ),
        "rai:dataCollectionMissingData": (
            "Curation columns (rejected, note, duplicate_of) are null where no curator acted; "
            "the *_file and *_sha256 columns are null for members an export does not have; a "
            "metric is null where it does not apply to the shape."
        ),
        "rai:dataCollectionTimeframe": f"{started}/{ended}",
        "rai:dataPreprocessingProtocol": (
            f"Of {drawn} draws, the filters kept {accepted}; the others were rejected by the "
            f"filters (a draw may fail several; rates over all draws): {rates or 'none'}. The "
            "filters' thresholds are in each run's config (runs.json, and the runs' "
            "`filters` property here). Rejected shapes are not exported."
        ),
        "rai:dataManipulationProtocol": (
            f"This export holds {shapes} shape(s): {selection}, ordered by key. Curators' "
            "stars, tags, rejections, notes and near-duplicate marks are kept as columns, "
            "not applied as filters."
        ),
        "rai:dataImputationProtocol": "None: no value is imputed.",
        "rai:dataAnnotationProtocol": (
            "The metrics (genus, components, faces, area, volume, curvature, symmetry, ...) "
            "are computed by the program from the mesh; stars, tags and curation notes, when "
            "present, come from people reviewing the shapes in surfgen's gallery."
        ),
        "rai:machineAnnotationTools": tools,
        "rai:personalSensitiveInformation": "None: the data are mathematical surfaces.",
        "rai:dataBiases": (
            "The shapes follow surfgen's sampler distribution and its filters: closed, "
            "manifold, watertight surfaces that are neither noise, nor box-dominated, nor "
            "convex blobs, at the grid resolution of each run; they do not represent "
            "real-world objects."
        ),
        "rai:dataLimitations": (
            "Meshes resolve details only down to the grid spacing. The field samples hold the "
            "implicit function F - level, not a signed distance; its magnitude is not "
            "comparable across shapes and it is non-finite at poles."
        ),
        "rai:dataUseCases": (
            "Training and evaluating 3D generative models, shape descriptors and mesh or "
            "implicit-surface methods; benchmarks of topology (genus) estimation."
        ),
        "rai:dataSocialImpact": "None known: synthetic geometry with no personal content.",
        "rai:dataReleaseMaintenancePlan": (
            "A static export: it is never updated in place. A new export of a grown or "
            "re-curated catalogue is a new dataset; `surfgen dataset verify` checks one."
        ),
    }
