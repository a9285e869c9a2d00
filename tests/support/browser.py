"""A small catalogue, a server and a headless browser: what the gallery and viewer tests share."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
import urllib.request
from collections.abc import Callable
from pathlib import Path

from surfgen.pipelines.catalogue.store import open_catalogue
from tests.support.catalogues import catalogue_formulas

SHAPES = {
    "sphere": ("x^2+y^2+z^2-1", 1.5),
    "torus": ("(sqrt(x^2+y^2)-1)^2+z^2-0.16", 1.6),
    "genus2": ("(x^2*(1-x^2)-y^2)^2+z^2-0.04", 1.3),
    "two_spheres": ("min((x-0.8)^2+y^2+z^2-0.25, (x+0.8)^2+y^2+z^2-0.25)", 1.5),
}


GRID = 32


CHROMIUM = Path("/usr/bin/chromium")


CHROMEDRIVER = Path("/usr/bin/chromedriver")


ARTEFACTS = Path(__file__).resolve().parents[2] / "out" / "test-artefacts"


def build_catalogue(root: Path) -> dict[str, str]:
    """The four canonical shapes as accepted rows with meshes (no pictures yet): {name: key}."""
    return catalogue_formulas(root, SHAPES, seed=7, grid=GRID)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_server(root: Path) -> tuple[subprocess.Popen, str]:
    """`surfgen serve` in a child process; returns it and its URL once it answers."""
    port = free_port()
    code = "import sys; from surfgen.pipelines.cli.main import main; sys.exit(main())"
    proc = subprocess.Popen(
        [sys.executable, "-c", code, "serve", "-C", str(root), "--port", str(port)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    url = f"http://127.0.0.1:{port}/"
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise AssertionError(f"surfgen serve exited: {proc.stderr.read()}")
        try:
            with urllib.request.urlopen(url + "api/health", timeout=2) as res:
                if res.status == 200:
                    return proc, url
        except OSError:
            time.sleep(0.2)
    proc.kill()
    raise AssertionError("surfgen serve did not answer within 30 s")


def stop_server(proc: subprocess.Popen) -> None:
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    proc.stdout.close()
    proc.stderr.close()


def wait_for(what: Callable[[], object], timeout: float = 15.0, message: str = "") -> object:
    """Poll ``what`` until it is truthy. The page re-renders a card when its state changes, so an
    element found a moment ago may be gone when it is read: a stale element means "look again",
    as Selenium's own ``WebDriverWait`` treats it; only the deadline fails the test."""
    from selenium.common.exceptions import StaleElementReferenceException

    deadline = time.monotonic() + timeout
    while True:
        try:
            value = what()
        except StaleElementReferenceException:
            value = None
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {message or what}")
        time.sleep(0.1)


def make_browser(profile: Path, flags: tuple[str, ...] = ("--disable-gpu",)):
    """Debian's headless Chromium through chromedriver, with a fresh profile and ``flags``."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    assert CHROMEDRIVER.exists(), (
        "chromium is installed but not chromium-driver (apt-get install chromium-driver)"
    )
    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for arg in (
        "--headless",
        "--no-sandbox",
        *flags,
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        f"--user-data-dir={profile}",
        "--window-size=1280,900",
    ):
        options.add_argument(arg)
    return webdriver.Chrome(options=options, service=Service(str(CHROMEDRIVER)))


def db_row(root: Path, key: str) -> dict:
    with open_catalogue(root, must_exist=True) as cat:
        return cat.shape(key)
