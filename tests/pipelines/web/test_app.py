"""Tests for surfgen.pipelines.web.app: the live gallery's JSON API and page, turntables
rendered on first request, and an end-to-end run of `surfgen serve` driven by a real headless
Chromium."""

from __future__ import annotations

import io
import zipfile

import pytest
from PIL import Image

from surfgen.pipelines.catalogue.store import open_catalogue
from surfgen.pipelines.web.app import create_app
from tests.support.browser import (
    ARTEFACTS,
    CHROMIUM,
    db_row,
    make_browser,
    start_server,
    stop_server,
    wait_for,
)
from tests.support.gallery import page_data, without_turntables


def test_api_reads_and_pages(cat_dir, keys) -> None:
    client = create_app(cat_dir).test_client()
    page = client.get("/")
    assert page.status_code == 200
    data = page_data(page.get_data(as_text=True))
    assert data["readonly"] is False and len(data["shapes"]) == 4
    assert {s["key"] for s in data["shapes"]} == set(keys.values())
    thumb = client.get(f"/thumbs/{keys['torus']}.png")
    assert thumb.status_code == 200 and thumb.mimetype == "image/png"
    assert client.get("/static/gallery.js").status_code == 200
    assert client.get("/thumbs/../catalogue.sqlite").status_code == 404
    assert client.get("/meshes/..%2fcatalogue.sqlite").status_code == 404
    assert client.get("/api/health").get_json() == {"ok": True, "shapes": 4}
    res = client.get("/api/shapes", query_string={"where": "genus >= 1", "sort": "-genus"})
    assert [s["genus"] for s in res.get_json()["shapes"]] == [2, 1]
    res = client.get("/api/shapes", query_string={"where": "genus >= 1", "keys": "1"})
    assert set(res.get_json()["keys"]) == {keys["torus"], keys["genus2"]}
    bad = client.get("/api/shapes", query_string={"where": "genus >="})
    assert bad.status_code == 400 and "column 9" in bad.get_json()["error"]
    one = client.get(f"/api/shapes/{keys['torus'][:8]}").get_json()["shape"]
    assert one["key"] == keys["torus"] and one["history"] == []
    assert client.get("/api/shapes/0000000000").status_code == 404
    assert client.get("/", headers={"Host": "evil.example:80"}).status_code == 400


def test_api_writes_go_to_the_catalogue(cat_dir, keys) -> None:
    client = create_app(cat_dir).test_client()
    k = keys["genus2"]

    def post(action: str, body: dict, key: str = k):
        return client.post(f"/api/shapes/{key}/{action}", json=body)

    assert post("star", {"stars": 2}).get_json()["shape"]["stars"] == 2
    assert post("tag", {"tags": ["Nice", "holes"]}).get_json()["shape"]["tags"] == ["holes", "nice"]
    assert post("untag", {"tags": ["holes"]}).get_json()["shape"]["tags"] == ["nice"]
    assert post("note", {"note": "pretzel"}).get_json()["shape"]["note"] == "pretzel"
    assert post("reject", {"why": "thin"}).get_json()["shape"]["rejected"] == "thin"
    with open_catalogue(cat_dir, must_exist=True) as cat:  # written at once
        row = cat.shape(k)
        assert (row["stars"], row["tags"], row["note"], row["user_rejected"]) == (
            2,
            ["nice"],
            "pretzel",
            "thin",
        )
    assert post("unreject", {}).get_json()["shape"]["rejected"] is None
    history = client.get(f"/api/shapes/{k}").get_json()["shape"]["history"]
    assert [h["action"] for h in history] == ["star", "tag", "untag", "note", "reject", "unreject"]
    # refusals
    res = post("star", {"stars": 9})
    assert res.status_code == 400 and "0 to 5" in res.get_json()["error"]
    assert post("reject", {}).status_code == 400
    assert post("star", {}, key="0000000000").status_code == 404
    assert post("explode", {}).status_code == 404
    form = client.post(f"/api/shapes/{k}/star", data={"stars": "1"})
    assert form.status_code == 415
    assert (
        client.post(
            f"/api/shapes/{k}/star", data="[1]", content_type="application/json"
        ).status_code
        == 400
    )


