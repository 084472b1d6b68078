"""The narrow forward crop through LeRobot's doors: the oasis env (``--env.front_crop``), the
oasis robot (``--robot.front_crop``) and ``lerobot-eval`` of a policy that reads the crop.

Frames of 24x32 with a crop of half the front frame: the world is rendered at 48x64, so the crop
must be the centre of that world's full-size front frame, pixel for pixel."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from lerobot.envs.utils import env_to_policy_features
from lerobot_env_oasis import OasisEnvConfig, OasisVectorEnv
from lerobot_policy_oasis.modeling_oasis import OasisPolicy
from lerobot_robot_oasis import OasisRobot, OasisRobotConfig

from oasis_torchrl.drivers.folders import export_lerobot
from oasis_torchrl.models import DrivingNet, DrivingNetConfig
from oasis_torchrl.protocol import POLICY_CAMERAS

from ._cli import cli_env, run_tool

SMALL, FULL = (24, 32), (48, 64)
CENTRE = (slice(12, 36), slice(16, 48))  # half of a 48x64 frame's height and width
SEED = 4


def _env_frames(size: tuple[int, int], front_crop: float | None) -> dict[str, np.ndarray]:
    height, width = size
    config = OasisEnvConfig(
        episode_length=4,
        observation_height=height,
        observation_width=width,
        server_height=height,
        server_width=width,
        front_crop=front_crop,
    )
    env = OasisVectorEnv(config, num_envs=1)
    try:
        assert set(env.observation_space["pixels"]) == set(config.cameras)
        observation, _ = env.reset(seed=SEED)
        return observation["pixels"]
    finally:
        env.close()


def test_the_env_gives_the_crop_as_a_fourth_camera() -> None:
    config = OasisEnvConfig(front_crop=0.5)
    assert env_to_policy_features(config)["observation.images.front_crop"].shape == (3, 64, 96)
    crop = _env_frames(SMALL, 0.5)["front_crop"]
    full = _env_frames(FULL, None)["front"]
    assert crop.shape == (1, *SMALL, 3)
    np.testing.assert_array_equal(crop[0], full[0][CENTRE])
    with pytest.raises(ValueError, match=r"front_crop must be a fraction in \(0, 1\], got 1\.5"):
        OasisEnvConfig(front_crop=1.5)


def _robot_observation(size: tuple[int, int], front_crop: float | None) -> dict:
    height, width = size
    robot = OasisRobot(
        OasisRobotConfig(
            seed=SEED,
            image_height=height,
            image_width=width,
            server_height=height,
            server_width=width,
            front_crop=front_crop,
        )
    )
    robot.connect()
    try:
        assert set(robot.observation_features) >= set(robot.config.camera_names)
        return robot.get_observation()
    finally:
        robot.disconnect()


def test_the_robot_records_the_crop() -> None:
    crop = _robot_observation(SMALL, 0.5)["front_crop"]
    full = _robot_observation(FULL, None)["front"]
    assert crop.shape == (*SMALL, 3)
    np.testing.assert_array_equal(crop, full[CENTRE])
    with pytest.raises(ValueError, match="front_crop must be a fraction"):
        OasisRobotConfig(front_crop=0.0)


@pytest.fixture(scope="module")
def crop_policy(tmp_path_factory: pytest.TempPathFactory) -> Path:
    torch.manual_seed(0)
    net = DrivingNet(DrivingNetConfig(cameras=POLICY_CAMERAS, image_size=SMALL, front_crop=0.5))
    return export_lerobot(net, tmp_path_factory.mktemp("crop") / "policy")


def test_a_policy_without_its_crop_names_the_flag(crop_policy: Path) -> None:
    policy = OasisPolicy.from_pretrained(str(crop_policy))
    batch = {f"observation.images.{c}": torch.zeros(1, 3, *SMALL) for c in POLICY_CAMERAS[:3]}
    batch["observation.state"] = torch.zeros(1, 2)
    with pytest.raises(KeyError, match=r"front_crop.*--env\.front_crop=0\.5 in lerobot-eval"):
        policy.select_action(batch)


@pytest.mark.timeout(900)
def test_lerobot_eval_drives_a_crop_policy_with_the_crop(crop_policy: Path, tmp_path: Path) -> None:
    output = tmp_path / "eval"
    args = [
        f"--policy.path={crop_policy}",
        "--env.type=oasis",
        "--env.task=urban",
        "--env.episode_length=8",
        f"--env.observation_height={SMALL[0]}",
        f"--env.observation_width={SMALL[1]}",
        f"--env.server_height={SMALL[0]}",
        f"--env.server_width={SMALL[1]}",
        "--env.front_crop=0.5",
        "--eval.batch_size=2",
        "--eval.n_episodes=2",
        f"--seed={SEED}",
        f"--output_dir={output}",
    ]
    run_tool("lerobot-eval", args, cli_env(tmp_path / "home"), 900.0)
    info = json.loads((output / "eval_info.json").read_text())
    assert info["overall"]["n_episodes"] == 2
