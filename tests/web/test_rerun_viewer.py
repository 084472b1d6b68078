"""An evaluation's rerun recording opened in rerun's own viewer (its web build, served by
``rerun --serve-web``, in headless Chromium drawing WebGL on the CPU): the file starts with its
layout and summary, so the viewer shows the summary table while it still reads the episodes.
With ``OASIS_REGENERATE_ASSETS=1`` it rewrites the rerun guide's two screenshots (the summary and
a crashed episode side by side with the autopilot), at the hosted size."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from oasis_torchrl.cli import main

from ._viewer import open_on_table, web_viewer

ASSETS = Path(__file__).parents[2] / "docs" / "assets"
REGENERATE = os.environ.get("OASIS_REGENERATE_ASSETS") == "1"
OPEN_WITHIN_S = 90.0  # a busy CI machine draws WebGL on its CPU


@pytest.mark.timeout(900)
def test_the_viewer_opens_an_evaluation_on_its_summary(browser, tmp_path: Path) -> None:
    path = tmp_path / "pair.rrd"
    size = ["env.server.width=384", "env.server.height=256"] if REGENERATE else []
    evaluated = ["policy=constant:throttle=1.0,steering=0.0", "compare=[autopilot]"]
    run = ["episodes=4", "max_steps=100", f"rerun={path}", "progress=false", *size]
    assert main(["eval", *evaluated, *run]) == 0
    if REGENERATE:
        browser.set_window_size(1600, 1000)
    with web_viewer(path.parent) as url:
        seconds, _ = open_on_table(browser, url(path.name), OPEN_WITHIN_S)
        assert seconds is not None, f"no summary table within {OPEN_WITHIN_S:.0f} s"
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
