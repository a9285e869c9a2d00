"""``croissant.json``: MLCommons Croissant 1.1 metadata of an export of
:mod:`surfgen.pipelines.export.dataset`, with the Croissant RAI vocabulary.

What it holds:

- **distribution**: a ``cr:FileObject`` with ``sha256`` and ``contentSize`` for every file of
  the export but ``croissant.json`` itself (``README.md``, ``metadata.parquet``,
  ``runs.json``, ``features.json``, each shard), and one ``cr:FileSet`` per kind of shard member (``*.json``,
  ``*.ply``/``*.glb``, ``*.png``, ``*.points.npy``, ``*.sdf.npz``) contained in all the shards.
- **recordSet** ``metadata``: one field per Parquet column, with its data type (lists are
  ``isArray``), keyed by ``key``; and one record set per kind of shard member (``sidecars``,
  ``meshes``, ``thumbnails``, ``surface_points``, ``field_samples``): the sample's key, taken
  from the member's file name and referencing ``metadata/key``, and the member's bytes.
- **provenance and RAI**: ``isLiveDataset`` false; the runs as PROV activities (seed, draws,
  acceptance, config hash, sampler version, the filters' thresholds, every rejection reason
  with its rate, the library versions); ``rai:dataCollection``, ``dataCollectionType``,
  ``dataPreprocessingProtocol`` (the filters and their rejection rates), ``dataManipulationProtocol``
  (curation), and the other RAI fields that apply to synthetic data; the paper as ``citeAs``.

It is deterministic: the same catalogue and options give the same bytes. The only dates are
read from the catalogue, never from a clock: ``dateCreated`` is the start of the earliest
exported run, ``dateModified`` and ``datePublished`` the latest end of a run or curation
action on an exported shape (the data as it was exported), ``rai:dataCollectionTimeframe``
the interval between.
"""

from __future__ import annotations

import hashlib
import json
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from surfgen.generator.files import write_atomic
from surfgen.pipelines.catalogue.store import Catalogue

