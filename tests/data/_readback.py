"""Reading datasets back with LeRobot and comparing them with what the fake env produced."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from oasis_torchrl.data.loading import default_repo_id

from ._fake_env import action, reward


def open_dataset(root: Path, **kwargs: object) -> LeRobotDataset:
    """The dataset at ``root`` as LeRobot reads it (pyav: torchcodec cannot load here)."""
    return LeRobotDataset(default_repo_id(root), root=root, video_backend="pyav", **kwargs)


@dataclass(frozen=True)
class Episode:
    """One episode as stored: task, dataset index range and its numeric columns."""

    task: str
    start: int
    stop: int
    columns: dict[str, np.ndarray]

    @property
    def env_row(self) -> int:
        return int(self.task.split()[1].split("-")[0])

    @property
    def number(self) -> int:
        return int(self.task.split("-")[1])


def episodes(dataset: LeRobotDataset) -> list[Episode]:
    """Every stored episode, in order."""
    meta = dataset.meta.episodes
    data = dataset.hf_dataset
    keys = [
        k for k in ("observation.state", "action", "next.reward", "next.done") if k in data.features
    ]
    columns = {key: torch.stack(list(data[key])).numpy() for key in keys}
    out = []
    for task, start, stop in zip(
        meta["tasks"], meta["dataset_from_index"], meta["dataset_to_index"], strict=True
    ):
        out.append(Episode(task[0], start, stop, {k: v[start:stop] for k, v in columns.items()}))
    return out


def expected_frame_rows(row: int, number: int, steps: int, finished: bool) -> dict[str, np.ndarray]:
    """Numeric columns of a frame-row episode of ``steps`` steps (see the mapping table)."""
    acts = np.stack([action(row, number, t, k) for t in range(steps) for k in range(4)])
    state = np.concatenate([np.zeros((1, 2), np.float32), acts[:-1]])
    rewards = np.zeros(4 * steps, np.float32)
    rewards[3::4] = [reward(row, number, t) for t in range(steps)]
    done = np.zeros(4 * steps, bool)
    done[-1] = finished
    return {"observation.state": state, "action": acts, "next.reward": rewards, "next.done": done}


def psnr(decoded: torch.Tensor, original: np.ndarray) -> float:
    """PSNR (dB) of a LeRobot image (float ``[3, H, W]`` in [0, 1]) against a uint8 HWC frame."""
    image = (decoded.permute(1, 2, 0).numpy() * 255.0).round()
    mse = float(np.mean((image - original.astype(np.float64)) ** 2))
    return 10 * np.log10(255.0**2 / max(mse, 1e-10))
