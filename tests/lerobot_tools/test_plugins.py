"""LeRobot finds every plugin by its distribution name; the teleoperators and the example."""

from __future__ import annotations

import importlib.metadata
import json
from pathlib import Path

import pytest
from lerobot.envs.configs import EnvConfig
from lerobot.policies.factory import get_policy_class
from lerobot.robots import RobotConfig
from lerobot.robots.utils import make_robot_from_config
from lerobot.teleoperators import TeleoperatorConfig, make_teleoperator_from_config
from lerobot.utils.errors import DeviceNotConnectedError
from lerobot.utils.import_utils import register_third_party_plugins

from ._cli import cli_env, run_tool
from ._policies import act_folder

EXAMPLE = Path(__file__).parents[2] / "examples" / "lerobot_world_model.py"
DISTRIBUTIONS = ("policy", "robot", "teleoperator", "env")


def test_lerobot_imports_every_plugin_by_its_distribution_name() -> None:
    installed = {dist.metadata["Name"] for dist in importlib.metadata.distributions()}
    assert {f"lerobot_{kind}_oasis" for kind in DISTRIBUTIONS} <= installed
    register_third_party_plugins()
    assert "oasis" in RobotConfig.get_known_choices()
    assert "oasis" in EnvConfig.get_known_choices()
    assert get_policy_class("oasis").name == "oasis"
    robot = make_robot_from_config(RobotConfig.get_choice_class("oasis")())
    assert type(robot).__name__ == "OasisRobot"
    for name in ("oasis_keyboard", "oasis_gamepad"):
        teleop = make_teleoperator_from_config(TeleoperatorConfig.get_choice_class(name)())
        assert teleop.action_features == robot.action_features


def test_a_gamepad_that_is_not_there_is_named() -> None:
    teleop = make_teleoperator_from_config(TeleoperatorConfig.get_choice_class("oasis_gamepad")())
    with pytest.raises((ImportError, DeviceNotConnectedError), match="gamepad"):
        teleop.connect()


@pytest.mark.timeout(900)
def test_the_example_records_trains_and_evaluates(tmp_path: Path) -> None:
    policy = act_folder(tmp_path / "act", n_action_steps=8)
    root = tmp_path / "drive"
    args = [str(EXAMPLE), "--root", str(root), "--episodes", "2", "--seconds", "0.5"]
    args += ["--policy", str(policy), "--sessions", "2", "--episode-frames", "8"]
    args += ["--train", "oasis", "act", "--train-steps", "2"]
    done = run_tool("python", args, cli_env(tmp_path / "hf"), timeout=900)
    assert "recorded 2 episodes, 20 rows" in done.stdout
    reports = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    trained = [
        tmp_path / f"drive_{kind}/checkpoints/last/pretrained_model" for kind in ("oasis", "act")
    ]
    assert [report["policy"] for report in reports] == [str(policy), *map(str, trained)]
    for report in reports:
        assert report["episodes"] == 2 and 0.0 <= report["collision_rate"] <= 1.0
