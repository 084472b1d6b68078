"""An evaluation's rerun recording opened in rerun's own viewer (its web build, served by
``rerun --serve-web``, in headless Chromium drawing WebGL on the CPU): the file starts with its
layout and summary, so the viewer shows the summary table while it still reads the episodes.
With ``OASIS_REGENERATE_ASSETS=1`` it rewrites the rerun guide's two screenshots (the summary and
a crashed episode side by side with the autopilot), at the hosted size."""

from __future__ import annotations

import functools
import io
import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import quote

import numpy as np
import pytest
from PIL import Image

from oasis_torchrl.cli import main

ASSETS = Path(__file__).parents[2] / "docs" / "assets"
REGENERATE = os.environ.get("OASIS_REGENERATE_ASSETS") == "1"
OPEN_WITHIN_S = 90.0  # a busy CI machine draws WebGL on its CPU
TABLE = (0.17, 0.13, 0.75, 0.33)
"""Where the summary tab's table of episodes lies in the viewer (left, top, right, bottom as
shares of the window): white while the viewer loads, text once the table shows."""


class _Files(SimpleHTTPRequestHandler):
    """Serves a folder to the viewer's page, which lives on another port."""

    def end_headers(self) -> None:
        self.send_header("Access-Control-Allow-Origin", "*")
        super().end_headers()

    def log_message(self, *args: object) -> None:
        pass


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _listening(port: int) -> bool:
    with socket.socket() as probe:
        return probe.connect_ex(("127.0.0.1", port)) == 0


@contextmanager
def _viewer_url(recording: Path) -> Iterator[str]:
    """The web viewer's address with ``recording`` (served over HTTP) as its data source."""
    handler = functools.partial(_Files, directory=str(recording.parent))
    files = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=files.serve_forever, daemon=True).start()
    web_port = _free_port()
    args = ["--serve-web", "--web-viewer-port", str(web_port), "--port", str(_free_port())]
    viewer = subprocess.Popen(
        [sys.executable, "-m", "rerun", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 60
        while not _listening(web_port) and time.monotonic() < deadline:
            time.sleep(0.2)
        source = f"http://127.0.0.1:{files.server_address[1]}/{recording.name}"
        yield f"http://127.0.0.1:{web_port}/?url={quote(source, safe='')}"
    finally:
        viewer.terminate()
        viewer.wait(timeout=30)
        files.shutdown()


def _table_shown(browser) -> Image.Image | None:
    """The screenshot if the summary's table shows in it (dark text where it lies), else None."""
    shot = Image.open(io.BytesIO(browser.get_screenshot_as_png())).convert("L")
    width, height = shot.size
    left, top, right, bottom = TABLE
    region = np.asarray(shot.crop((left * width, top * height, right * width, bottom * height)))
    # A table is text on a light page: the viewer's start is dark all over, its loading screen
    # white all over, plots leave about 1% of it drawn; the table draws 6-10%, on 55-70% white.
    drawn, light = (region < 200).mean(), (region > 240).mean()
    return shot if 0.03 < drawn < 0.3 and light > 0.4 else None


@pytest.mark.timeout(900)
def test_the_viewer_opens_an_evaluation_on_its_summary(browser, tmp_path: Path) -> None:
    path = tmp_path / "pair.rrd"
    size = ["env.server.width=384", "env.server.height=256"] if REGENERATE else []
    evaluated = ["policy=constant:throttle=1.0,steering=0.0", "compare=[autopilot]"]
    run = ["episodes=4", "max_steps=100", f"rerun={path}", "progress=false", *size]
    assert main(["eval", *evaluated, *run]) == 0
    if REGENERATE:
        browser.set_window_size(1600, 1000)
    with _viewer_url(path) as url:
        browser.get(url)
        started, shown = time.monotonic(), None
        while shown is None and time.monotonic() - started < OPEN_WITHIN_S:
            time.sleep(0.5)
            shown = _table_shown(browser)
        assert shown is not None, f"no summary table within {OPEN_WITHIN_S:.0f} s"
        if REGENERATE:
            time.sleep(5)  # the bar charts and the time panel settle
            browser.save_screenshot(str(ASSETS / "rerun_summary.png"))
            _open_first_episode(browser)
            browser.save_screenshot(str(ASSETS / "rerun_crash.png"))


def _open_first_episode(browser) -> None:
    """Click the tab after the summary's (the first episode's) and let it draw."""
    from selenium.webdriver.common.action_chains import ActionChains

    canvas = browser.find_element("tag name", "canvas")
    width, height = canvas.size["width"], canvas.size["height"]
    tab = (0.37 * width, 0.047 * height)
    ActionChains(browser).move_to_element_with_offset(
        canvas, tab[0] - width / 2, tab[1] - height / 2
    ).click().perform()
    time.sleep(8)
