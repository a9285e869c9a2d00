"""surfgen.Catalogue and its records: reading, query, curation, export, reprs."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image

import surfgen
from surfgen.generator.mesh.exchange import load_mesh
from surfgen.pipelines.catalogue.curation import get_shape, select_shapes
from surfgen.pipelines.catalogue.store import open_catalogue
from tests.api.conftest import N
from tests.support.catalogues import catalogue_shapes


@pytest.fixture()
def catalogue(api_catalogue: surfgen.Catalogue, tmp_path: Path) -> surfgen.Catalogue:
    """A copy of the run's catalogue, for tests that change it."""
    shutil.copytree(api_catalogue.path, tmp_path / "cat")
    return surfgen.Catalogue(tmp_path / "cat")


def test_len_iteration_and_lookup(api_catalogue: surfgen.Catalogue) -> None:
    records = list(api_catalogue)
    assert len(api_catalogue) == N == len(records)
    assert [(r.to_dict()["run"], r.to_dict()["index"]) for r in records] == sorted(
        (r.to_dict()["run"], r.to_dict()["index"]) for r in records
    )
    first = records[0]
    assert api_catalogue[first.key[:6]].key == first.key and first.key in api_catalogue
    assert "0000000000" not in api_catalogue and 3 not in api_catalogue  # type: ignore[operator]
    with pytest.raises(surfgen.CatalogueError, match="no shape with key 'abcdef'"):
        api_catalogue["abcdef"]
    with pytest.raises(surfgen.CatalogueError, match="'zz' is not a shape key"):
        api_catalogue["zz"]
    with open_catalogue(api_catalogue.path, readonly=True) as cat:  # what `show --json` prints
        assert api_catalogue[first.key].to_dict() == get_shape(cat, first.key)


def test_opening_a_folder_without_catalogue_fails_at_once(tmp_path: Path) -> None:
    with pytest.raises(surfgen.CatalogueError, match="no catalogue at .*run `surfgen sample`"):
        surfgen.Catalogue(tmp_path / "none")


def test_query_is_catalogue_list(api_catalogue: surfgen.Catalogue) -> None:
    where, sort = "faces > 0 and genus >= 0", "-faces"
    found = api_catalogue.query(where, sort)
    faces = [r.to_dict()["faces"] for r in found]
    assert faces == sorted(faces, reverse=True) and found
    with open_catalogue(api_catalogue.path, readonly=True) as cat:
        assert [r.to_dict() for r in found] == select_shapes(cat, where=where, sort=sort)
    assert len(api_catalogue.query(limit=2)) == 2
    everything = api_catalogue.query(everything=True)
    assert len(everything) > N and any(not r.accepted for r in everything)
    duplicates = api_catalogue.query("reason = duplicate")
    assert duplicates and all(r.reasons == ["duplicate"] for r in duplicates)
    with pytest.raises(surfgen.CatalogueError, match="unknown field 'colour' at column 1"):
        api_catalogue.query("colour = red")


def test_curation(catalogue: surfgen.Catalogue) -> None:
    key = next(iter(catalogue)).key
    assert catalogue.star(key, 4).stars == 4
    assert catalogue.tag(key, "Nice", "blue").tags == ["blue", "nice"]
    assert catalogue.untag(key, "blue").tags == ["nice"]
    assert catalogue.note(key, "a note").note == "a note"
    assert catalogue.reject(key, "too plain").rejected == "too plain"
    assert [r.key for r in catalogue.query("rejected and tag = nice and stars = 4")] == [key]
    assert catalogue.unreject(key).rejected is None
    history = [h["action"] for h in catalogue[key].to_dict()["history"]]
    assert history == ["star", "tag", "untag", "note", "reject", "unreject"]
    with pytest.raises(surfgen.CatalogueError, match="stars must be from 0 to 5, got 9"):
        catalogue.star(key, 9)
    with pytest.raises(surfgen.CatalogueError, match="bad tag 'no spaces'"):
        catalogue.tag(key, "no spaces")
    with pytest.raises(surfgen.CatalogueError, match="say why the shape is rejected"):
        catalogue.reject(key, " ")


