"""Fixtures of the drive page tests: the page served on loopback, and headless Chromium.

Chromium and its driver are Debian's ``chromium`` and ``chromium-driver`` (``.ci/run`` installs
them); Selenium drives them through the system ``chromedriver``, no browser download.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from oasis_torchrl.config import load_config, to_object
from oasis_torchrl.web import RunningPage

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
BROWSER_FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--window-size=1280,760",
    # WebGL on the CPU (SwiftShader): rerun's web viewer draws with it, as on a machine without
    # a GPU driver
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
)
SMALL = ("env.server.width=96", "env.server.height=64")


def page_config(*settings: str):
    """The play settings of a test page: a free loopback port, 96x64 frames."""
    return to_object(load_config("play", ["port=0", *SMALL, *settings]))


@pytest.fixture
def serve_page() -> Iterator[Callable[..., RunningPage]]:
    """``serve_page(*settings, token=None)``: a running page (closed at the end of the test)."""
    opened: list[RunningPage] = []

    def serve(*settings: str, token: str | None = None) -> RunningPage:
        page = RunningPage(page_config(*settings), token=token)
        opened.append(page)
        return page.__enter__()

    yield serve
    for page in opened:
        page.close()


@pytest.fixture(scope="module")
def browser():
    """Headless Chromium through Selenium, a fresh profile per module."""
    if not (CHROMIUM.exists() and CHROMEDRIVER.exists()):
        pytest.skip(
            "browser tests need Debian's chromium and chromium-driver "
            "(apt-get install chromium chromium-driver; .ci/run installs them)"
        )
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="oasis-chromium-")
    options = Options()
    options.binary_location = str(CHROMIUM)
    for flag in (*BROWSER_FLAGS, f"--user-data-dir={profile}"):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=options)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)
