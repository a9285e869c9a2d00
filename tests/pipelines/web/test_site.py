"""Tests for surfgen.pipelines.web.site: the static gallery (`surfgen gallery`), drawing the
turntables it is missing first."""

from __future__ import annotations

from surfgen.pipelines.catalogue.store import open_catalogue
from tests.support.gallery import cli, page_data, without_turntables


def test_thumbnails_and_static_gallery_render_missing_turntables(
    cat_dir, keys, renders, capsys, tmp_path
) -> None:
    without_turntables(cat_dir)
    thumb = cat_dir / "thumbs" / f"{keys['torus']}.png"
    before = thumb.stat().st_mtime_ns
    out = tmp_path / "site"
    rc, stdout, _ = cli(
        capsys, "gallery", "-o", str(out), "-C", str(cat_dir), "--where", "genus = 1"
    )
    assert rc == 0 and "(1 shapes)" in stdout
    assert renders == [f"{keys['torus']}.png"]
    data = page_data((out / "index.html").read_text())
    assert data["shapes"][0]["turntable"] == f"turntables/{keys['torus']}.png"
    assert (out / "turntables" / f"{keys['torus']}.png").is_file()
    rc, stdout, _ = cli(capsys, "thumbnails", "-C", str(cat_dir))
    assert rc == 0 and stdout.startswith("rendered 3, already there 1, failed 0")
    assert sorted(renders) == sorted(f"{k}.png" for k in keys.values())
    assert thumb.stat().st_mtime_ns == before  # only the missing turntables were drawn
    with open_catalogue(cat_dir, must_exist=True) as cat:
        for key in keys.values():
            assert cat.shape(key)["turntable_path"] == f"turntables/{key}.png"


def test_static_gallery(cat_dir, keys, capsys, tmp_path) -> None:
    out = tmp_path / "site"
    rc, stdout, _ = cli(
        capsys, "gallery", "-o", str(out), "-C", str(cat_dir), "--where", "genus >= 1"
    )
    assert rc == 0 and "(2 shapes)" in stdout
    data = page_data((out / "index.html").read_text())
    assert data["readonly"] is True and len(data["shapes"]) == 2
    assert (out / "static" / "gallery.js").is_file() and (out / "static" / "gallery.css").is_file()
    assert (out / "static" / "common.js").is_file()  # the helpers gallery.js and viewer.js share
    for s in data["shapes"]:
        assert (out / s["thumb"]).is_file() and (out / s["turntable"]).is_file()
        assert s["mesh"] is None
    assert not (out / "meshes").exists()
    assert len(list((out / "thumbs").iterdir())) == 2
    rc, _, _ = cli(capsys, "gallery", "-o", str(out), "-C", str(cat_dir), "--meshes")
    assert rc == 0 and len(list((out / "meshes").iterdir())) == 4
    rc, _, err = cli(capsys, "gallery", "-o", str(cat_dir), "-C", str(cat_dir))
    assert rc == 1 and "another folder" in err


def test_a_failed_gallery_changes_nothing_in_the_catalogue(
    cat_dir, keys, renders, capsys, tmp_path
):
    # the turntables the gallery must draw are drawn into it, and cached in the catalogue only
    # once it is written: a gallery that cannot be written leaves the catalogue as it was
    without_turntables(cat_dir)
    db = cat_dir / "catalogue.sqlite"
    before = (db.read_bytes(), sorted(p.name for p in (cat_dir / "turntables").iterdir()))
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    rc, _, err = cli(capsys, "gallery", "-o", str(blocker / "site"), "-C", str(cat_dir))
    assert rc == 1 and err.startswith("error: cannot write the gallery to"), err
    assert len(err.strip().splitlines()) == 1
    assert renders == []  # nothing recorded
    assert (db.read_bytes(), sorted(p.name for p in (cat_dir / "turntables").iterdir())) == before
    with open_catalogue(cat_dir, readonly=True) as cat:
        assert all(cat.shape(k)["turntable_path"] is None for k in keys.values())
    # the same gallery written where it can be: then the turntables are cached
    rc, _, _ = cli(capsys, "gallery", "-o", str(tmp_path / "site"), "-C", str(cat_dir))
    assert rc == 0 and sorted(renders) == sorted(f"{k}.png" for k in keys.values())
