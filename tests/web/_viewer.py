"""rerun's web viewer in headless Chromium, shared by the browser tests and
``benchmarks/viewer_load.py``: the browser (Debian's ``chromium`` and ``chromium-driver`` through
Selenium, WebGL drawn on the CPU), rerun's web viewer (``rerun --serve-web``) with recordings
served to it over HTTP, and the probe that tells when the summary tab's table of episodes shows.

A benchmark imports it as ``web._viewer`` with ``tests/`` on ``sys.path``, as pytest does.
"""

from __future__ import annotations

import contextlib
import functools
import io
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import IO, Any
from urllib.parse import quote

import numpy as np
from PIL import Image

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
VIEWER_START_S = 60.0
"""How long ``rerun --serve-web`` may take to listen."""
TABLE = (0.17, 0.13, 0.75, 0.33)
"""Where the summary tab's table of episodes lies in the viewer (left, top, right, bottom as
shares of the window): white while the viewer loads, text once the table shows."""


def missing_browser() -> str | None:
    """Why headless Chromium cannot be driven here, or None if it can.

    Example:
        >>> missing_browser() is None or "chromium" in missing_browser()
        True
    """
    if not (CHROMIUM.exists() and CHROMEDRIVER.exists()):
        return (
            f"the browser needs Debian's chromium and chromium-driver ({CHROMIUM}, "
            f"{CHROMEDRIVER}: apt-get install chromium chromium-driver; .ci/run installs them)"
        )
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "the browser is driven through Selenium: pip install -e '.[dev]'"
    return None


@contextmanager
def headless_chromium() -> Iterator[Any]:
    """Headless Chromium through Selenium (:data:`BROWSER_FLAGS`), a fresh profile, quit at the
    end; a RuntimeError says what is missing (:func:`missing_browser`)."""
    missing = missing_browser()
    if missing is not None:
        raise RuntimeError(missing)
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


class _Files(SimpleHTTPRequestHandler):
    """Serves a folder to the viewer's page, which lives on another port (never cached: a
    recording is read anew each time)."""

    def end_headers(self) -> None:
        self.send_header("Access-Control-Allow-Origin", "*")
        self.send_header("Cache-Control", "no-store")
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
def web_viewer(folder: Path) -> Iterator[Callable[[str | None], str]]:
    """rerun's web viewer (``rerun --serve-web``) and ``folder`` served over HTTP; yields
    ``url(name)``: the viewer's address with the recording ``folder/name`` as its data source
    (``url(None)``: the viewer alone). A RuntimeError says why the viewer did not start."""
    handler = functools.partial(_Files, directory=str(folder))
    files = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=files.serve_forever, daemon=True).start()
    web_port = _free_port()
    args = ["--serve-web", "--web-viewer-port", str(web_port), "--port", str(_free_port())]
    # What the viewer says goes to a file, not a pipe: a full pipe would stop it.
    with tempfile.TemporaryFile(mode="w+") as said:
        # A session of its own: ``python -m rerun`` runs the viewer as its child, which ends
        # with it only when the whole group is ended.
        viewer = subprocess.Popen(
            [sys.executable, "-m", "rerun", *args],
            stdout=subprocess.DEVNULL,
            stderr=said,
            start_new_session=True,
        )
        try:
            deadline = time.monotonic() + VIEWER_START_S
            while not _listening(web_port):
                if viewer.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"rerun's web viewer did not start: {_why(viewer, said)}")
                time.sleep(0.2)

            def url(name: str | None) -> str:
                page = f"http://127.0.0.1:{web_port}/"
                if name is None:
                    return page
                source = f"http://127.0.0.1:{files.server_address[1]}/{name}"
                return f"{page}?url={quote(source, safe='')}"

            yield url
        finally:
            _end_group(viewer)
            files.shutdown()
            files.server_close()


def _end_group(process: subprocess.Popen) -> None:
    """End ``process`` and the processes it started (its session's group)."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(process.pid, signal.SIGTERM)
    try:
        process.wait(timeout=30)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait(timeout=30)


def _why(viewer: subprocess.Popen, said: IO[str]) -> str:
    """What the viewer's process said, if it ended; else that it did not listen in time."""
    if viewer.poll() is None:
        return f"rerun --serve-web did not listen within {VIEWER_START_S:.0f} s"
    said.seek(0)
    text = said.read().strip()[-2000:] or "(nothing)"
    return f"rerun --serve-web exited with {viewer.returncode}: {text}"


def table_shown(browser: Any) -> Image.Image | None:
    """The screenshot if the summary's table shows in it (dark text where it lies), else None."""
    shot = Image.open(io.BytesIO(browser.get_screenshot_as_png())).convert("L")
    width, height = shot.size
    left, top, right, bottom = TABLE
    region = np.asarray(shot.crop((left * width, top * height, right * width, bottom * height)))
    # A table is text on a light page: the viewer's start is dark all over, its loading screen
    # white all over, plots leave about 1% of it drawn; the table draws 6-10%, on 55-70% white.
    drawn, light = (region < 200).mean(), (region > 240).mean()
    return shot if 0.03 < drawn < 0.3 and light > 0.4 else None


def open_on_table(
    browser: Any, url: str, within_s: float, poll_s: float = 0.5
) -> tuple[float | None, Image.Image | None]:
    """Open ``url`` and wait until the summary's table shows: the seconds from the page's
    request to the screenshot that shows it, and that screenshot; ``(None, None)`` if it does
    not show within ``within_s``."""
    started = time.monotonic()
    browser.get(url)
    while time.monotonic() - started < within_s:
        shown = table_shown(browser)
        if shown is not None:
            return time.monotonic() - started, shown
        time.sleep(poll_s)
    return None, None
