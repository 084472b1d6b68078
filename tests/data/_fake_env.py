"""Hand-built env steps that follow :mod:`oasis_torchrl.envs.specs` exactly, with known content.

Every frame, action and reward is a function of (env row, episode, index), so a test can
compute what each dataset row must hold.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch
from tensordict import NonTensorStack, TensorDict

CAMERAS = ("left_forward", "front", "right_forward")
SIZE = (48, 64)


def frame(
    row: int, episode: int, index: int, camera: int, size: tuple[int, int] = SIZE
) -> np.ndarray:
    """Frame ``index`` (0-3: the reset chunk) of an episode: smooth shading and a moving block."""
    height, width = size
    yy, xx = np.mgrid[0:height, 0:width]
    image = np.empty((height, width, 3), np.uint8)
    image[..., 0] = 40 + (xx * 150) // width
    image[..., 1] = 40 + (yy * 150) // height + 20 * camera
    image[..., 2] = 60 + 30 * ((row + 2 * episode) % 5)
    left = (index * 7) % (width - 12)
    image[8 : 8 + 16, left : left + 12] = (230, 230, 40)
    return image


def action(row: int, episode: int, step: int, k: int) -> np.ndarray:
    """Action ``k`` of the chunk of ``step``, inside [-1, 1] and distinct everywhere."""
    throttle = ((step * 4 + k) % 9) / 9.0
    steering = ((row * 3 + episode * 5 + k) % 11) / 11.0 - 0.5
    return np.array([throttle, steering], np.float32)


def reward(row: int, episode: int, step: int) -> float:
    return float(step) + 0.25 * row + 0.01 * episode


def prompt(row: int, episode: int) -> str:
    return f"road {row}-{episode}"


@dataclass
class FakeEnvRun:
    """N env rows running episodes of given lengths (steps), producing ``[N, T]`` batches.

    After its listed episodes, a row runs one episode that never ends.
    """

    lengths: Sequence[Sequence[int]]
    all_frames: bool = True
    size: tuple[int, int] = SIZE
    episode: list[int] = field(default_factory=list)
    step: list[int] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.episode = [0] * len(self.lengths)
        self.step = [0] * len(self.lengths)

    def _pixels(self, row: int, episode: int, first: int, camera: int) -> torch.Tensor:
        frames = [frame(row, episode, first + k, camera, self.size) for k in range(4)]
        stacked = torch.from_numpy(np.stack(frames))
        return stacked if self.all_frames else stacked[-1]

    def _obs(self, row: int, episode: int, step: int) -> dict:
        state = action(row, episode, step - 1, 3) if step else np.zeros(2, np.float32)
        return {
            "pixels": {c: self._pixels(row, episode, 4 * step, i) for i, c in enumerate(CAMERAS)},
            "state": torch.from_numpy(state),
            "episode_seed": torch.tensor([1000 * row + episode]),
            "prompt": prompt(row, episode),
        }

    def batch(self, horizon: int) -> TensorDict:
        steps = []
        for _ in range(horizon):
            rows = []
            for row in range(len(self.lengths)):
                episode, step = self.episode[row], self.step[row]
                planned = self.lengths[row]
                done = episode < len(planned) and step + 1 == planned[episode]
                root = self._obs(row, episode, step)
                after = self._obs(row, episode, step + 1)
                chunk = np.stack([action(row, episode, step, k) for k in range(4)])
                flags = {key: torch.tensor([done]) for key in ("done", "terminated")}
                flags["truncated"] = torch.tensor([False])
                rows.append((root, chunk, after, flags, reward(row, episode, step)))
                if done:
                    self.episode[row], self.step[row] = episode + 1, 0
                else:
                    self.step[row] = step + 1
            steps.append(_stack_rows(rows))
        return torch.stack(steps, dim=1)


def _row_td(obs: dict) -> TensorDict:
    return TensorDict({k: v for k, v in obs.items() if k != "prompt"}, batch_size=[])


def _stack_rows(rows: list) -> TensorDict:
    n = len(rows)
    root = torch.stack([_row_td(r[0]) for r in rows])
    after = torch.stack([_row_td(r[2]) for r in rows])
    root["prompt"] = NonTensorStack(*(r[0]["prompt"] for r in rows))
    after["prompt"] = NonTensorStack(*(r[2]["prompt"] for r in rows))
    root["action"] = torch.from_numpy(np.stack([r[1] for r in rows]))
    for key in ("done", "terminated", "truncated"):
        root[key] = torch.zeros(n, 1, dtype=torch.bool)
        after[key] = torch.stack([r[3][key] for r in rows])
    after["reward"] = torch.tensor([[r[4]] for r in rows], dtype=torch.float32)
    root["next"] = after
    return root
