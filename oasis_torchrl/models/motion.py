"""The frames-only reward's network: a chunk's progress and the crashes it sees, from the front
camera alone.

:class:`MotionNet` reads one chunk (the 4 front frames an Infer returns) and answers three
questions, each a head on one small convolutional trunk:

- **progress**: metres the car moved along its way during the chunk (regression). It reads the
  frames alone, never the action, so a policy cannot earn it with the throttle.
- **collided**: whether the chunk shows a collision (the car hit something or left the road and
  stands still). A car stopped of its own accord shows still frames too; the head learns the
  difference from the obstacle at the bumper or the verge under the car.
- **collision ahead**: given the chunk's actions, the chance of a collision within each of the
  next ``horizon`` chunks, as a discrete-time hazard (DIAMOND's end head and DreamerV3's continue
  head predict the end of an episode the same way, from real transitions):
  ``P(within k) = 1 - prod_{j <= k} (1 - sigmoid(hazard_j))``, monotone in ``k`` by construction.

The input is grey: the frames, normalised per chunk (so night and fog look like day to the
trunk), and their three differences, which carry the motion. Frames of another size are resized
to ``image_size`` first.

Example:
    >>> net = MotionNet(MotionNetConfig(channels=(8, 8, 8, 8)))
    >>> out = net(torch.zeros(2, 4, 64, 96, 3, dtype=torch.uint8), torch.zeros(2, 4, 2))
    >>> out.progress.shape, out.collided.shape, out.ahead.shape
    (torch.Size([2]), torch.Size([2]), torch.Size([2, 5]))
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import torch
from torch import nn
from torch.nn import functional as F

from oasis_torchrl.protocol import ACTION_DIM, CHUNK

GREY = (0.299, 0.587, 0.114)
"""ITU-R BT.601 luma weights of R, G, B."""


@dataclasses.dataclass(frozen=True)
class MotionNetConfig:
    """Shape of :class:`MotionNet`.

    >>> MotionNetConfig().horizon
    5
    """

    image_size: tuple[int, int] = (64, 96)
    channels: tuple[int, ...] = (16, 32, 48, 64)
    hidden: int = 96
    horizon: int = 5

    def __post_init__(self) -> None:
        if len(self.image_size) != 2 or min(self.image_size) < 16:
            raise ValueError(f"image_size must be [height, width] >= 16, got {self.image_size}")
        if not self.channels or min(self.channels) < 1 or self.hidden < 1 or self.horizon < 1:
            raise ValueError(
                f"channels, hidden and horizon must be positive, got {self.channels}, "
                f"{self.hidden}, {self.horizon}"
            )


class MotionOutput(NamedTuple):
    """What :class:`MotionNet` says of each chunk ``[N]``: progress (m), the collided logit and
    the hazard logits of the next ``horizon`` chunks ``[N, horizon]``."""

    progress: torch.Tensor
    collided: torch.Tensor
    ahead: torch.Tensor


def chunk_inputs(frames: torch.Tensor, image_size: tuple[int, int]) -> torch.Tensor:
    """The trunk's input ``[N, 2 * CHUNK - 1, h, w]`` from uint8 frames ``[N, CHUNK, H, W, 3]``:
    the grey frames normalised per chunk, then their successive differences.

    Example:
        >>> chunk_inputs(torch.zeros(3, 4, 32, 48, 3, dtype=torch.uint8), (16, 24)).shape
        torch.Size([3, 7, 16, 24])
    """
    if frames.ndim != 5 or frames.shape[1] != CHUNK or frames.shape[-1] != 3:
        raise ValueError(f"frames must be [N, {CHUNK}, H, W, 3], got {list(frames.shape)}")
    weights = torch.tensor(GREY, device=frames.device)
    grey = (frames.float() @ weights) / 255.0
    if tuple(grey.shape[-2:]) != tuple(image_size):
        grey = F.interpolate(grey, size=tuple(image_size), mode="area")
    mean = grey.mean(dim=(1, 2, 3), keepdim=True)
    std = grey.std(dim=(1, 2, 3), keepdim=True).clamp_min(0.02)
    grey = (grey - mean) / std
    return torch.cat([grey, grey[:, 1:] - grey[:, :-1]], dim=1)


class MotionNet(nn.Module):
    """Progress, collision and collision-ahead heads on the front frames of a chunk."""

    def __init__(self, cfg: MotionNetConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg or MotionNetConfig()
        layers: list[nn.Module] = []
        width = 2 * CHUNK - 1
        for index, channels in enumerate(self.cfg.channels):
            kernel = 5 if index == 0 else 3
            layers += [
                nn.Conv2d(width, channels, kernel, stride=2, padding=kernel // 2),
                nn.BatchNorm2d(channels),
                nn.ReLU(inplace=True),
            ]
            width = channels
        self.trunk = nn.Sequential(*layers)
        height, wide = self.cfg.image_size
        for _ in self.cfg.channels:
            height, wide = (height + 1) // 2, (wide + 1) // 2
        self.features = nn.Sequential(
            nn.Flatten(), nn.Linear(width * height * wide, self.cfg.hidden), nn.ReLU(inplace=True)
        )
        self.progress_head = nn.Linear(self.cfg.hidden, 1)
        self.collided_head = nn.Linear(self.cfg.hidden, 1)
        self.ahead_head = nn.Sequential(
            nn.Linear(self.cfg.hidden + CHUNK * ACTION_DIM, self.cfg.hidden),
            nn.ReLU(inplace=True),
            nn.Linear(self.cfg.hidden, self.cfg.horizon),
        )

    def forward(self, frames: torch.Tensor, actions: torch.Tensor) -> MotionOutput:
        """The heads of ``frames`` uint8 ``[N, 4, H, W, 3]`` with the chunk's ``actions``."""
        features = self.features(self.trunk(chunk_inputs(frames, self.cfg.image_size)))
        acted = torch.cat([features, actions.reshape(len(actions), -1).float()], dim=1)
        return MotionOutput(
            self.progress_head(features).squeeze(-1),
            self.collided_head(features).squeeze(-1),
            self.ahead_head(acted),
        )


