"""A person drives the world model in headless Chromium: real key events on the page move the car
(ground truth), record an episode that LeRobot reads back, and replay it."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from oasis_torchrl.config import load_config
from oasis_torchrl.data.features import DatasetLayout, build_features, user_features
from oasis_torchrl.protocol import CAMERAS
from oasis_torchrl.train.bc import BCTrainer
from oasis_torchrl.web import RunningPage

SCREENSHOT = Path(__file__).parents[2] / "docs" / "assets" / "drive_page.png"
REGENERATE = os.environ.get("OASIS_REGENERATE_ASSETS") == "1"
WAIT_S = 120.0  # a busy CI machine; the checks themselves do not depend on timing


FAKE_GAMEPAD = """
const [throttle, steering, pressed] = arguments;
const buttons = Array.from({length: 17}, (_, i) => ({
  pressed: pressed.includes(i) || (i === 7 && throttle > 0), value: i === 7 ? throttle : 0}));
navigator.getGamepads = () => [{axes: [steering, 0, 0, 0], buttons}];
"""
"""Replaces the browser's gamepads with one whose right trigger, left stick and buttons are
given (a headless browser has none)."""


def wait_until(check: Callable[[], Any], what: str, timeout: float = WAIT_S) -> Any:
    """Poll ``check`` until it returns something true (fail naming ``what`` otherwise)."""
    deadline = time.monotonic() + timeout
    while True:
        value = check()
        if value:
            return value
        if time.monotonic() > deadline:
            pytest.fail(f"no {what} within {timeout:.0f} s")
        time.sleep(0.1)


def page_state(browser) -> dict[str, Any]:
    return browser.execute_script("return window.oasisPage")


def status(browser) -> dict[str, Any]:
    return page_state(browser)["status"] or {}


def truth(page: RunningPage, field: str) -> float:
    """The world's ground truth after the latest chunk (embedded server)."""
    return float(page.session.last["next", "truth", field][0, -1])


def chunks_later(browser, count: int) -> None:
    """Wait until ``count`` more chunks were driven."""
    start = status(browser)["chunk"]
    wait_until(lambda: status(browser)["chunk"] >= start + count, f"{count} chunks")


def hold(browser, page: RunningPage, keys: str, field: str, chunks: int) -> float:
    """Hold ``keys`` while the world drives ``chunks`` chunks (however long they take on this
    machine); returns how much truth ``field`` changed meanwhile."""
    from selenium.webdriver.common.action_chains import ActionChains

    chunks_later(browser, 1)
    before = truth(page, field)
    actions = ActionChains(browser)
    for key in keys:
        actions.key_down(key)
    actions.perform()
    chunks_later(browser, chunks)
    after = truth(page, field)
    actions = ActionChains(browser)
    for key in keys:
        actions.key_up(key)
    actions.perform()
    return after - before


def press(browser, key: str) -> None:
    from selenium.webdriver.common.action_chains import ActionChains

    ActionChains(browser).send_keys(key).perform()


def open_page(browser, page: RunningPage) -> None:
    browser.get(page.url)
    wait_until(lambda: page_state(browser)["connected"], "connection")
    wait_until(lambda: status(browser).get("chunk", 0) >= 2, "live frames")


