"""Hand-built rollouts that follow :mod:`oasis_torchrl.envs.specs` exactly, with known content.

Every value is a function of (env row, step ``t``, frame ``k``), so a test can compute what each
logged entity must hold. Rows end episodes where ``ends`` says (terminated, with a collision on
frames 2-3 of that step); TorchRL then puts the next episode's reset observation at ``t + 1``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import torch
from tensordict import NonTensorStack, TensorDict

CAMERAS = ("left_forward", "front", "right_forward")
SIZE = (16, 24)
TERMS = ("progress_gained", "collision_risk")


def color(row: int, t: int, camera: int, reset: bool) -> tuple[int, int, int]:
    """The flat colour of a frame (JPEG keeps flat colours within a few levels)."""
    return (20 + 40 * row, 10 + 30 * t, 30 + 60 * camera + (100 if reset else 0))


def action(row: int, t: int, k: int) -> tuple[float, float]:
    return (0.1 * k - 0.2, 0.25 * (row - 1) + 0.01 * t)


def reward(row: int, t: int) -> float:
    return row + t / 10


def prompt(row: int, episode: int) -> str:
    return f"road {row}-{episode}"


def seed(row: int, episode: int) -> int:
    return 100 * row + episode


def _frames(rows: int, t: int, camera: int, reset: bool, all_frames: bool) -> torch.Tensor:
    h, w = SIZE
    values = torch.tensor([color(r, t, camera, reset) for r in range(rows)], dtype=torch.uint8)
    frames = values[:, None, None, :].expand(rows, h, w, 3)
    if all_frames:
        frames = frames[:, None].expand(rows, 4, h, w, 3)
    return frames.contiguous()


def observation(
    t: int,
    episodes: Sequence[int],
    *,
    reset: bool,
    collided: Sequence[bool] = (),
    all_frames: bool = False,
    depth: bool = False,
) -> TensorDict:
    """The ``[N]`` observation at step ``t`` (after the step, or a reset when ``reset``)."""
    n = len(episodes)
    k = torch.arange(4, dtype=torch.float32)
    hit = torch.tensor(collided or [False] * n)[:, None] & (k >= 2)
    obs = TensorDict(batch_size=[n])
    for index, camera in enumerate(CAMERAS):
        obs["pixels", camera] = _frames(n, t, index, reset, all_frames)
    obs["state"] = torch.zeros(n, 2)
    obs["prompt"] = NonTensorStack(*(prompt(r, e) for r, e in enumerate(episodes)))
    obs["episode_seed"] = torch.tensor([[seed(r, e)] for r, e in enumerate(episodes)])
    rows = torch.arange(n, dtype=torch.float32)[:, None]
    obs["truth", "x"] = (4 * t + k).expand(n, 4).clone()
    obs["truth", "y"] = (10 * rows).expand(n, 4).clone()
    obs["truth", "heading"] = torch.zeros(n, 4)
    obs["truth", "speed"] = (1 + rows).expand(n, 4).clone()
    obs["truth", "collided"] = hit.float()
    obs["truth", "off_road"] = torch.zeros(n, 4)
    obs["truth", "obstacle_distance"] = torch.full((n, 4), float("inf"))
    for term in TERMS:
        obs["reward_terms", term] = rows * 0 + (0.5 if term == "collision_risk" else 1.0)
    if depth:
        h, w = SIZE
        maps = torch.full((n, h, w), 7.5)
        maps[:, 0] = float("inf")  # sky
        obs["depth", "front"] = maps
    return obs


def rollout(
    rows: int, steps: int, ends: Mapping[int, Sequence[int]] = (), **obs_options: bool
) -> TensorDict:
    """A ``[rows, steps]`` rollout; ``ends[row]`` lists the steps that end that row's episode."""
    ends = dict(ends)
    episodes = [0] * rows
    root = observation(0, episodes, reset=True, **obs_options)
    out = []
    for t in range(steps):
        done = torch.tensor([t in ends.get(r, ()) for r in range(rows)])
        nxt = observation(t, episodes, reset=False, collided=done.tolist(), **obs_options)
        nxt["reward"] = torch.tensor([[reward(r, t)] for r in range(rows)])
        nxt["terminated"] = done[:, None].clone()
        nxt["truncated"] = torch.zeros(rows, 1, dtype=torch.bool)
        nxt["done"] = done[:, None].clone()
        step = root.clone()
        step["action"] = torch.tensor([[action(r, t, k) for k in range(4)] for r in range(rows)])
        step["done"] = torch.zeros(rows, 1, dtype=torch.bool)
        step["next"] = nxt
        out.append(step)
        episodes = [e + int(d) for e, d in zip(episodes, done.tolist(), strict=True)]
        root = nxt.exclude("reward", "terminated", "truncated", "done").clone()
        if done.any():
            fresh = observation(t + 1, episodes, reset=True, **obs_options)
            root[done] = fresh[done]
    return torch.stack(out, dim=1)
