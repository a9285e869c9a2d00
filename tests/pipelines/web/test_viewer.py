"""End to end: the 3-D detail page in Debian's headless Chromium, WebGL through SwiftShader.

Opens a shape's page from `surfgen serve`, waits for the canvas to draw the mesh, drags a
slider and sees the face count change, saves the variant (then in the catalogue), curates with
the keyboard on the page and on the grid, and opens the static gallery's page from disk."""

from __future__ import annotations

from pathlib import Path

import pytest

from surfgen.pipelines.catalogue.store import open_catalogue
from surfgen.pipelines.cli.main import main
from tests.support.browser import (
    ARTEFACTS,
    CHROMIUM,
    build_catalogue,
    db_row,
    start_server,
    stop_server,
    wait_for,
)
from tests.support.browser import (
    make_browser as make_gallery_browser,
)

# WebGL in headless Chromium without a GPU: SwiftShader, which Chromium only uses when told it
# is acceptable (--enable-unsafe-swiftshader); --disable-gpu keeps it off any real GPU.
WEBGL_FLAGS = ("--use-gl=swiftshader", "--enable-unsafe-swiftshader", "--disable-gpu")


@pytest.fixture(scope="module")
def template(tmp_path_factory):
    root = tmp_path_factory.mktemp("viewer") / "cat"
    keys = build_catalogue(root)
    assert main(["thumbnails", "-C", str(root)]) == 0
    return root, keys


@pytest.fixture
def keys(template) -> dict[str, str]:
    return template[1]


def make_browser(profile: Path):
    return make_gallery_browser(profile, WEBGL_FLAGS)


def rendered(browser) -> bool:
    return browser.execute_script(
        "return document.getElementById('viewer').dataset.rendered === 'true'"
    )


def face_count(browser) -> str:
    return browser.execute_script("return document.getElementById('face-count').textContent")


@pytest.mark.skipif(not CHROMIUM.exists(), reason="no /usr/bin/chromium: apt-get install chromium")
def test_viewer_end_to_end(cat_dir, keys, tmp_path) -> None:
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    ARTEFACTS.mkdir(parents=True, exist_ok=True)
    torus = keys["torus"]
    proc, url = start_server(cat_dir)
    browser = make_browser(tmp_path / "profile")
    try:
        browser.get(f"{url}shape/{torus}")
        poster = browser.find_element(By.ID, "poster")
        assert poster.get_attribute("src").endswith(f"/thumbs/{torus}.png")
        wait_for(lambda: rendered(browser), 60, "the canvas to draw the mesh")
        canvas = browser.find_element(By.ID, "viewer")
        before = face_count(browser)
        assert canvas.get_attribute("data-faces") == before.replace(",", "")
        assert int(before.replace(",", "")) == db_row(cat_dir, torus)["faces"]
        assert not poster.is_displayed()
        # the picture is not blank: the mesh's colours differ from the background
        colours = browser.execute_script(
            "const c = document.getElementById('viewer'); const g = c.getContext('webgl2');"
            "const px = new Uint8Array(4 * 64 * 64);"
            "g.readPixels(c.width / 2 - 32, c.height / 2 - 32, 64, 64, g.RGBA, g.UNSIGNED_BYTE, px);"
            "const seen = new Set(); for (let i = 0; i < px.length; i += 4) seen.add(px[i] + ',' + px[i + 1]);"
            "return seen.size;"
        )
        assert colours > 20
        # orbit with the mouse, then the wireframe and flat shading still draw
        ActionChains(browser).drag_and_drop_by_offset(canvas, 80, 30).perform()
        browser.find_element(By.ID, "wireframe").click()
        browser.find_element(By.CSS_SELECTOR, "#shading option[value=flat]").click()
        # drag the d slider to the left: a thinner tube, fewer faces
        slider = browser.find_element(By.CSS_SELECTOR, 'input[data-knob="d"]')
        ActionChains(browser).drag_and_drop_by_offset(slider, -70, 0).perform()
        wait_for(lambda: face_count(browser) != before, 60, "the face count to change")
        wait_for(lambda: canvas.get_attribute("data-faces") == face_count(browser).replace(",", ""))
        after = int(face_count(browser).replace(",", ""))
        assert after < int(before.replace(",", ""))
        formula = browser.find_element(By.ID, "formula").text
        assert formula.startswith("(sqrt(x^2+y^2)-1)^2+z^2-") and not formula.endswith("-0.16")
        browser.save_screenshot(str(ARTEFACTS / "viewer.png"))
        # save the variant: it is in the catalogue, derived from the torus
        save = browser.find_element(By.ID, "save-variant")
        wait_for(lambda: save.is_enabled())
        save.click()
        link = wait_for(lambda: browser.find_elements(By.ID, "saved-link"), 60, "the saved link")
        new = link[0].text
        with open_catalogue(cat_dir, must_exist=True) as cat:
            rec = cat.shape(new)
        assert '"derived_from":"' + torus in rec["spec"] and rec["faces"] == after
        assert rec["formula"] == formula
        # keyboard curation on the page: s stars, t asks for tags, r asks why
        body = browser.find_element(By.TAG_NAME, "body")
        body.send_keys("s")
        wait_for(lambda: db_row(cat_dir, torus)["stars"] == 1, message="the star")
        body.send_keys("t")
        alert = wait_for(lambda: _alert(browser), message="the tag prompt")
        alert.send_keys("ring")
        alert.accept()
        wait_for(lambda: db_row(cat_dir, torus)["tags"] == ["ring"], message="the tag")
        body.send_keys("r")
        alert = wait_for(lambda: _alert(browser), message="the reason prompt")
        alert.send_keys("too plain")
        alert.accept()
        wait_for(lambda: db_row(cat_dir, torus)["user_rejected"] == "too plain")
        # → goes to the next shape's page, which draws too
        body.send_keys(Keys.ARROW_RIGHT)
        wait_for(lambda: torus not in browser.current_url, message="the next page")
        wait_for(lambda: rendered(browser), 60, "the next page's canvas")
        # the grid: → focuses a card, s stars it
        browser.get(url)
        wait_for(lambda: browser.execute_script("return document.body.dataset.ready === '1'"))
        browser.find_element(By.TAG_NAME, "body").send_keys(Keys.ARROW_RIGHT)
        focused = wait_for(lambda: browser.find_elements(By.CSS_SELECTOR, ".card.focus"))
        key = focused[0].get_attribute("data-key")
        browser.find_element(By.TAG_NAME, "body").send_keys("s")
        wait_for(lambda: db_row(cat_dir, key)["stars"] == 1, message="the star from the grid")
        severe = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
        assert severe == [], severe
        # the static gallery's 3-D page works opened from disk
        site = tmp_path / "site"
        assert main(["gallery", "-C", str(cat_dir), "-o", str(site), "--meshes"]) == 0
        browser.get((site / "shapes" / f"{keys['genus2']}.html").as_uri())
        wait_for(lambda: rendered(browser), 60, "the file:// page to draw")
        assert face_count(browser) == f"{db_row(cat_dir, keys['genus2'])['faces']:,}"
        assert browser.find_elements(By.ID, "sliders") == []  # read-only: no explore
    finally:
        browser.quit()
        stop_server(proc)


def _alert(browser):
    from selenium.common.exceptions import NoAlertPresentException

    try:
        return browser.switch_to.alert
    except NoAlertPresentException:
        return None
