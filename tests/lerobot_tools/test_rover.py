"""LeRobot's stock rover teleoperator drives the oasis robot: ``lerobot-record
--teleop.type=keyboard_rover`` with real key events on a virtual display records the mapped
throttle and steering."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from oasis_torchrl.data.features import ACTION_NAMES

from ._cli import STREAMING, Display, background, cli_env

EPISODE_S = 3.0
STARTUP_S = 300.0  # LeRobot's tools import slowly on a busy machine


@pytest.mark.timeout(900)
def test_keyboard_rover_records_a_drive(tmp_path: Path, display: Display) -> None:
    root = tmp_path / "rover"
    args = [
        "--robot.type=oasis",
        "--teleop.type=keyboard_rover",
        "--dataset.repo_id=local/rover",
        f"--dataset.root={root}",
        "--dataset.single_task=urban",
        "--dataset.fps=20",
        "--dataset.num_episodes=1",
        f"--dataset.episode_time_s={EPISODE_S}",
        "--dataset.reset_time_s=0",
        "--dataset.push_to_hub=false",
        *STREAMING,
        "--play_sounds=false",
    ]
    env = cli_env(tmp_path / "hf", DISPLAY=display.name)
    with background("lerobot-record", args, env, tmp_path / "record.log") as record:
        record.wait_for("Recording episode 0", STARTUP_S)
        display.keys("keydown", "w")
        time.sleep(EPISODE_S / 3)
        display.keys("keydown", "a")  # keyboard_rover: angular +1, a left turn
        record.wait_for("Stop recording", STARTUP_S)
        display.keys("keyup", "a", "keyup", "w")
        record.finish(STARTUP_S)

    dataset = LeRobotDataset("local/rover", root=root, video_backend="pyav")
    assert dataset.features["action"]["names"] == list(ACTION_NAMES)
    actions = {tuple(row) for row in np.stack(dataset.hf_dataset["action"]).round(3).tolist()}
    # W: throttle 1; W and A: throttle 1, steering -1 (left in the world's convention).
    assert {(1.0, 0.0), (1.0, -1.0)} <= actions <= {(0.0, 0.0), (1.0, 0.0), (1.0, -1.0)}
