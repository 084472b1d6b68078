"""Reward shaping for PPO on the embedded simulator: keep clear of what is ahead.

The ground-truth reward pays progress and punishes a collision once, when it happens. From
pixels, the policy first learns to drive straight at full speed; learning to change lanes
needs the long, well-timed steering that random exploration rarely produces before the
collision ends the episode. :class:`ClearanceShaping` adds a dense cost while an obstacle
sits in the corridor ahead of the car (ground truth ``obstacle_distance``, per frame), which
starts to pay off as soon as the car turns out of that corridor.
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase

from oasis_torchrl.rewards.base import RewardModule, get_entry


class ClearanceShaping:
    """``base(td)`` minus ``weight * mean(clip(1 - obstacle_distance / horizon, 0, 1))``.

    Args:
        base: the reward module shaped (its terms, termination and state are kept).
        weight: cost per step with an obstacle right at the bumper.
        horizon: metres ahead from which an obstacle starts to cost.

    Example:
        >>> from oasis_torchrl.rewards import GroundTruthReward
        >>> shaped = ClearanceShaping(GroundTruthReward(lane_penalty=0.0), weight=0.4, horizon=20)
        >>> truth = {"progress": torch.zeros(1, 4), "collided": torch.zeros(1, 4),
        ...          "lane_offset": torch.zeros(1, 4),
        ...          "obstacle_distance": torch.full((1, 4), 10.0)}
        >>> out = shaped(TensorDict({("truth", k): v for k, v in truth.items()}, [1]))
        >>> round(out["reward"].item(), 3), out["reward_terms", "clearance"].item()
        (-0.2, 0.5)
    """

    def __init__(self, base: RewardModule, weight: float = 0.2, horizon: float = 25.0) -> None:
        if weight < 0 or horizon <= 0:
            raise ValueError(f"weight must be >= 0 and horizon > 0, got {weight}, {horizon}")
        self.base = base
        self.weight = weight
        self.horizon = horizon
        self.terms = (*getattr(base, "terms", ()), "clearance")

    def __call__(self, td: TensorDictBase) -> TensorDict:
        """The base reward with the clearance cost, and the cost as a term."""
        out = self.base(td)
        distance = get_entry(td, ("truth", "obstacle_distance"), "ClearanceShaping").float()
        closeness = (1.0 - distance / self.horizon).clamp(0.0, 1.0).mean(-1, keepdim=True)
        out["reward"] = out["reward"] - self.weight * closeness
        out["reward_terms", "clearance"] = closeness
        return out

    def reset(self, mask: torch.Tensor | None = None) -> None:
        """Reset the base module's per-row state."""
        self.base.reset(mask)