CROISSANT_FILE = "croissant.json"
CONFORMS_TO = "http://mlcommons.org/croissant/1.1"
# The JSON-LD context of Croissant 1.1 (the specification's appendix, as mlcroissant 1.1
# writes it), with the RAI and PROV-O prefixes.
CONTEXT: dict[str, Any] = {
    "@language": "en",
    "@vocab": "https://schema.org/",
    "arrayShape": "cr:arrayShape",
    "citeAs": "cr:citeAs",
    "column": "cr:column",
    "conformsTo": "dct:conformsTo",
    "containedIn": "cr:containedIn",
    "cr": "http://mlcommons.org/croissant/",
    "data": {"@id": "cr:data", "@type": "@json"},
    "dataType": {"@id": "cr:dataType", "@type": "@vocab"},
    "dct": "http://purl.org/dc/terms/",
    "description": {"@container": "@language"},
    "equivalentProperty": "cr:equivalentProperty",
    "examples": {"@id": "cr:examples", "@type": "@json"},
    "extract": "cr:extract",
    "field": "cr:field",
    "fileObject": "cr:fileObject",
    "fileProperty": "cr:fileProperty",
    "fileSet": "cr:fileSet",
    "format": "cr:format",
    "includes": "cr:includes",
    "isArray": "cr:isArray",
    "isLiveDataset": "cr:isLiveDataset",
    "jsonPath": "cr:jsonPath",
    "key": "cr:key",
    "md5": "cr:md5",
    "name": {"@container": "@language"},
    "parentField": "cr:parentField",
    "path": "cr:path",
    "prov": "http://www.w3.org/ns/prov#",
    "rai": "http://mlcommons.org/croissant/RAI/",
    "recordSet": "cr:recordSet",
    "references": "cr:references",
    "regex": "cr:regex",
    "repeated": "cr:repeated",
    "replace": "cr:replace",
    "samplingRate": "cr:samplingRate",
    "sc": "https://schema.org/",
    "separator": "cr:separator",
    "source": "cr:source",
    "subField": "cr:subField",
    "transform": "cr:transform",
}
PAPER_BIBTEX = (
    "@misc{elmesbahi_surfaces,\n"
    "  title = {A wide diversity of {3D} surfaces Generator using implicit functions},\n"
    "  author = {El Mesbahi, Jelloul and Errami, Ahmed and Khaldoun, Mohammed and"
    " Bouattane, Omar},\n"
    "  note = {Hassan II University of Casablanca; an enhanced version of arXiv:1505.03977}\n"
    "}"
)
# Hugging Face's licence identifiers (the card's `license:`) -> SPDX pages.
SPDX = {
    "mit": "MIT",
    "apache-2.0": "Apache-2.0",
    "bsd-2-clause": "BSD-2-Clause",
    "bsd-3-clause": "BSD-3-Clause",
    "cc0-1.0": "CC0-1.0",
    "cc-by-4.0": "CC-BY-4.0",
    "cc-by-sa-4.0": "CC-BY-SA-4.0",
    "cc-by-nc-4.0": "CC-BY-NC-4.0",
    "cc-by-nc-sa-4.0": "CC-BY-NC-SA-4.0",
    "odc-by": "ODC-By-1.0",
    "pddl": "PDDL-1.0",
    "unlicense": "Unlicense",
}
# Media types; formats without a registered one are named by the page that defines them, as
# the specification advises.
MEDIA_TYPES = {
    ".tar": "application/x-tar",
    ".parquet": "application/x-parquet",
    ".json": "application/json",
    ".md": "text/markdown",
    ".png": "image/png",
    ".glb": "model/gltf-binary",
    ".ply": "https://en.wikipedia.org/wiki/PLY_(file_format)",
    ".npy": "https://numpy.org/doc/stable/reference/generated/numpy.lib.format.html",
    ".npz": "https://numpy.org/doc/stable/reference/generated/numpy.savez.html",
}
# The record sets of the shard members: (member kind, record set, file set, pattern's
# suffix, data type of the content, what it is).
MEMBER_SETS = (
    ("json", "sidecars", "sidecar-files", ".json", "sc:Text",
     "KEY.json: the sample's Parquet row as JSON, with its spec and metrics (UTF-8 bytes)"),
    ("mesh", "meshes", "mesh-files", None, "sc:Text",
     "KEY.ply or KEY.glb: the closed triangle mesh, in the box's units (the file's bytes)"),
    ("thumb", "thumbnails", "thumbnail-files", ".png", "sc:ImageObject",
     "KEY.png: a 256 x 256 thumbnail"),
    ("points", "surface_points", "points-files", ".points.npy", "sc:Text",
     "KEY.points.npy: float32 (N, 6), points uniform by area on the surface and their "
     "outward unit normals (the .npy file's bytes)"),
    ("sdf", "field_samples", "sdf-files", ".sdf.npz", "sc:Text",
     "KEY.sdf.npz: points uniform in the box and F - level there (the implicit function, "
     "not a signed distance), with its sign and a first-order distance estimate (the .npz "
     "file's bytes)"),
)  # fmt: skip


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


