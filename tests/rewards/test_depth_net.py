"""The shipped small depth network as a depth source, its weights files and their errors, and
MonocularDepth's one-line error when its model cannot be fetched offline."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.models.depth import DepthNet, DepthNetConfig
from oasis_torchrl.rewards import DepthCollisionReward, GroundTruthDepth, MonocularDepth
from oasis_torchrl.rewards.depth_net import (
    SmallDepth,
    depth_source_for,
    load_small_depth,
    save_weights,
)
from oasis_torchrl.rewards.depth_sources import DepthModelError
from oasis_torchrl.sim.config import ServerConfig

TINY = DepthNetConfig(channels=(4, 8))


@pytest.fixture(scope="module")
def real_step() -> TensorDict:
    """One step of an urban scene on the embedded server: front frame and metric depth."""
    env = OasisEnv(
        "local",
        2,
        "urban street",
        server=ServerConfig(width=96, height=64, processes=0),
        depth_cameras=("front",),
    )
    try:
        env.set_seed(3)
        td = env.reset()
        td["action"] = torch.tensor([0.5, 0.0]).expand(2, 4, 2).clone()
        return env.step(td)["next"]
    finally:
        env.close()


def test_shipped_weights_give_nearness_in_the_right_order(real_step: TensorDict) -> None:
    source = load_small_depth()
    nearness = source(real_step)
    assert nearness.shape == (2, 64, 96) and nearness.dtype == torch.float32
    truth = GroundTruthDepth()(real_step)
    sky = truth == 0
    near = truth >= torch.quantile(truth.flatten(1), 0.9, dim=1).view(-1, 1, 1)
    assert sky.any() and near.any()
    for row in range(2):
        assert nearness[row][near[row]].mean() > nearness[row][sky[row]].mean()


def test_the_small_source_drives_the_reference_reward(real_step: TensorDict) -> None:
    td = real_step.clone().set("action", torch.full((2, 4, 2), 0.5))
    out = DepthCollisionReward(depth_source_for("small"))(td)
    assert out["reward_terms", "collision_risk"].shape == (2, 1)
    assert torch.isfinite(out["reward"]).all()


def test_frames_of_another_size_are_resized_both_ways() -> None:
    source = SmallDepth(DepthNet(TINY), image_size=(8, 12))
    for size in ((16, 24), (6, 10)):
        td = TensorDict({("pixels", "front"): torch.zeros(3, *size, 3, dtype=torch.uint8)}, [3])
        assert source(td).shape == (3, *size)
    with pytest.raises(ValueError, match="multiples of 4"):
        SmallDepth(DepthNet(TINY), image_size=(6, 12))


def test_depth_source_for_maps_the_setting() -> None:
    assert isinstance(depth_source_for("small", camera="left_forward"), SmallDepth)
    other = depth_source_for("some/depth-model", camera="right_forward")
    assert isinstance(other, MonocularDepth) and not other.is_loaded
    assert other.source == "some/depth-model" and other.camera == "right_forward"


def test_saved_weights_load_back_identically(tmp_path: Path) -> None:
    torch.manual_seed(0)
    net = DepthNet(TINY).eval()
    path = save_weights(tmp_path / "nested" / "tiny.pt", net, (8, 12), {"seed": 1})
    source = load_small_depth("right_forward", path)
    frames = torch.randint(0, 256, (2, 8, 12, 3), dtype=torch.uint8)
    assert source.camera == "right_forward" and source.image_size == (8, 12)
    with torch.inference_mode():
        assert torch.equal(source.net(frames), net(frames))


def _one_line_error(path: Path, cause: str) -> None:
    with pytest.raises(DepthModelError) as error:
        load_small_depth(path=path)
    message = str(error.value)
    assert "\n" not in message
    assert f"small depth network '{path}' cannot be loaded: " in message
    assert cause in message and "oasis-torchrl train depth" in message


def test_unloadable_weights_files_are_one_line_errors(tmp_path: Path) -> None:
    _one_line_error(tmp_path / "missing.pt", "FileNotFoundError")
    corrupt = tmp_path / "corrupt.pt"
    corrupt.write_bytes(b"not a weights file")
    _one_line_error(corrupt, "Error")
    foreign = tmp_path / "foreign.pt"
    torch.save({"weights": torch.zeros(2)}, foreign)
    _one_line_error(foreign, "not a weights file of 'oasis-torchrl depth net 1'")
    reshaped = tmp_path / "reshaped.pt"
    save_weights(reshaped, DepthNet(TINY), (8, 12))
    payload = torch.load(reshaped, weights_only=True)
    payload["config"]["channels"] = [4, 16]
    torch.save(payload, reshaped)
    _one_line_error(
        reshaped, "ValueError: the weights do not fit their config: decoder.0.0.weight is"
    )


def test_monocular_model_missing_offline_is_a_one_line_error(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from huggingface_hub import constants

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setattr(constants, "HF_HUB_OFFLINE", True)
    source = MonocularDepth("oasis-torchrl-tests/no-such-depth-model")
    td = TensorDict({("pixels", "front"): torch.zeros(1, 64, 96, 3, dtype=torch.uint8)}, [1])
    with pytest.raises(DepthModelError) as error:
        source(td)
    message = str(error.value)
    assert "\n" not in message and "://" not in message
    assert message.startswith(
        "depth model 'oasis-torchrl-tests/no-such-depth-model' cannot be loaded: it is not in "
        "the local cache, and downloads are off (HF_HUB_OFFLINE)"
    )
    assert message.endswith("env.reward.depth_model=small")


def test_monocular_model_missing_folder_is_named(tmp_path: Path) -> None:
    td = TensorDict({("pixels", "front"): torch.zeros(1, 64, 96, 3, dtype=torch.uint8)}, [1])
    with pytest.raises(DepthModelError, match="cannot be loaded: no such folder; offline"):
        MonocularDepth(tmp_path / "absent")(td)
