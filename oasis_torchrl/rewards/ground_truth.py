"""A dense reward from the embedded server's ground truth (``("truth", field)``, ``[N, T]``).

Per row and step (a chunk of T frames)::

    reward = progress_scale * progress_gained
             - collision_penalty * collision
             - lane_penalty * lane_offset

- ``progress_gained``: metres along the road centreline gained during the chunk: the chunk's last
  ``progress`` minus the previous step's last ``progress``. The server counts progress from the
  last Prompt, so a reset row starts again from 0. Reversing gives a negative gain, so speed
  along the road is what is rewarded; there is no separate speed term.
- ``collision``: 1 on the first step whose chunk has a collided frame (hitting an obstacle or
  leaving the road), else 0; the penalty is paid once per episode.
- ``lane_offset``: mean ``|lane_offset|`` over the chunk: metres from the centre of the lane the
  car is in. Not from the road's centreline (``lateral_offset``): on a road of two or four lanes
  that is the line between two lanes, the one place a lane-keeping cost should not favour.

``terminated`` is True whenever a frame of the chunk collided. ``reset(mask)`` forgets the
progress baseline and the collided flag of the masked rows.
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase

from oasis_torchrl.rewards.base import RowState, batch_rows, get_entry, reward_output


class GroundTruthReward:
    """Progress along the road, a one-off collision penalty and a small lane-centering cost.

    >>> reward = GroundTruthReward(lane_penalty=0.0)
    >>> def step(progress, collided):
    ...     frames = {"progress": torch.tensor([progress]), "collided": torch.tensor([collided])}
    ...     frames["lane_offset"] = torch.zeros(1, 4)
    ...     return reward(TensorDict({("truth", k): v for k, v in frames.items()}, [1]))
    >>> step([0.5, 1.0, 1.5, 2.0], [0.0] * 4)["reward"].item()
    0.20000000298023224
    >>> out = step([2.5, 2.6, 2.6, 2.6], [0.0, 1.0, 1.0, 1.0])
    >>> round(out["reward"].item(), 3), out["terminated"].item()
    (-1.94, True)
    """

    terms = ("progress_gained", "collision", "lane_offset")

    def __init__(
        self,
        progress_scale: float = 0.1,
        collision_penalty: float = 2.0,
        lane_penalty: float = 0.01,
    ) -> None:
        self.progress_scale = progress_scale
        self.collision_penalty = collision_penalty
        self.lane_penalty = lane_penalty
        self._last_progress = RowState("last progress")
        self._collided = RowState("collided", dtype=torch.bool)

    def __call__(self, td: TensorDictBase) -> TensorDict:
        """Reward, termination and terms for the chunk whose ground truth is in ``td``."""
        batch = batch_rows(td)
        progress = _read_truth(td, "progress", batch)
        hit = _read_truth(td, "collided", batch).gt(0.5).any(-1)
        lane_offset = _read_truth(td, "lane_offset", batch).abs().mean(-1)

        last_progress = progress[:, -1]
        progress_gained = last_progress - self._last_progress.read(batch, progress.device)
        self._last_progress.write(last_progress)
        already_collided = self._collided.read(batch, progress.device)
        collision = (hit & ~already_collided).float()
        self._collided.write(hit | already_collided)

        reward = (
            self.progress_scale * progress_gained
            - self.collision_penalty * collision
            - self.lane_penalty * lane_offset
        )
        values = (progress_gained, collision, lane_offset)
        return reward_output(reward, dict(zip(self.terms, values, strict=True)), terminated=hit)

    def reset(self, mask: torch.Tensor | None = None) -> None:
        """Forget the progress baseline and collided flag of the rows where ``mask`` is True."""
        self._last_progress.reset(mask)
        self._collided.reset(mask)


def _read_truth(td: TensorDictBase, field: str, batch: int) -> torch.Tensor:
    value = get_entry(td, ("truth", field), "GroundTruthReward (needs the embedded server)")
    if value.ndim != 2 or value.shape[0] != batch or value.shape[1] == 0:
        raise ValueError(
            f"GroundTruthReward needs td[('truth', {field!r})] as [{batch}, T] (one value per "
            f"frame of the chunk), got {list(value.shape)}"
        )
    return value.float()