def collision_within(hazard_logits: torch.Tensor) -> torch.Tensor:
    """``P(a collision within k chunks)`` ``[N, horizon]`` from hazard logits ``[N, horizon]``.

    Example:
        >>> collision_within(torch.zeros(1, 3)).tolist()
        [[0.5, 0.75, 0.875]]
    """
    survive = torch.cumsum(F.logsigmoid(-hazard_logits), dim=-1)
    return 1.0 - survive.exp()


def hazard_loss(hazard_logits: torch.Tensor, time_to: torch.Tensor) -> torch.Tensor:
    """Negative log-likelihood of the chunks to the next collision under the hazard model.

    ``time_to`` ``[N]``: chunks until the collision (1: the next chunk), 0 where none comes
    within the horizon and the episode runs at least that long, -k where the episode ends after
    k chunks without one (censored), and masked out by the caller where the car has already
    collided.

    Example:
        >>> loss = hazard_loss(torch.zeros(3, 5), torch.tensor([1, 0, -2]))
        >>> round(loss.item(), 3)
        1.848
    """
    horizon = hazard_logits.shape[-1]
    steps = torch.arange(1, horizon + 1, device=hazard_logits.device)
    event = time_to > 0
    seen = torch.where(event, time_to, torch.where(time_to < 0, -time_to, horizon))
    survived = steps.unsqueeze(0) < seen.unsqueeze(1)
    survived = survived | (~event.unsqueeze(1) & (steps.unsqueeze(0) == seen.unsqueeze(1)))
    hit = event.unsqueeze(1) & (steps.unsqueeze(0) == seen.unsqueeze(1))
    log_survive = F.logsigmoid(-hazard_logits)
    log_hit = F.logsigmoid(hazard_logits)
    total = (log_survive * survived).sum(1) + (log_hit * hit).sum(1)
    return -total.mean()
