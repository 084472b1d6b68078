"""Fixtures of the drive page tests: the page served on loopback, and headless Chromium.

Chromium and its driver are Debian's ``chromium`` and ``chromium-driver`` (``.ci/run`` installs
them); Selenium drives them through the system ``chromedriver``, no browser download
(:mod:`._viewer`, which the viewer-load benchmark shares).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

from oasis_torchrl.config import load_config, to_object
from oasis_torchrl.web import RunningPage

from ._viewer import headless_chromium, missing_browser

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
    """Headless Chromium through Selenium, a fresh profile per module (skipped without it)."""
    missing = missing_browser()
    if missing is not None:
        pytest.skip(f"browser tests: {missing}")
    with headless_chromium() as driver:
        yield driver