def test_api_export_zip(cat_dir, keys) -> None:
    client = create_app(cat_dir).test_client()
    res = client.post("/api/export", data={"keys": f"{keys['torus']},{keys['sphere']}"})
    assert res.status_code == 200 and res.mimetype == "application/zip"
    names = set(zipfile.ZipFile(io.BytesIO(res.data)).namelist())
    assert {f"meshes/{keys['torus']}.ply", f"specs/{keys['sphere']}.json", "shapes.json"} <= names
    assert client.post("/api/export", data={"keys": ""}).status_code == 400


def test_turntable_rendered_on_first_request_cached_and_served_after_restart(
    cat_dir, keys, renders
) -> None:
    without_turntables(cat_dir)
    torus, sphere = keys["torus"], keys["sphere"]
    client = create_app(cat_dir).test_client()
    data = page_data(client.get("/").get_data(as_text=True))
    urls = {s["key"]: s["turntable"] for s in data["shapes"]}
    assert urls == {k: f"turntables/{k}.png" for k in keys.values()}  # offered, not rendered
    assert not any((cat_dir / "turntables").iterdir()) and renders == []

    first = client.get(f"/turntables/{torus}.png")
    assert first.status_code == 200 and first.mimetype == "image/png"
    with Image.open(io.BytesIO(first.data)) as im:
        assert im.size == (12 * 256, 256)
    assert renders == [f"{torus}.png"]
    assert client.get(f"/turntables/{torus}.png").data == first.data
    assert renders == [f"{torus}.png"]  # the second request was served from the cache
    with open_catalogue(cat_dir, must_exist=True) as cat:
        assert cat.shape(torus)["turntable_path"] == f"turntables/{torus}.png"
        assert cat.shape(sphere)["turntable_path"] is None
    assert sorted(p.name for p in (cat_dir / "turntables").iterdir()) == [f"{torus}.png"]

    restarted = create_app(cat_dir).test_client()  # a new server over the same catalogue
    assert restarted.get(f"/turntables/{torus}.png").data == first.data
    assert renders == [f"{torus}.png"]
    # Records from the API keep offering the lazy picture, also after a curation action.
    starred = restarted.post(f"/api/shapes/{sphere}/star", json={"stars": 2}).get_json()
    assert starred["shape"]["turntable"] == f"turntables/{sphere}.png"
    one = restarted.get(f"/api/shapes/{sphere}").get_json()["shape"]
    assert one["turntable"] == f"turntables/{sphere}.png"
    listed = restarted.get("/api/shapes").get_json()["shapes"]
    assert all(s["turntable"] == f"turntables/{s['key']}.png" for s in listed)
    # Unknown keys and other names are 404s, and render nothing.
    assert restarted.get("/turntables/0123456789abcdef.png").status_code == 404
    assert restarted.get("/turntables/../catalogue.sqlite").status_code == 404
    assert restarted.get("/turntables/notakey.png").status_code == 404
    assert renders == [f"{torus}.png"]


def test_page_data_cannot_break_out_of_its_script(cat_dir, keys) -> None:
    client = create_app(cat_dir).test_client()
    client.post(
        f"/api/shapes/{keys['torus']}/note", json={"note": "</script><script>alert(1)</script>"}
    )
    html = client.get("/").get_data(as_text=True)
    assert "</script><script>alert(1)" not in html
    notes = [s["note"] for s in page_data(html)["shapes"]]
    assert "</script><script>alert(1)</script>" in notes


