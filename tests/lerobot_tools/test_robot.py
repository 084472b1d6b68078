"""The oasis robot in-process: its features, its episodes and seeds, bad actions."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from lerobot.robots.utils import make_robot_from_config
from lerobot.utils.feature_utils import hw_to_dataset_features
from lerobot.utils.utils import log_say
from lerobot_robot_oasis import OasisRobot, OasisRobotConfig

from oasis_torchrl.data.features import DatasetLayout, build_features
from oasis_torchrl.protocol import API_KEY_ENV_VAR, CAMERAS
from oasis_torchrl.rewards import DepthCollisionReward, GroundTruthReward
from oasis_torchrl.sim.launcher import LocalServer


@pytest.fixture
def robot() -> Iterator[OasisRobot]:
    robot = make_robot_from_config(OasisRobotConfig(seed=5))
    robot.connect()
    yield robot
    if robot.is_connected:
        robot.disconnect()


def _drive(robot: OasisRobot, ticks: int, throttle: float = 1.0) -> None:
    for _ in range(ticks):
        robot.get_observation()
        robot.send_action({"throttle.vel": throttle, "steering.vel": 0.2})


def test_recorded_features_are_the_project_datasets() -> None:
    robot = OasisRobot(OasisRobotConfig())
    recorded = {
        **hw_to_dataset_features(robot.observation_features, "observation"),
        **hw_to_dataset_features(robot.action_features, "action"),
    }
    layout = DatasetLayout(CAMERAS, (64, 96), with_reward=False, with_seed=False)
    project = {key: value for key, value in build_features(layout).items() if key != "next.done"}
    assert recorded.keys() == project.keys()
    for key, feature in project.items():
        assert recorded[key]["dtype"] == feature["dtype"], key
        assert tuple(recorded[key]["shape"]) == tuple(feature["shape"]), key
        assert list(recorded[key]["names"]) == list(feature["names"]), key
    assert robot.robot_type == robot.name == "oasis" and robot.cameras == {}


def test_a_tick_holds_the_newest_frame_and_sends_every_fourth(robot: OasisRobot) -> None:
    first = robot.get_observation()
    assert first["throttle.vel"] == first["steering.vel"] == 0.0
    frames = []
    for throttle in (1.0, 0.5, 0.25, 0.75):
        robot.send_action({"throttle.vel": throttle, "steering.vel": 0.0})
        frames.append(robot.get_observation())
    held = [np.array_equal(frame["front"], first["front"]) for frame in frames]
    assert held == [True, True, True, False]  # the 4th action sends the chunk
    assert [frame["throttle.vel"] for frame in frames] == [1.0, 0.5, 0.25, 0.75]


def test_dataset_episode_n_is_the_world_of_seed_plus_n(
    robot: OasisRobot, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO)  # LeRobot's tools log at INFO
    _drive(robot, 8)
    log_say("Recording episode 2", play_sounds=False)
    fresh = robot.get_observation()
    assert robot.episode == 2 and fresh["throttle.vel"] == 0.0
    other = OasisRobot(OasisRobotConfig(seed=7))
    other.connect()
    try:
        expected = other.get_observation()
    finally:
        other.disconnect()
    for camera in CAMERAS:
        np.testing.assert_array_equal(fresh[camera], expected[camera])
    # A re-recorded episode is announced again: an untouched world is kept, a driven one rebuilt.
    log_say("Recording episode 2", play_sounds=False)
    np.testing.assert_array_equal(robot.get_observation()["front"], fresh["front"])
    _drive(robot, 4)
    assert not np.array_equal(robot.get_observation()["front"], fresh["front"])
    log_say("Recording episode 2", play_sounds=False)
    np.testing.assert_array_equal(robot.get_observation()["front"], fresh["front"])
    robot.disconnect()
    log_say("Recording episode 3", play_sounds=False)  # a disconnected robot stops listening


def test_bad_actions_are_named(robot: OasisRobot) -> None:
    with pytest.raises(KeyError, match=r"lacks \['steering\.vel'\]"):
        robot.send_action({"throttle.vel": 1.0, "angular_velocity": 0.5})
    with pytest.raises(ValueError, match="not finite"):
        robot.send_action({"throttle.vel": float("nan"), "steering.vel": 0.0})


def test_a_remote_endpoint_drives_without_ground_truth(
    local_server: LocalServer, server_keys: tuple[str, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(API_KEY_ENV_VAR, server_keys[0])  # keys never travel as flags
    robot = OasisRobot(OasisRobotConfig(endpoint=f"http://{local_server.address}", image_height=32))
    robot.connect()
    try:
        first = robot.get_observation()
        _drive(robot, 8)
        assert first["front"].shape == (32, 96, 3)
        assert not np.array_equal(robot.get_observation()["front"], first["front"])
    finally:
        robot.disconnect()


def test_a_robots_steps_run_no_reward(
    local_server: LocalServer, server_keys: tuple[str, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    def scored(self: object, td: object) -> None:
        raise AssertionError(f"{type(self).__name__} scored a robot's step")

    # Frames alone would get the depth-collision reward, ground truth the ground-truth one.
    monkeypatch.setattr(DepthCollisionReward, "__call__", scored)
    monkeypatch.setattr(GroundTruthReward, "__call__", scored)
    monkeypatch.setenv(API_KEY_ENV_VAR, server_keys[0])
    robot = OasisRobot(OasisRobotConfig(endpoint=f"http://{local_server.address}", image_height=32))
    robot.connect()
    try:
        _drive(robot, 8)
    finally:
        robot.disconnect()


def test_the_robots_rerun_recording_is_the_shared_one(tmp_path: Path) -> None:
    """``--robot.rerun``: the same recording as an evaluation's (frames as served, a tab named
    after its episode, the step timeline)."""
    from viz._readback import Readback, blueprint_views, printed

    path = tmp_path / "robot.rrd"
    robot = make_robot_from_config(OasisRobotConfig(seed=5, rerun=str(path)))
    robot.connect()
    try:
        _drive(robot, 8)  # two chunks
        robot.start_episode(3)  # LeRobot's dataset episode 3: the events say so
        _drive(robot, 4)
    finally:
        robot.disconnect()
    readback = Readback(path)

    frames, images = readback.images("env/0/camera/front")
    assert frames == [3, 7, 11, 15, 19]  # a reset, then the last frame of each chunk
    assert images[0].shape == (64, 96, 3)  # as served: the viewer scales it
    steps, _ = readback.column("env/0/action/throttle", "Scalars:scalars", index="step")
    assert steps == [1, 2, 4]
    starts = [text.split(":")[0] for text in readback.texts("env/0/events")[1]]
    assert starts == ["episode 0 starts", "episode 3 starts"]
    assert "[episode 0: running; episode 3: running]" in printed(path)
    assert ("2D", "oasis: front", "env/0/camera/front") in blueprint_views(path)  # the robot's