def test_a_record_s_surface_mesh_and_thumbnail(api_catalogue: surfgen.Catalogue) -> None:
    record = next(iter(api_catalogue))
    mesh = record.mesh()
    assert isinstance(mesh, trimesh.Trimesh) and mesh.metadata["key"] == record.key
    stored = load_mesh(api_catalogue.path / record.to_dict()["mesh"])
    np.testing.assert_array_equal(mesh.faces, stored.faces)
    surface = record.surface
    assert surface.key == record.key and surface.cap  # the run's [run] cap
    assert surface.config is not None and surface.config.run.dedupe_threshold == 3.5
    np.testing.assert_allclose(surface.mesh().vertices, mesh.vertices, rtol=0, atol=1e-6)
    metrics = surface.metrics()
    for name, value in record.metrics.items():  # the catalogue keeps 10 digits
        if name.startswith("resolution_"):
            continue  # the resolution check's, which check() measures (below)
        if (
            isinstance(value, float)
            or isinstance(value, list)
            and value
            and all(isinstance(v, float) for v in value)
        ):
            assert metrics[name] == pytest.approx(value, rel=1e-9), name
        else:
            assert metrics[name] == value, name
    assert surface.check().metrics == record.metrics  # the run's verdict, the run's numbers
    thumb = record.thumbnail()
    assert isinstance(thumb, Image.Image) and thumb.size == (256, 256)
    assert np.array_equal(np.asarray(thumb), np.asarray(surface.thumbnail()))


def test_a_record_of_a_run_without_a_readable_config(tmp_path: Path, sphere_mesh) -> None:
    spec = surfgen.Surface.from_formula("x^2+y^2+z^2-1", box=(-1.5, 1.5), grid=40).spec
    (key,) = catalogue_shapes(tmp_path / "cat", [(spec, sphere_mesh)])  # its run's config: {}
    surface = surfgen.Catalogue(tmp_path / "cat")[key].surface
    assert surface.spec == spec and surface.cap and surface.config is None
    assert surface.mesh().is_watertight


def test_a_rejected_draw_has_no_mesh(api_catalogue: surfgen.Catalogue) -> None:
    rejected = api_catalogue.query("verdict = rejected", limit=1)[0]
    with pytest.raises(surfgen.CatalogueError, match="it has no mesh file"):
        rejected.mesh()


def test_export_is_surfgen_export(api_catalogue: surfgen.Catalogue, tmp_path: Path) -> None:
    keys = [r.key for r in api_catalogue.query(limit=2)]
    files = api_catalogue.export(keys, tmp_path / "print", format="stl", size=40)
    assert [f.name for f in files] == [f"{k}.stl" for k in keys]
    for f, key in zip(files, keys, strict=True):
        mesh = trimesh.load(f)  # STL stores each face's corners: merged on load
        assert mesh.is_watertight and max(mesh.extents) == pytest.approx(40, rel=1e-4)
        sidecar = json.loads(f.with_suffix(".json").read_text())
        assert sidecar["key"] == key
    with pytest.raises(surfgen.SurfgenError, match="unknown format 'xyz'"):
        api_catalogue.export(keys, tmp_path / "x", format="xyz")
    assert not (tmp_path / "x").exists()


def test_reprs(api_catalogue: surfgen.Catalogue) -> None:
    assert repr(api_catalogue) == f"Catalogue({str(api_catalogue.path)!r}: {N} accepted shapes)"
    page = api_catalogue._repr_html_()
    assert page.count("data:image/png;base64,") == N
    record = next(iter(api_catalogue))
    assert repr(record).startswith(f"Record(key='{record.key}', family='{record.family}'")
    assert (record._repr_png_() or b"").startswith(b"\x89PNG")
    assert record.key in record._repr_html_() and "genus" in record._repr_html_()
