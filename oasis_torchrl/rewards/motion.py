"""The frames-only reward: metres the car is seen to move, and the crashes the frames show.

What the hosted world model sends is frames, so this is the reward of every endpoint without
ground truth (``env.reward.kind=auto`` picks it there). Per row and step (a chunk of 4 frames),
from the front camera's 4 frames through :class:`~oasis_torchrl.models.motion.MotionNet`::

    reward = progress_scale * seen_progress
             - collision_penalty * crash
             - swing_weight * swing
             - ahead_weight * P(collision within the head's horizon)

- ``seen_progress``: the metres the network sees the car move during the chunk, linear, with
  ``deadband`` metres shaved off either way (a car standing still earns nothing, whatever its
  throttle: the reward never reads the throttle to pay).
- ``crash``: 1 on the first step the frames show a crash, which also ends the episode: the
  collided head says so, or the car is *stuck*: after it was seen moving (``arm_metres`` in a
  chunk), it has not been seen to move (less than ``stuck_metres`` a chunk) for
  ``stuck_chunks`` chunks in a row while the mean throttle was at least ``stuck_throttle``. A car
  that collided stands still, whatever the policy asks; a car pulling away from rest moves too
  little to be seen for a chunk or two, so standing still with the throttle released disarms
  the rule until the car is seen moving again.
- ``swing``: the mean squared change of the action (throttle and steering) from one action to
  the next, across the chunk and from the previous chunk's last action (the action-rate cost of
  legged-robot RL). A policy that swings the steering within a chunk turns the camera, and the
  network reads the turning as metres: PPO learned to do exactly that on frames alone, seen
  2.4 times as far as it drove. A driver that steers smoothly pays next to nothing.
- the collision-ahead cost reads the chunk's actions with the frames (off by default).

It needs all 4 frames of a chunk: the env hands them over whatever it observes
(:class:`~oasis_torchrl.envs.OasisEnv` asks the server for them when the reward reads them).
Where the endpoint sends ground truth, :class:`~oasis_torchrl.rewards.GroundTruthReward` is the
default and this reward is scored beside it in evaluations, so the two can be compared.
"""

from __future__ import annotations

import dataclasses

import torch
from tensordict import TensorDict, TensorDictBase

from oasis_torchrl.models.motion import MotionNet, collision_within
from oasis_torchrl.protocol import ACTION_DIM, CHUNK, FRONT
from oasis_torchrl.rewards.base import RowState, batch_rows, get_entry, reward_output
from oasis_torchrl.rewards.motion_net import SMALL_MOTION_MODEL, load_motion_net


@dataclasses.dataclass(frozen=True)
class MotionRewardConfig:
    """Constants of :class:`MotionReward`.

    >>> MotionRewardConfig().stuck_chunks
    2
    """

    progress_scale: float = 0.1
    collision_penalty: float = 2.0
    ahead_weight: float = 0.0
    swing_weight: float = 0.1
    deadband: float = 0.03
    stuck_metres: float = 0.06
    stuck_throttle: float = 0.5
    stuck_chunks: int = 2
    arm_metres: float = 0.5
    collided_threshold: float = 0.5

    def __post_init__(self) -> None:
        weights = (
            self.progress_scale,
            self.collision_penalty,
            self.ahead_weight,
            self.swing_weight,
        )
        if min(weights) < 0:
            raise ValueError(
                "progress_scale, collision_penalty, ahead_weight and swing_weight must be >= 0, "
                f"got {weights}"
            )
        if self.deadband < 0 or self.stuck_metres < 0 or self.stuck_chunks < 1:
            raise ValueError(
                f"deadband and stuck_metres must be >= 0 and stuck_chunks >= 1, got "
                f"{self.deadband}, {self.stuck_metres}, {self.stuck_chunks}"
            )
        if self.arm_metres < self.stuck_metres:
            raise ValueError(
                f"arm_metres ({self.arm_metres}) must be at least stuck_metres "
                f"({self.stuck_metres}): a car seen still cannot be seen moving"
            )
        if not 0.0 < self.collided_threshold < 1.0:
            raise ValueError(f"collided_threshold must be in (0, 1), got {self.collided_threshold}")


