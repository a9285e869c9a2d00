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
  from the member's file name and referencing ``metadata/key``, and the member's bytes; the
  meshes' record set also joins the sample's labels (split, formula, genus, ...) by key.
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
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from surfgen.generator.files import write_atomic
from surfgen.pipelines.export.croissant_provenance import (
    RunRecord,
    export_dates,
    rai_fields,
    run_activity,
)

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


# The labels the meshes' record set joins from the metadata (those the export has).
MESH_LABELS = ("split", "formula", "family", "genus", "components", "faces", "curation", "tags")


def sha256_file(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        while chunk := f.read(1 << 20):
            digest.update(chunk)
    return digest.hexdigest()


def media_type(name: str) -> str:
    """The media type of a file name or a suffix (``.png``, ``.points.npy``)."""
    return MEDIA_TYPES.get(
        Path(f"file{name}" if name.startswith(".") else name).suffix, "application/octet-stream"
    )


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


def _joined(record_set: str, schema: Any) -> list[dict[str, Any]]:
    """Fields of ``record_set`` joined from ``metadata`` by key: the sample's labels."""
    fields = []
    for column in schema:
        if column.name in MESH_LABELS:
            data_type, is_list = _data_type(column.type)
            field: dict[str, Any] = {
                "@type": "cr:Field",
                "@id": f"{record_set}/{column.name}",
                "name": column.name,
                "description": f"The sample's {column.name} (metadata/{column.name}, by key).",
                "dataType": data_type,
                "source": {"field": {"@id": f"metadata/{column.name}"}},
            }
            fields.append(field | ({"isArray": True, "arrayShape": "-1"} if is_list else {}))
    return fields


def _member_sets(
    kinds: set[str], mesh_suffix: str, shards: list[str], schema: Any
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The file sets and record sets of the shard members present (``kinds``); the meshes'
    record set joins the sample's labels from ``metadata``."""
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
                    *(_joined(record_set, schema) if kind == "mesh" else []),
                ],
            }
        )
    return file_sets, record_sets


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
    started, ended = export_dates(runs, curated)
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
    file_sets, member_records = _member_sets(set(member_kinds), f".{mesh_format}", shards, schema)
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
        "prov:wasGeneratedBy": [run_activity(r) for r in runs],
        **rai_fields(runs, shapes, where, started, ended),
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
