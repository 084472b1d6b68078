"""Noisy-execution autopilot demonstrations: noisy actions in the env, clean ones in the data."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from oasis_torchrl.config import load_config
from oasis_torchrl.train.demonstrations import ActionNoise, NoiseProcess, record_demonstrations

from .conftest import TINY_ENV


def _record(root: Path, noise: ActionNoise) -> LeRobotDataset:
    cfg = load_config("demo", [*TINY_ENV, "env.num_envs=2", "env.max_steps=3"])
    record_demonstrations(cfg.env, root, episodes=2, seed=5, noise=noise, progress=False)
    return LeRobotDataset("local/demos", root=root, video_backend="pyav")


def _executed_vs_stored(dataset: LeRobotDataset) -> torch.Tensor:
    """|executed - stored| of each chunk's last action: the next chunk's first row holds the
    executed one as its state (the env reports the previous applied action)."""
    columns = dataset.hf_dataset.with_format("torch")[:]
    state, action = columns["observation.state"], columns["action"]
    episode = columns["episode_index"]
    rows = torch.arange(3, len(action) - 1, 4)
    same_episode = episode[rows] == episode[rows + 1]
    return (state[rows + 1] - action[rows])[same_episode].abs()


def test_noise_moves_the_car_but_not_the_labels(tmp_path: Path) -> None:
    clean = _record(tmp_path / "clean", ActionNoise(0.0, 0.0, 0.0))
    noisy = _record(tmp_path / "noisy", ActionNoise(0.3, 0.3, 0.5))
    assert clean.num_episodes == noisy.num_episodes == 2
    assert _executed_vs_stored(clean).max() == 0
    assert _executed_vs_stored(noisy).max() > 0.01
    assert noisy.hf_dataset.with_format("torch")[:]["action"].abs().max() <= 1.0


def test_noise_process_is_seeded_and_resets_rows() -> None:
    first, second = (NoiseProcess(ActionNoise(), rows=4, seed=1) for _ in range(2))
    torch.testing.assert_close(first.step(), second.step())
    first.reset(torch.tensor([False, True, False, False]))
    assert first.value[1].abs().sum() == 0 and first.value[0].abs().sum() > 0
    with pytest.raises(ValueError, match="correlation in"):
        ActionNoise(correlation=1.0)