@pytest.mark.timeout(900)
def test_keys_drive_record_and_replay(browser, serve_page, tmp_path: Path) -> None:
    root = tmp_path / "drives"
    size = ("env.server.width=384", "env.server.height=256") if REGENERATE else ()
    page = serve_page(f"root={root}", *size)
    open_page(browser, page)
    assert page_state(browser)["framesShown"] > 0
    assert status(browser)["speed"] is not None  # the embedded server sends ground truth

    press(browser, "r")
    wait_until(lambda: status(browser)["recording"], "recording")
    forward = hold(browser, page, "w", "progress", 6)
    assert forward > 1.0, forward  # metres along the road
    assert truth(page, "speed") > 0
    left = hold(browser, page, "a", "heading", 3)  # coasting
    right = hold(browser, page, "d", "heading", 3)
    assert right < -0.02 < 0.02 < left, (right, left)  # steering + turns clockwise
    assert status(browser)["recording"]  # one episode all along: no collision reset it
    latencies = page_state(browser)["latencies"]
    assert latencies and min(latencies) > 0
    press(browser, "r")
    wait_until(lambda: status(browser)["saved"] == 1, "saved episode")
    assert not status(browser)["recording"]

    dataset = LeRobotDataset("local/drives", root=root, video_backend="pyav")
    assert dataset.num_episodes == 1 and dataset.fps == 20
    layout = DatasetLayout(CAMERAS, (256, 384) if REGENERATE else (64, 96), with_crash=True)
    expected = build_features(layout)
    assert {k: (v["dtype"], tuple(v["shape"])) for k, v in expected.items()} == {
        k: (v["dtype"], tuple(v["shape"])) for k, v in user_features(dataset.features).items()
    }  # the features of `oasis-torchrl record`
    rows = dataset.hf_dataset.with_format("numpy")
    action, state = np.stack(rows["action"]), np.stack(rows["observation.state"])
    assert action[:, 0].max() > 0.9 and action[:, 1].max() > 0.5 and action[:, 1].min() < -0.5
    np.testing.assert_allclose(state[1:], action[:-1])  # each row's state: the action before
    assert dataset.meta.episodes[0]["tasks"] == ["urban street"]

    browser.find_element("id", "replay").click()
    wait_until(lambda: "replayed episode 0" in browser.find_element("id", "message").text, "replay")
    # The end message can arrive while the last frames wait in the page's display queue.
    shown = lambda: page_state(browser)["replayed"] == dataset.num_frames  # noqa: E731
    wait_until(shown, f"all {dataset.num_frames} replayed frames shown")

    # C marks a crash: the episode ends at the next chunk, saved with that chunk's last row
    # marked; the rows of the episode before carry no mark (no collision on the way).
    press(browser, "r")
    wait_until(lambda: status(browser)["recording"], "recording again")
    chunks_later(browser, 2)
    press(browser, "c")
    wait_until(lambda: status(browser)["saved"] == 2, "the crashed episode saved")
    assert not status(browser)["recording"]
    rows = LeRobotDataset("local/drives", root=root).hf_dataset.with_format("numpy")
    episode = np.asarray(rows["episode_index"])
    crash, done = (np.asarray(rows[key]).reshape(-1) for key in ("next.crash", "next.done"))
    assert not crash[episode == 0].any()
    assert crash[episode == 1].tolist() == done[episode == 1].tolist()
    assert crash[episode == 1].tolist()[-5:] == [False] * 4 + [True]

    if REGENERATE:
        press(browser, "w")
        chunks_later(browser, 3)
        SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
        browser.save_screenshot(str(SCREENSHOT))

    # A gamepad (the browser's Gamepad API, here a stand-in): analog trigger and stick drive,
    # buttons command.
    browser.execute_script(FAKE_GAMEPAD, 0.7, -0.5, [])
    chunks_later(browser, 3)
    assert page.session.last["action"][0, 0].tolist() == pytest.approx([0.7, -0.5])
    browser.execute_script(FAKE_GAMEPAD, 0.0, 0.0, [3])  # Y: take over (there is no policy)
    wait_until(lambda: "no_policy" in page_state(browser)["errors"], "the takeover refused")
    browser.execute_script(FAKE_GAMEPAD, 0.0, 0.0, [])


@pytest.mark.timeout(900)
def test_a_person_takes_over_from_a_policy_behind_a_token(
    browser, serve_page, tmp_path: Path
) -> None:
    root = tmp_path / "corrections"
    page = serve_page(f"root={root}", "policy=constant:throttle=0.4", token="s3cret")
    browser.get(page.url.split("?")[0])
    assert "forbidden" in browser.find_element("tag name", "body").text
    open_page(browser, page)
    assert status(browser)["policy"] and not status(browser)["human"]

    press(browser, "r")
    wait_until(lambda: status(browser)["recording"], "recording")
    chunks_later(browser, 3)
    press(browser, "t")
    wait_until(lambda: status(browser)["human"], "the person driving")
    hold(browser, page, "d", "heading", 3)
    press(browser, "t")
    wait_until(lambda: not status(browser)["human"], "the policy driving again")
    chunks_later(browser, 3)
    press(browser, "r")
    wait_until(lambda: status(browser)["saved"] == 1, "saved episode")

    dataset = LeRobotDataset("local/corrections", root=root, video_backend="pyav")
    assert dataset.features["intervention"]["dtype"] == "bool"  # LeRobot's DAgger column
    rows = dataset.hf_dataset.with_format("numpy")
    person = np.stack(rows["intervention"]).reshape(-1)
    action = np.stack(rows["action"])
    assert person.any() and not person[:12].any() and not person[-12:].any()
    np.testing.assert_allclose(action[~person], [[0.4, 0.0]] * int((~person).sum()))
    assert action[person, 1].max() > 0.2  # the person steered right

    # Behaviour cloning trains on the corrections as recorded.
    settings = [f"dataset.root={root}", f"output_dir={tmp_path / 'bc'}", "train.steps=2"]
    small = ["policy.image_size=[32,48]", "train.batch_size=8", "eval.episodes=0"]
    result = BCTrainer(load_config("bc", [*settings, *small, "progress=false"])).run()
    assert math.isfinite(result.final_loss)