def sha256_file(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        while chunk := f.read(1 << 20):
            digest.update(chunk)
    return digest.hexdigest()


def media_type(name: str) -> str:
    return MEDIA_TYPES.get(Path(name).suffix, "application/octet-stream")


def license_url(license_id: str) -> str | dict[str, str]:
    """The SPDX page of a Hugging Face licence identifier, else a named CreativeWork."""
    spdx = SPDX.get(license_id.lower())
    if spdx is None:
        return {"@type": "sc:CreativeWork", "name": license_id}
    return f"https://spdx.org/licenses/{spdx}.html"


def _file_object(folder: Path, name: str, description: str) -> dict[str, Any]:
    path = folder / name
    return {
        "@type": "cr:FileObject",
        "@id": name,
        "name": name,
        "description": description,
        "contentUrl": name,
        "contentSize": f"{path.stat().st_size} B",
        "encodingFormat": media_type(name),
        "sha256": sha256_file(path),
    }


def _data_type(arrow_type: Any) -> tuple[str, bool]:
    """The Croissant data type of a Parquet column's values, and whether it is a list."""
    text = str(arrow_type)
    if text.startswith(("list<", "large_list<")):
        return _data_type(arrow_type.value_type)[0], True
    if text.startswith(("int", "uint")):
        return "sc:Integer", False
    if text in ("float", "double", "halffloat"):
        return "sc:Float", False
    if text == "bool":
        return "sc:Boolean", False
    return "sc:Text", False


COLUMN_DESCRIPTIONS = {
    "key": "The shape's key: the sha256 prefix of its canonical spec; also the WebDataset key.",
    "formula": "F(x, y, z) in K3DSurf/MathMod syntax; the surface is F = level.",
    "family": "The sampler's family of the shape (when it records one).",
    "split": "train, val or test (80/10/10), from a hash of the key.",
    "run": "The sampling run (see runs.json) that drew the shape.",
    "seed": "The run's seed.",
    "index": "The draw's index in the run: (seed, index, config) regenerate the shape.",
    "grid": "Grid points along x, y, z.",
    "box": "The box: xmin, xmax, ymin, ymax, zmin, zmax.",
    "level": "The iso level.",
    "d": "The constant d of the paper's equation (13).",
    "config_hash": "The hash of the run's configuration (in runs.json).",
    "sampler_version": "The sampler version that drew the shape.",
    "spec": "The canonical spec as JSON: formula, box, grid, level, provenance.",
    "curation": "rejected, duplicate, starred or unreviewed (a curator's state).",
    "stars": "A curator's stars (0: none).",
    "tags": "A curator's tags.",
    "rejected": "A curator's reason to reject the shape (null: not rejected).",
    "note": "A curator's note.",
    "duplicate_of": "The key of the shape this one nearly duplicates (null: none).",
    "shard": "The tar shard holding the sample's members.",
}


def _metadata_record_set(schema: Any) -> dict[str, Any]:
    fields = []
    for column in schema:
        data_type, is_list = _data_type(column.type)
        if column.name.endswith("_file"):
            description = f"The name of the {column.name[:-5]} member in the shard (null: none)."
        elif column.name.endswith("_sha256"):
            description = f"The sha256 of the {column.name[:-7]} member (null: none)."
        else:
            description = COLUMN_DESCRIPTIONS.get(column.name, "A metric of the catalogue.")
        field: dict[str, Any] = {
            "@type": "cr:Field",
            "@id": f"metadata/{column.name}",
            "name": column.name,
            "description": description,
            "dataType": data_type,
            "source": {
                "fileObject": {"@id": "metadata.parquet"},
                "extract": {"column": column.name},
            },
        }
        if is_list:
            field |= {"isArray": True, "arrayShape": "-1"}
        fields.append(field)
    return {
        "@type": "cr:RecordSet",
        "@id": "metadata",
        "name": "metadata",
        "description": "One record per shape: the rows of metadata.parquet.",
        "key": {"@id": "metadata/key"},
        "field": fields,
    }


def _member_sets(
    kinds: set[str], mesh_suffix: str, shards: list[str]
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The file sets and record sets of the shard members present (``kinds``)."""
    file_sets, record_sets = [], []
    for kind, record_set, file_set, suffix, data_type, what in MEMBER_SETS:
        if kind not in kinds:
            continue
        suffix = suffix or mesh_suffix
        file_sets.append(
            {
                "@type": "cr:FileSet",
                "@id": file_set,
                "name": file_set,
                "description": f"The *{suffix} members of the WebDataset shards.",
                "containedIn": [{"@id": s} for s in shards],
                "encodingFormat": media_type(suffix),
                "includes": f"*{suffix}",
            }
        )
        source = {"fileSet": {"@id": file_set}}
        record_sets.append(
            {
                "@type": "cr:RecordSet",
                "@id": record_set,
                "name": record_set,
                "description": f"One record per sample: {what}.",
                "key": {"@id": f"{record_set}/key"},
                "field": [
                    {
                        "@type": "cr:Field",
                        "@id": f"{record_set}/key",
                        "name": "key",
                        "description": "The sample's key (the member's name before its first dot).",
                        "dataType": "sc:Text",
                        "source": source
                        | {
                            "extract": {"fileProperty": "filename"},
                            "transform": {"regex": r"^([^.]+)"},
                        },
                        "references": {"field": {"@id": "metadata/key"}},
                    },
                    {
                        "@type": "cr:Field",
                        "@id": f"{record_set}/content",
                        "name": "content",
                        "description": what,
                        "dataType": data_type,
                        "source": source | {"extract": {"fileProperty": "content"}},
                    },
                ],
            }
        )
    return file_sets, record_sets


def _rate(count: int, drawn: int) -> str:
    return f"{count} of {drawn} draws ({100 * count / drawn:.1f} %)" if drawn else f"{count}"


def _activity(rec: RunRecord) -> dict[str, Any]:
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


def _dates(runs: list[RunRecord], curated: str | None) -> tuple[str, str]:
    started = min(r.run["started"] for r in runs)
    ends = [r.run["ended"] or r.run["started"] for r in runs]
    return started, max([*ends, *([curated] if curated else [])])


def _rai(
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


def croissant_metadata(
    folder: Path,
    *,
    schema: Any,
    member_kinds: Iterable[str],
    mesh_format: str,
    shards: list[str],
    runs: list[RunRecord],
    shapes: int,
    license_id: str,
    where: str | None,
    curated: str | None,
) -> dict[str, Any]:
    """The Croissant document of the export in ``folder`` (every file but
    ``croissant.json`` already written). ``schema`` is ``metadata.parquet``'s pyarrow schema,
    ``member_kinds`` the kinds of shard members present (``json``, ``mesh``, ``thumb``,
    ``points``, ``sdf``), ``curated`` the time of the latest curation action on an exported
    shape (or None)."""
    started, ended = _dates(runs, curated)
    surfgen = sorted({r.run["versions"].get("surfgen", "?") for r in runs})
    distribution = [
        _file_object(folder, "README.md", "The dataset card (Hugging Face YAML header)."),
        _file_object(folder, "metadata.parquet", "One row per shape (zstd Parquet)."),
        _file_object(folder, "runs.json", "The sampling runs: seed, n, grid, config, versions."),
    ]
    if (folder / "features.json").is_file():
        what = "The Hugging Face datasets features of the samples."
        distribution.append(_file_object(folder, "features.json", what))
    distribution += [_file_object(folder, s, "A WebDataset shard (USTAR tar).") for s in shards]
    file_sets, member_records = _member_sets(set(member_kinds), f".{mesh_format}", shards)
    return {
        "@context": CONTEXT,
        "@type": "sc:Dataset",
        "conformsTo": CONFORMS_TO,
        "name": "surfgen-implicit-surfaces",
        "description": (
            f"{shapes} closed 3D surfaces F(x, y, z) = level drawn at random from equation "
            "(13) of El Mesbahi et al., 'A wide diversity of 3D surfaces Generator using "
            f"implicit functions', by surfgen {', '.join(surfgen)}: meshes, thumbnails and "
            "samples in WebDataset shards, and their recipes and metrics in metadata.parquet."
        ),
        "citeAs": PAPER_BIBTEX,
        "license": license_url(license_id),
        "keywords": ["3D", "mesh", "implicit surface", "procedural", "synthetic", "webdataset"],
        # an export is never changed in place (see rai:dataReleaseMaintenancePlan)
        "version": "1.0.0",
        "isLiveDataset": False,
        "dateCreated": started,
        "dateModified": ended,
        "datePublished": ended,
        "prov:wasGeneratedBy": [_activity(r) for r in runs],
        **_rai(runs, shapes, where, started, ended),
        "distribution": distribution + file_sets,
        "recordSet": [_metadata_record_set(schema), *member_records],
    }


def write_croissant(folder: Path, **kwargs: Any) -> Path:
    """Write ``folder/croissant.json`` (see :func:`croissant_metadata` for the arguments)."""
    document = croissant_metadata(folder, **kwargs)
    path = folder / CROISSANT_FILE
    write_atomic(path, (json.dumps(document, indent=1, ensure_ascii=False) + "\n").encode())
    return path


def check_croissant(folder: Path) -> list[str]:
    """Problems between ``folder/croissant.json`` and the files it lists: a missing file, a
    size or sha256 that differs, a shard on disk that it does not list. Empty when it agrees.
    Raises nothing: an unreadable file is a problem too."""
    path = Path(folder) / CROISSANT_FILE
    try:
        document = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        return [f"{CROISSANT_FILE}: cannot read it ({exc})"]
    problems = []
    if document.get("conformsTo") != CONFORMS_TO:
        problems.append(f"{CROISSANT_FILE}: conformsTo is not {CONFORMS_TO}")
    listed = set()
    for node in document.get("distribution", []):
        if node.get("@type") != "cr:FileObject":
            continue
        name = node.get("contentUrl", "")
        listed.add(name)
        file = Path(folder) / name
        if not file.is_file():
            problems.append(f"{name}: listed in {CROISSANT_FILE}, missing")
        elif node.get("contentSize") != f"{file.stat().st_size} B":
            problems.append(f"{name}: its size differs from {CROISSANT_FILE}'s")
        elif node.get("sha256") != sha256_file(file):
            problems.append(f"{name}: does not match its sha256 in {CROISSANT_FILE}")
    for shard in sorted(Path(folder).glob("shards/*.tar")):
        name = shard.relative_to(folder).as_posix()
        if name not in listed:
            problems.append(f"{name}: a shard that {CROISSANT_FILE} does not list")
    return problems
