"""One loader for any LeRobot policy folder: ``load_driver(<folder>)``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from lerobot.envs.utils import preprocess_observation
from tensordict import TensorDict

from oasis_torchrl.commands import eval as eval_command
from oasis_torchrl.config import load_config
from oasis_torchrl.drivers import PolicyDriver, load_driver
from oasis_torchrl.drivers.folders import export_lerobot
from oasis_torchrl.drivers.lerobot import LeRobotDriver
from oasis_torchrl.models import DrivingNet
from oasis_torchrl.protocol import CAMERAS, FRONT_CROP, POLICY_CAMERAS

from ._policies import IMAGE_SIZE, act_folder


@pytest.fixture(scope="module")
def act(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return act_folder(tmp_path_factory.mktemp("act") / "pretrained_model")


def _chunk_step(rows: int, step_count: int, seed: int = 0) -> TensorDict:
    """One env step's observation as the env factory gives it (all 4 frames per camera)."""
    generator = torch.Generator().manual_seed(seed)
    td = TensorDict(batch_size=[rows])
    for camera in CAMERAS:
        td["pixels", camera] = torch.randint(
            0, 256, (rows, 4, *IMAGE_SIZE, 3), dtype=torch.uint8, generator=generator
        )
    td["state"] = torch.rand(rows, 2, generator=generator) * 2 - 1
    td["step_count"] = torch.full((rows, 1), step_count)
    td["prompt"] = "urban"
    return td


def test_the_folder_type_picks_the_loader(act: Path, tmp_path: Path) -> None:
    assert isinstance(load_driver(act), LeRobotDriver)
    assert load_driver(act).image_size == IMAGE_SIZE
    oasis = export_lerobot(DrivingNet(), tmp_path / "oasis")
    assert isinstance(load_driver(oasis), PolicyDriver)  # ours stays the TorchRL network
    with pytest.raises(FileNotFoundError, match=r"no config\.json"):
        load_driver(tmp_path)
    unknown = tmp_path / "unknown"
    unknown.mkdir()
    (unknown / "config.json").write_text(json.dumps({"type": "no_such_policy"}))
    with pytest.raises(ValueError, match="no_such_policy"):
        load_driver(unknown)


def test_a_chunk_is_planned_on_the_newest_frame_and_the_previous_action(act: Path) -> None:
    driver = load_driver(act)
    first = _chunk_step(rows=2, step_count=0)
    chunk = driver(first.clone())["action"]
    # What the policy plans from the last frame of each camera and the state, postprocessed.
    observation = preprocess_observation(
        {
            "pixels": {c: first["pixels", c][:, -1].numpy() for c in CAMERAS},
            "agent_pos": first["state"].numpy(),
        }
    )
    observation["task"] = ["urban"] * 2
    batch = driver.preprocessor(observation)
    with torch.no_grad():
        planned = driver.policy.predict_action_chunk(batch)[:, :4]
    expected = torch.stack([driver.postprocessor(planned[:, k]) for k in range(4)], dim=1)
    torch.testing.assert_close(chunk, expected.clamp(-1, 1))
    # Mid-episode the queue carries on; a row starting an episode makes every row plan afresh.
    later = _chunk_step(rows=2, step_count=1, seed=1)
    assert not torch.equal(driver(later.clone())["action"], chunk)
    torch.testing.assert_close(driver(first.clone())["action"], chunk)


def test_frames_of_another_size_are_resized_to_the_policy(act: Path) -> None:
    driver = load_driver(act)
    td = _chunk_step(rows=1, step_count=0)
    for camera in CAMERAS:
        td["pixels", camera] = torch.zeros(1, 4, 128, 192, 3, dtype=torch.uint8)
    assert driver(td)["action"].shape == (1, 4, 2)


def test_a_stock_policy_reading_the_crop_gets_it_or_a_named_error(tmp_path: Path) -> None:
    folder = act_folder(tmp_path / "act_crop", cameras=POLICY_CAMERAS)
    driver = load_driver(folder)
    assert driver.cameras == POLICY_CAMERAS and driver.front_crop is None  # ACT keeps no fraction
    td = _chunk_step(rows=1, step_count=0)
    with pytest.raises(ValueError, match=r"lacks \['front_crop'\]: build it with env\.front_crop"):
        driver(td.clone())
    td["pixels", FRONT_CROP] = td["pixels", "front"].flip(-2)
    assert driver(td)["action"].shape == (1, 4, 2)


def test_oasis_torchrl_eval_evaluates_a_stock_act_folder(act: Path, tmp_path: Path) -> None:
    output = tmp_path / "eval.json"
    overrides = [f"policy={act}", "episodes=2", "max_steps=3", f"output={output}"]
    assert eval_command.run(load_config("eval", overrides)) == 0
    report = json.loads(output.read_text())
    assert report["episodes"] == 2 and report["mean_distance"] >= 0