class MotionReward:
    """Progress seen in the front frames, and crashes seen there, ending the episode.

    Args:
        net: the motion network; default: the shipped one (``env.reward.motion_model=small``).
        config: the reward's constants.
        camera: the camera it reads (the network was trained on the front camera).

    Example:
        >>> reward = MotionReward()
        >>> frames = torch.randint(0, 256, (2, 4, 64, 96, 3), dtype=torch.uint8)
        >>> td = TensorDict({("pixels", "front"): frames, "action": torch.zeros(2, 4, 2)}, [2])
        >>> out = reward(td)
        >>> out["reward"].shape, sorted(out["reward_terms"].keys())
        (torch.Size([2, 1]), ['collision_ahead', 'crash', 'seen_progress', 'swing'])
    """

    terms = ("seen_progress", "crash", "swing", "collision_ahead")
    reads_chunk_frames = True
    """The env hands this reward all 4 frames of every chunk."""

    def __init__(
        self,
        net: MotionNet | None = None,
        config: MotionRewardConfig | None = None,
        camera: str = FRONT,
    ) -> None:
        self.net = (net if net is not None else load_motion_net(SMALL_MOTION_MODEL)).eval()
        self.config = config or MotionRewardConfig()
        self.camera = camera
        self._still = RowState("chunks seen still under throttle")
        self._armed = RowState("seen moving", dtype=torch.bool)
        self._crashed = RowState("crashed", dtype=torch.bool)
        self._last_action = RowState("last action of the previous chunk", shape=(ACTION_DIM,))
        self._started = RowState("chunks driven", dtype=torch.bool)

    def __call__(self, td: TensorDictBase) -> TensorDict:
        """Reward, termination and terms of the chunk in ``td``."""
        batch = batch_rows(td)
        frames = self._chunk_frames(td, batch)
        action = get_entry(td, "action", type(self).__name__).reshape(batch, CHUNK, -1).float()
        with torch.inference_mode():
            out = self.net(frames, action.to(frames.device))
        cfg = self.config
        moved = out.progress.float().cpu()
        seen = torch.sign(moved) * (moved.abs() - cfg.deadband).clamp_min(0.0)
        collided = torch.sigmoid(out.collided.float().cpu()) >= cfg.collided_threshold
        crashed_now = collided | self._stuck(moved, action[..., 0].mean(-1))
        before = self._crashed.read(batch, moved.device)
        crash = (crashed_now & ~before).float()
        self._crashed.write(before | crashed_now)
        ahead = collision_within(out.ahead.float().cpu())[:, -1]
        swing = self._swing(action)
        reward = (
            cfg.progress_scale * seen
            - cfg.collision_penalty * crash
            - cfg.swing_weight * swing
            - cfg.ahead_weight * ahead
        )
        terms = dict(zip(self.terms, (seen, crash, swing, ahead), strict=True))
        return reward_output(reward, terms, terminated=crashed_now)

    def _stuck(self, moved: torch.Tensor, throttle: torch.Tensor) -> torch.Tensor:
        """Per row, whether the car seen moving earlier has now been seen still under throttle
        for ``stuck_chunks`` chunks (and count the chunks)."""
        cfg = self.config
        batch = moved.shape[0]
        pushed = throttle >= cfg.stuck_throttle
        seen_still = moved.abs() < cfg.stuck_metres
        armed = self._armed.read(batch, moved.device) | (moved.abs() >= cfg.arm_metres)
        count = (self._still.read(batch, moved.device) + 1) * (seen_still & pushed & armed)
        self._armed.write(armed & ~(seen_still & ~pushed))
        self._still.write(count)
        return count >= cfg.stuck_chunks

    def _swing(self, action: torch.Tensor) -> torch.Tensor:
        """Per row, the mean squared change of ``action`` ``[N, CHUNK, A]`` from one action to
        the next, the previous chunk's last action first where the episode has one."""
        batch = action.shape[0]
        action = action.cpu()
        steps = action.diff(dim=1).square().sum(-1)
        started = self._started.read(batch, action.device)
        last = self._last_action.read(batch, action.device)
        across = (action[:, 0] - last).square().sum(-1) * started
        self._last_action.write(action[:, -1])
        self._started.write(torch.ones(batch, dtype=torch.bool))
        return (steps.sum(-1) + across) / (steps.shape[1] + started.float())

    def reset(self, mask: torch.Tensor | None = None) -> None:
        """Forget the still count, the armed and crashed flags and the last action of the rows
        where ``mask`` is True."""
        self._still.reset(mask)
        self._armed.reset(mask)
        self._crashed.reset(mask)
        self._started.reset(mask)
        self._last_action.reset(mask)

    def _chunk_frames(self, td: TensorDictBase, batch: int) -> torch.Tensor:
        frames = get_entry(td, ("pixels", self.camera), type(self).__name__)
        if frames.ndim != 5 or frames.shape[:2] != (batch, CHUNK) or frames.dtype != torch.uint8:
            raise ValueError(
                f"MotionReward needs all {CHUNK} frames of each chunk, td[('pixels', "
                f"{self.camera!r})] as uint8 [{batch}, {CHUNK}, H, W, 3], got "
                f"{frames.dtype} {list(frames.shape)}: build the env with this reward (it asks "
                "the server for every frame) or with all_frames=True"
            )
        return frames
