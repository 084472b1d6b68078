"""Fixtures of the LeRobot tool tests: a virtual X display to type into."""

from __future__ import annotations

import os
import select
import shutil
import subprocess
from collections.abc import Iterator

import pytest

from ._cli import Display

XVFB_PACKAGES = "Debian's xvfb and xdotool (apt-get install xvfb xdotool; .ci/run installs them)"


@pytest.fixture(scope="module")
def display() -> Iterator[Display]:
    """A fresh Xvfb display for the module's tests."""
    missing = [tool for tool in ("Xvfb", "xdotool") if shutil.which(tool) is None]
    if missing:
        pytest.skip(f"{missing} not found: keyboard tests need {XVFB_PACKAGES}")
    read_end, write_end = os.pipe()
    server = subprocess.Popen(
        ["Xvfb", "-displayfd", str(write_end), "-screen", "0", "320x240x24", "-nolisten", "tcp"],
        pass_fds=(write_end,),
        stderr=subprocess.DEVNULL,
    )
    os.close(write_end)
    try:
        ready, _, _ = select.select([read_end], [], [], 30)
        assert ready, "Xvfb did not report its display within 30 s"
        number = os.read(read_end, 64).decode().strip()
        yield Display(f":{number}")
    finally:
        os.close(read_end)
        server.terminate()
        server.wait(timeout=30)
