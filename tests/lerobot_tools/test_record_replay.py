"""A person drives the world model with ``lerobot-record`` (real key events on a virtual display)
and ``lerobot-replay`` rebuilds an episode's frames from its seed."""

from __future__ import annotations

import itertools
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from oasis_torchrl.data.features import ACTION_NAMES
from oasis_torchrl.protocol import CAMERAS

from ._cli import STREAMING, Display, background, cli_env, run_tool

SEED = 7
EPISODE_S = 2.0
STARTUP_S = 300.0  # LeRobot's tools import slowly on a busy machine


def _record(root: Path, home: Path, keyboard: Display, log: Path) -> None:
    """Two episodes: W, then W+D held in the first; S held in the second."""
    args = [
        "--robot.type=oasis",
        f"--robot.seed={SEED}",
        "--teleop.type=oasis_keyboard",
        "--dataset.repo_id=local/human",
        f"--dataset.root={root}",
        "--dataset.single_task=urban",
        "--dataset.fps=20",
        "--dataset.num_episodes=2",
        f"--dataset.episode_time_s={EPISODE_S}",
        "--dataset.reset_time_s=0",
        "--dataset.push_to_hub=false",
        *STREAMING,
        "--play_sounds=false",
    ]
    env = cli_env(home, DISPLAY=keyboard.name)
    with background("lerobot-record", args, env, log) as record:
        record.wait_for("Recording episode 0", STARTUP_S)
        keyboard.keys("keydown", "w")
        time.sleep(EPISODE_S / 3)
        keyboard.keys("keydown", "d")
        record.wait_for("Recording episode 1", STARTUP_S)
        keyboard.keys("keyup", "d", "keyup", "w", "keydown", "s")
        record.wait_for("Stop recording", STARTUP_S)
        keyboard.keys("keyup", "s")
        record.finish(STARTUP_S)


def _runs(actions: np.ndarray) -> list[tuple[float, float]]:
    """The distinct actions of consecutive rows, in order."""
    return [key for key, _ in itertools.groupby(map(tuple, actions.round(3).tolist()))]


def _frames(dataset: LeRobotDataset, episode: int, camera: str = "front") -> np.ndarray:
    """uint8 ``[T, H, W, 3]`` frames of one episode."""
    start = dataset.meta.episodes["dataset_from_index"][episode]
    stop = dataset.meta.episodes["dataset_to_index"][episode]
    key = f"observation.images.{camera}"
    frames = [dataset[i][key] for i in range(start, stop)]
    return (torch.stack(frames).permute(0, 2, 3, 1) * 255).round().byte().numpy()


def _episode_columns(dataset: LeRobotDataset, episode: int) -> dict[str, np.ndarray]:
    start = dataset.meta.episodes["dataset_from_index"][episode]
    stop = dataset.meta.episodes["dataset_to_index"][episode]
    rows = dataset.hf_dataset.select(range(start, stop))
    return {k: torch.stack(list(rows[k])).numpy() for k in ("action", "observation.state")}


@pytest.mark.timeout(1500)
def test_a_person_drives_then_lerobot_replay_rebuilds_the_episode(
    tmp_path: Path, display: Display
) -> None:
    root, home = tmp_path / "human", tmp_path / "hf"
    _record(root, home, display, tmp_path / "record.log")

    dataset = LeRobotDataset("local/human", root=root, video_backend="pyav")
    assert dataset.meta.robot_type == "oasis" and dataset.fps == 20
    assert dataset.num_episodes == 2
    assert dataset.features["action"]["names"] == list(ACTION_NAMES)
    assert {f"observation.images.{c}" for c in CAMERAS} <= set(dataset.features)
    first, second = _episode_columns(dataset, 0), _episode_columns(dataset, 1)
    # The actions are the keys held, in the order they were pressed.
    assert set(_runs(first["action"])) <= {(0.0, 0.0), (1.0, 0.0), (1.0, 0.5)}
    assert _runs(first["action"])[-2:] == [(1.0, 0.0), (1.0, 0.5)]
    assert (-1.0, 0.0) in _runs(second["action"])
    # Each row's state is the action before it (zeros at an episode's start).
    for columns in (first, second):
        previous = np.concatenate([np.zeros((1, 2)), columns["action"][:-1]])
        np.testing.assert_allclose(columns["observation.state"], previous)
    # The person drove: the front camera's view changed.
    recorded = _frames(dataset, 0)
    assert np.abs(recorded[-1].astype(int) - recorded[0].astype(int)).mean() > 5

    replayed = _replay(root, home, tmp_path, episode=1)
    again, other = _frames(dataset, 1), _frames(dataset, 0)
    # Row t shows the last frame of chunk t // 4 - 1 (held), the replay's image of tick t // 4
    # (one a tick: the last frame of each chunk, at the size served).
    rows = np.arange(len(again))
    shown = replayed[rows // 4]
    same = np.abs(shown.astype(int) - again.astype(int)).mean()
    n = min(len(shown), len(other))
    elsewhere = np.abs(shown[:n].astype(int) - other[:n].astype(int)).mean()
    # JPEG 70 (the recording) and h264 (the dataset) on both sides; another episode is 4x as far.
    assert same < 10 < elsewhere, (same, elsewhere)


def _replay(root: Path, home: Path, tmp_path: Path, episode: int) -> np.ndarray:
    """Replay ``episode`` on its seed; the frames the world produced, from the robot's rerun
    recording (reset chunk first)."""
    from viz._readback import Readback

    recording = tmp_path / "replay.rrd"
    args = [
        "--robot.type=oasis",
        f"--robot.seed={SEED + episode}",
        f"--robot.rerun={recording}",
        "--dataset.repo_id=local/human",
        f"--dataset.root={root}",
        f"--dataset.episode={episode}",
        "--play_sounds=false",
    ]
    run_tool("lerobot-replay", args, cli_env(home), timeout=STARTUP_S)
    _, frames = Readback(recording).images("env/0/camera/front")
    return np.stack(frames)
