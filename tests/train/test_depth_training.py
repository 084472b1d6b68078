"""``train depth``: frames and depth from the embedded server, a tiny network that learns from
them, the command end to end, and its settings' checks."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from oasis_torchrl.cli import main
from oasis_torchrl.config.reward_networks import DepthTrainConfig
from oasis_torchrl.models.depth import DepthNet, DepthNetConfig, scale_shift_invariant_loss
from oasis_torchrl.rewards.depth_net import load_small_depth
from oasis_torchrl.train.depth import (
    DepthFrames,
    collect_depth_frames,
    evaluate_loss,
    fit,
)
from oasis_torchrl.train.driven_rounds import split_rounds

SMOKE = {"num_envs": 2, "steps": 4, "render_scale": 1, "progress": False}


@pytest.fixture(scope="module")
def real_frames() -> DepthFrames:
    """Two rounds (two drivers) of two short episodes each."""
    settings = DepthTrainConfig(
        episodes=4,
        drivers=["constant:throttle=0.8", "scripted:throttle=0.5,steering=sine:0.5:16"],
        **SMOKE,
    )
    return collect_depth_frames(settings)


def test_frames_and_nearness_come_from_the_same_steps(real_frames: DepthFrames) -> None:
    assert real_frames.frames.shape == (16, 64, 96, 3)
    assert real_frames.frames.dtype == torch.uint8
    assert real_frames.nearness.shape == (16, 64, 96)
    assert real_frames.rounds.tolist() == [0] * 8 + [1] * 8
    nearness = real_frames.nearness
    assert (nearness == 0).any() and torch.isfinite(nearness).all()  # sky, and nothing else inf
    # The road just ahead is nearer than the top of the image.
    assert (nearness[:, -8:].mean((1, 2)) > nearness[:, :8].mean((1, 2))).all()


def test_a_tiny_network_learns_from_real_frames(real_frames: DepthFrames) -> None:
    torch.manual_seed(0)
    net = DepthNet(DepthNetConfig(channels=(8, 16)))
    before = evaluate_loss(net, real_frames)
    losses = fit(net, real_frames, epochs=12, batch_size=8, lr=1e-2, seed=0)
    after = evaluate_loss(net, real_frames)
    assert losses[-1] < losses[0]
    assert after < 0.8 * before


def test_the_last_rounds_are_held_out(real_frames: DepthFrames) -> None:
    train, held = split_rounds(real_frames, 0.5)
    assert held is not None and train.rounds.unique().tolist() == [0]
    assert held.rounds.unique().tolist() == [1]
    assert split_rounds(real_frames, 0.0) == (real_frames, None)


def test_train_depth_writes_a_loadable_file_and_reuses_its_frames(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    frames_file = tmp_path / "frames.pt"
    settings = [
        "train",
        "depth",
        "episodes=4",
        "num_envs=2",
        "steps=3",
        "epochs=1",
        "batch_size=4",
        "render_scale=1",
        "channels=[4,8]",
        "drivers=[autopilot]",
        "progress=false",
        f"frames_file={frames_file}",
    ]
    output = tmp_path / "out" / "depth.pt"
    assert main([*settings, f"output={output}"]) == 0
    source = load_small_depth(path=output)
    assert source.image_size == (64, 96) and source.net.config.channels == (4, 8)
    meta = torch.load(output, weights_only=True)["meta"]
    assert meta["frames"] == 12 and meta["validation_loss"] is not None
    assert frames_file.exists() and "reading the rows" not in caplog.text
    again = tmp_path / "again.pt"
    with caplog.at_level("INFO"):
        assert main([*settings, f"output={again}", "epochs=2"]) == 0
    assert f"reading the rows of {frames_file}" in caplog.text
    assert torch.load(again, weights_only=True)["meta"]["frames"] == 12


@pytest.mark.parametrize(
    ("override", "named"),
    [("episodes=5", "episodes"), ("epochs=0", "epochs"), ("validation=2", "validation")],
)
def test_bad_settings_exit_2_naming_them(
    override: str, named: str, caplog: pytest.LogCaptureFixture
) -> None:
    assert main(["train", "depth", override]) == 2
    assert named in caplog.text


def test_near_weight_makes_errors_on_near_pixels_cost_more() -> None:
    target = torch.linspace(0, 1, 16).view(1, 4, 4)  # the last pixel is the nearest
    near_wrong, far_wrong = target.clone(), target.clone()
    near_wrong[0, 3, 3] -= 0.5
    far_wrong[0, 0, 1] += 0.5
    plain = [scale_shift_invariant_loss(p, target) for p in (near_wrong, far_wrong)]
    weighted = [scale_shift_invariant_loss(p, target, 4.0) for p in (near_wrong, far_wrong)]
    assert weighted[0] / weighted[1] > 1.5 * plain[0] / plain[1]
