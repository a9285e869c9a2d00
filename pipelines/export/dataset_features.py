"""``features.json``: the Hugging Face ``datasets`` features of an export's WebDataset samples.

``datasets.load_dataset("webdataset", data_files=...)`` infers the types of a sample's members
from the first five samples of the first shard. A ``KEY.json`` whose field is null or empty in
those five (a curator's note, tags, a metric only some families have) and set in a later
sample then fails the load ("Couldn't cast array of type string to null"). This file holds the
features typed over every sample of the export, in the form of ``Features.to_dict()``, so that

    features = datasets.Features.from_dict(json.loads(Path(DIR, "features.json").read_text()))
    load_dataset("webdataset", data_files=..., features=features)

reads any export. It is written without importing ``datasets``.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

from surfgen.generator.files import write_atomic

FEATURES_FILE = "features.json"
log = logging.getLogger(__name__)


def _value(dtype: str) -> dict[str, Any]:
    return {"dtype": dtype, "_type": "Value"}


def _list(feature: dict[str, Any]) -> dict[str, Any]:
    return {"feature": feature, "_type": "List"}


def arrow_feature(arrow_type: Any) -> dict[str, Any]:
    """The ``Features.to_dict()`` form of a pyarrow type (structs as dicts of fields)."""
    import pyarrow as pa  # optional: the dataset extra

    if pa.types.is_struct(arrow_type):
        return {field.name: arrow_feature(field.type) for field in arrow_type}
    if pa.types.is_list(arrow_type) or pa.types.is_large_list(arrow_type):
        return _list(arrow_feature(arrow_type.value_type))
    if pa.types.is_null(arrow_type):
        return _value("null")
    if pa.types.is_boolean(arrow_type):
        return _value("bool")
    if pa.types.is_integer(arrow_type):
        return _value(str(arrow_type))  # int8 ... uint64, as datasets names them
    if pa.types.is_floating(arrow_type):
        return _value(f"float{arrow_type.bit_width}")
    return _value("string")


def sample_features(
    sidecars: list[dict[str, Any]], kinds: tuple[str, ...], fmt: str
) -> dict[str, Any] | None:
    """The features of the samples whose ``KEY.json`` members are ``sidecars`` (typed over all
    of them), with members of ``kinds`` (``json``, ``mesh``, ``thumb``, ``points``, ``sdf``)
    and meshes in ``fmt``: the dict ``datasets.Features.from_dict`` takes. None when one
    field of the sidecars holds values of two types (a string here, a number there): no
    features can type it, and ``datasets`` cannot load such shards."""
    import pyarrow as pa  # optional: the dataset extra

    features: dict[str, Any] = {}
    if "json" in kinds:
        try:
            json_type = pa.array(sidecars).type  # a struct of every key of every sidecar
        except (pa.ArrowInvalid, pa.ArrowTypeError) as exc:
            log.warning("no features.json: the samples' KEY.json fields mix types (%s)", exc)
            return None
        features["json"] = arrow_feature(json_type)
    if "mesh" in kinds:
        features[fmt] = {"_type": "Mesh"}  # decoded to trimesh by datasets
    if "thumb" in kinds:
        features["png"] = {"_type": "Image"}
    if "points" in kinds:
        features["points.npy"] = _list(_list(_value("float32")))
    if "sdf" in kinds:
        features["sdf.npz"] = {
            "points": _list(_list(_value("float32"))),
            "f": _list(_value("float64")),
            "sign": _list(_value("int8")),
            "f_normalised": _list(_value("float64")),
        }
    return features | {"__key__": _value("string"), "__url__": _value("string")}


def write_features(folder: Path, features: dict[str, Any]) -> Path:
    path = Path(folder) / FEATURES_FILE
    write_atomic(path, (json.dumps(features, indent=1) + "\n").encode())
    return path
