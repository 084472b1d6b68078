"""The autopilot reacting late to obstacles: what demonstrations need to cover a clone's mistake.

The autopilot changes lanes 30-45 m before an obstacle, where the obstacle is a couple of pixels
in the policy's 96x64 frames. Its demonstrations therefore hold almost no frame with an obstacle
close ahead in the car's own lane, and a clone that misses the early cue drives into states it
has never seen, and keeps its lane into the obstacle as a constant full-throttle drive does
(docs/experiments/2026-11-26-mixture-clone-drives-like-a-constant.md). Executing this driver
while the autopilot labels
every frame (DART-style noise injection, shaped like that mistake) records exactly those states:
the car keeps its lane into a blocked stretch, and each frame says what the autopilot would do
there. It is the :func:`~oasis_torchrl.train.demonstrations.record_demonstrations` ``learner`` of
``record.late_reaction``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from tensordict import TensorDictBase

from oasis_torchrl.config.demonstrations import reaction_range
from oasis_torchrl.drivers.autopilot import Autopilot

TRUTH = "truth"
STEER_GAIN = 10.8
"""Linearised pure pursuit: ``steering = STEER_GAIN * (lane_offset / L**2 + heading_error / L)``
for a look-ahead ``L``; ``2 * wheelbase / max_steer`` of the embedded car (2.7 m, 0.5 rad)."""
PURSUIT_TIME = 0.4
MIN_PURSUIT = 6.0
"""The look-ahead ``L``: ``PURSUIT_TIME`` seconds of driving plus 5 m, at least ``MIN_PURSUIT``
metres (the autopilot's own lane keeping)."""


class LateReactionAutopilot(Autopilot):
    """Drives the autopilot's chunk, but keeps its lane until the obstacle in it is nearer than
    a reaction distance drawn for each approach.

    While an obstacle in the car's lane (ground truth ``lane_obstacle_distance``) is farther
    than the row's reaction distance, the steering follows the lane the car is in (pure pursuit
    on ``lane_offset`` and ``heading_error``) and the throttle is the autopilot's; nearer, the
    chunk is the autopilot's. A row draws a new distance, uniform in ``reaction``, whenever its
    lane has no obstacle within ``reaction[1]``, so every approach reacts at its own distance.

    Args:
        reaction: ``(near, far)`` metres of the reaction distance.
        seed: seeds the draws.

    Example:
        >>> from tensordict import TensorDict
        >>> def row(distance, offset):
        ...     truth = {"lane_obstacle_distance": distance, "lane_offset": offset,
        ...              "heading_error": 0.0, "speed": 10.0}
        ...     return {k: torch.full((1, 4), v) for k, v in truth.items()}
        >>> late = LateReactionAutopilot(reaction=(10.0, 20.0))
        >>> td = TensorDict({"expert_action": torch.tensor([[[0.5, -0.3]] * 4]),
        ...                  "truth": row(30.0, 0.5)}, batch_size=[1])
        >>> late(td)["action"][0, 0]  # the car keeps its lane: steers right, back to its centre
        tensor([0.5000, 0.0667])
        >>> td["truth"] = row(5.0, 0.5)
        >>> late(td)["action"][0, 0]  # near: the autopilot's chunk
        tensor([ 0.5000, -0.3000])
    """

    def __init__(self, reaction: Sequence[float] = (8.0, 40.0), seed: int = 0) -> None:
        super().__init__()
        self.reaction = reaction_range(reaction)
        self._generator = torch.Generator().manual_seed(seed)
        self._distances = torch.zeros(0)

    def chunks(self, td: TensorDictBase) -> torch.Tensor:
        """The autopilot's chunks, with lane-keeping steering in the rows still to react."""
        chunk = super().chunks(td).clone()
        truth = td.get(TRUTH, None)
        if truth is None:
            raise KeyError(
                f"the late-reacting autopilot reads the ground truth ({TRUTH!r}), which only "
                "the embedded server sends"
            )
        last = {key: truth.get(key)[:, -1].nan_to_num(0.0) for key in _TRUTH_READ}
        obstacle = truth.get("lane_obstacle_distance")[:, -1].nan_to_num(math.inf)
        waiting = obstacle > self._reaction_distances(obstacle)
        steering = lane_keeping(last["lane_offset"], last["heading_error"], last["speed"])
        chunk[..., 1] = torch.where(waiting[:, None], steering[:, None], chunk[..., 1])
        return chunk

    def _reaction_distances(self, obstacle: torch.Tensor) -> torch.Tensor:
        """Each row's reaction distance, drawn anew for the rows with no obstacle in reach."""
        near, far = self.reaction
        if self._distances.shape != obstacle.shape:
            self._distances = torch.full(obstacle.shape, far)
        fresh = obstacle > far
        draws = near + (far - near) * torch.rand(obstacle.shape, generator=self._generator)
        self._distances = torch.where(fresh, draws, self._distances)
        return self._distances


_TRUTH_READ = ("lane_offset", "heading_error", "speed")


def lane_keeping(offset: torch.Tensor, heading: torch.Tensor, speed: torch.Tensor) -> torch.Tensor:
    """Steering in ``[-1, 1]`` back to the centre of the car's lane (linearised pure pursuit):
    ``offset`` from the lane centre (m, + left), ``heading`` error against the road (rad, +
    left), ``speed`` (m/s).

    Example:
        >>> offset, heading = torch.tensor([0.0, 1.0]), torch.tensor([0.0, 0.0])
        >>> lane_keeping(offset, heading, speed=torch.tensor([10.0, 10.0]))
        tensor([0.0000, 0.1333])
    """
    look_ahead = (PURSUIT_TIME * speed.abs() + 5.0).clamp_min(MIN_PURSUIT)
    steering = STEER_GAIN * (offset / look_ahead.square() + heading / look_ahead)
    return steering.clamp(-1.0, 1.0)