@pytest.mark.skipif(
    not CHROMIUM.exists(),
    reason="no /usr/bin/chromium: apt-get install -y chromium chromium-driver (.ci/run does)",
)
def test_browser_end_to_end(cat_dir, keys, tmp_path) -> None:
    """Serve a catalogue, load the gallery in headless Chromium, star, reject and tag shapes
    with the page's buttons, check the catalogue changed, restart the server and check again."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    ARTEFACTS.mkdir(parents=True, exist_ok=True)
    proc, url = start_server(cat_dir)
    browser = make_browser(tmp_path / "profile")
    try:
        browser.get(url)
        wait_for(lambda: browser.execute_script("return document.body.dataset.ready === '1'"))
        cards = browser.find_elements(By.CSS_SELECTOR, ".card")
        assert len(cards) == 4
        wait_for(
            lambda: browser.execute_script(
                "const imgs = [...document.querySelectorAll('.card img')];"
                "return imgs.length === 4 && imgs.every(i => i.complete && i.naturalWidth === 256);"
            ),
            message="thumbnails to load",
        )
        # hovering a card spins it through its turntable
        pic = browser.find_element(By.CSS_SELECTOR, f'.card[data-key="{keys["genus2"]}"] .pic')
        ActionChains(browser).move_to_element(pic).perform()
        wait_for(
            lambda: (
                "spinning" in pic.get_attribute("class")
                and "turntables/" in pic.value_of_css_property("background-image")
            ),
            message="the turntable on hover",
        )
        ActionChains(browser).move_by_offset(0, 400).perform()

        # star the torus from its card
        torus = keys["torus"]
        browser.find_element(By.CSS_SELECTOR, f'.card[data-key="{torus}"] button.star').click()
        wait_for(lambda: db_row(cat_dir, torus)["stars"] == 1, message="the star in the catalogue")
        wait_for(
            lambda: (
                browser.find_element(
                    By.CSS_SELECTOR, f'.card[data-key="{torus}"] button.star'
                ).get_attribute("aria-pressed")
                == "true"
            )
        )

        # reject the sphere: its ✕ opens the detail view, which asks why
        sphere = keys["sphere"]
        browser.find_element(By.CSS_SELECTOR, f'.card[data-key="{sphere}"] button.reject').click()
        wait_for(lambda: browser.find_element(By.ID, "detail").is_displayed())
        assert browser.find_element(By.ID, "detail-title").text == sphere
        assert "x^2+y^2+z^2-1" in browser.find_element(By.ID, "formula").text
        browser.find_element(By.ID, "reject-why").send_keys("too plain")
        browser.find_element(By.ID, "reject").click()
        wait_for(
            lambda: db_row(cat_dir, sphere)["user_rejected"] == "too plain",
            message="the rejection in the catalogue",
        )
        browser.find_element(By.ID, "add-tag").send_keys("round\n")
        wait_for(lambda: db_row(cat_dir, sphere)["tags"] == ["round"], message="the tag")
        browser.save_screenshot(str(ARTEFACTS / "gallery-detail.png"))
        browser.find_element(By.ID, "close").click()
        wait_for(lambda: len(browser.find_elements(By.CSS_SELECTOR, ".card")) == 3)  # hidden

        # a restart keeps every change
        stop_server(proc)
        proc, url = start_server(cat_dir)
        browser.get(url)
        wait_for(lambda: browser.execute_script("return document.body.dataset.ready === '1'"))
        assert len(browser.find_elements(By.CSS_SELECTOR, ".card")) == 3
        star = browser.find_element(By.CSS_SELECTOR, f'.card[data-key="{torus}"] button.star')
        assert star.get_attribute("aria-pressed") == "true"
        browser.find_element(By.ID, "show-rejected").click()
        rejected = wait_for(
            lambda: browser.find_elements(
                By.CSS_SELECTOR, f'.card[data-key="{sphere}"].is-rejected'
            )
        )
        assert "round" in rejected[0].text
        wait_for(
            lambda: browser.execute_script(
                "return [...document.querySelectorAll('.card img')].every(i => i.complete && i.naturalWidth === 256);"
            )
        )
        browser.save_screenshot(str(ARTEFACTS / "gallery.png"))
        severe = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
        assert severe == [], severe  # no script errors, no missing files
    finally:
        browser.quit()
        stop_server(proc)
    assert (ARTEFACTS / "gallery.png").stat().st_size > 10_000
