"""Tests for surfgen.pipelines.pictures.thumbnails: thumbnails and turntables rendered and
recorded (on one process or two), a turntable on demand, contact sheets."""

from __future__ import annotations

import shutil
import threading
from pathlib import Path

import pytest
from PIL import Image

from surfgen.pipelines.catalogue.store import open_catalogue
from surfgen.pipelines.pictures.thumbnails import ensure_turntable, render_pictures
from tests.support.gallery import cli, without_turntables


def test_thumbnails_rendered_and_recorded(cat_dir, keys, capsys) -> None:
    with open_catalogue(cat_dir, must_exist=True) as cat:
        for key in keys.values():
            row = cat.shape(key)
            assert row["thumb_path"] == f"thumbs/{key}.png"
            with Image.open(cat_dir / row["thumb_path"]) as im:
                assert im.size == (256, 256)
            with Image.open(cat_dir / row["turntable_path"]) as im:
                assert im.size == (12 * 256, 256)
    (cat_dir / "thumbs" / f"{keys['torus']}.png").unlink()
    rc, out, _ = cli(capsys, "thumbnails", "-C", str(cat_dir))
    assert rc == 0 and out.startswith("rendered 1, already there 3, failed 0")
    with open_catalogue(cat_dir, must_exist=True) as cat:
        res = render_pictures(cat, force=True, where="genus >= 1")
        assert (res.rendered, res.skipped, res.failed) == (2, 0, [])
        cat.conn.execute(
            "UPDATE shapes SET mesh_path=NULL, thumb_path=NULL WHERE key=?", (keys["sphere"],)
        )
        cat.conn.commit()
        assert render_pictures(cat).failed == [(keys["sphere"], "no mesh recorded")]


def test_contact_sheet(cat_dir, keys, capsys, tmp_path) -> None:
    sheet = tmp_path / "sheet.png"
    rc, out, _ = cli(
        capsys, "contact-sheet", "-C", str(cat_dir), "-o", str(sheet), "--columns", "2"
    )
    assert rc == 0 and "4 shapes" in out
    with Image.open(sheet) as im:
        assert im.width == 2 * 256 + 3 * 4 and im.height > 2 * 256
    rc, out, _ = cli(
        capsys,
        "contact-sheet",
        "-C",
        str(cat_dir),
        "-o",
        str(sheet),
        "--where",
        "genus >= 1",
        "--sort",
        "-genus",
    )
    assert rc == 0 and "2 shapes" in out
    rc, _, err = cli(
        capsys, "contact-sheet", "-C", str(cat_dir), "-o", str(sheet), "--where", "genus > 99"
    )
    assert rc == 1 and err.startswith("error: none of the 0 selected shapes")
    rc, _, err = cli(capsys, "contact-sheet", "-C", str(cat_dir), "-o", str(tmp_path / "s.jpg"))
    assert rc == 1 and "should end in .png" in err


def test_turntable_rendered_once_when_asked_twice_at_once(cat_dir, keys, renders) -> None:
    without_turntables(cat_dir)
    paths: list[Path | None] = []

    def ask() -> None:
        with open_catalogue(cat_dir, must_exist=True) as cat:
            paths.append(ensure_turntable(cat, keys["genus2"]))

    threads = [threading.Thread(target=ask) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert renders == [f"{keys['genus2']}.png"]
    assert paths == [cat_dir / "turntables" / f"{keys['genus2']}.png"] * 3


def test_pictures_on_one_process_or_two_are_the_same_files(cat_dir, keys, capsys) -> None:
    def pictures() -> dict[str, bytes]:
        files = [*cat_dir.glob("thumbs/*.png"), *cat_dir.glob("turntables/*.png")]
        return {f"{f.parent.name}/{f.name}": f.read_bytes() for f in files}

    rc, stdout, _ = cli(capsys, "thumbnails", "-C", str(cat_dir), "--force", "--workers", "1")
    assert rc == 0 and stdout.startswith("rendered 4,")
    one = pictures()
    rc, stdout, _ = cli(capsys, "thumbnails", "-C", str(cat_dir), "--force", "--workers", "2")
    assert rc == 0 and stdout.startswith("rendered 4,")
    assert pictures() == one and len(one) == 8
    rc, _, err = cli(
        capsys, "gallery", "-o", str(cat_dir.parent / "g"), "-C", str(cat_dir), "--workers", "0"
    )
    assert rc == 1 and err.strip() == "error: --workers must be a whole number from 1 to 256, got 0"


@pytest.mark.parametrize("lost", [1, 4], ids=["some", "all"])
def test_missing_meshes_are_one_line_with_the_count(template, tmp_path, capsys, lost) -> None:

    root = tmp_path / "cat"
    shutil.copytree(template[0], root)
    meshes = sorted((root / "meshes").glob("*.ply"))
    for f in meshes[:lost]:
        f.unlink()
    rc, out, err = cli(capsys, "thumbnails", "-C", str(root), "--force", "--workers", "1")
    lines = err.strip().splitlines()
    assert len(lines) == 1, lines  # not one line per shape
    assert f"{lost} shape(s) got no pictures" in lines[0]
    assert f"surfgen catalogue check -C {root}" in lines[0]
    if lost == len(meshes):
        assert rc == 1 and lines[0].startswith("error: no pictures could be rendered")
    else:
        assert rc == 0 and lines[0].startswith("warning: ")
        assert f"rendered {len(meshes) - lost}, already there 0, failed {lost}" in out
