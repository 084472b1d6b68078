"""The motion network's training rows: chunks of front frames with their labels, and the labels
of driven episodes from the embedded world's ground truth (progress, collisions)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import torch

UNLABELLED = -(10**6)
"""``time_to`` of a chunk the hazard head learns nothing from: at or after the episode's
collision, or the episode's last chunk without one."""


@dataclass
class MotionChunks:
    """Chunks of the front camera with their ground-truth labels, one row per chunk.

    ``frames`` uint8 ``[M, 4, H, W, 3]``, ``actions`` ``[M, 4, 2]``, ``progress`` metres gained
    ``[M]``, ``collided`` ``[M]``, ``time_to`` chunks to the next collision ``[M]`` (see
    :func:`~oasis_torchrl.models.motion.hazard_loss`; :data:`UNLABELLED` once collided),
    ``rounds`` ``[M]``.
    """

    frames: torch.Tensor
    actions: torch.Tensor
    progress: torch.Tensor
    collided: torch.Tensor
    time_to: torch.Tensor
    rounds: torch.Tensor

    def __len__(self) -> int:
        return self.frames.shape[0]

    def select(self, rows: torch.Tensor) -> MotionChunks:
        """The rows ``rows`` names (indices, or a bool mask)."""
        return MotionChunks(*(value[rows] for value in dataclasses.astuple(self)))

    def save(self, path: str | Path) -> None:
        """Write the rows to ``path`` (a torch file)."""
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        torch.save(dataclasses.asdict(self), path)

    @classmethod
    def load(cls, path: str | Path) -> MotionChunks:
        """The rows :meth:`save` wrote to ``path``."""
        return cls(**torch.load(path, weights_only=True))

    @classmethod
    def concat(cls, parts: list[MotionChunks]) -> MotionChunks:
        """The rows of ``parts``, in order."""
        columns = zip(*(dataclasses.astuple(part) for part in parts), strict=True)
        return cls(*(torch.cat(column) for column in columns))


def chunk_labels(
    progress: torch.Tensor, collided: torch.Tensor, horizon: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per chunk of episodes ``[E, T]``: progress gained, collided and chunks to the collision.

    Args:
        progress: ground truth ``progress`` ``[E, T, 4]`` (metres since the Prompt).
        collided: ground truth ``collided`` ``[E, T, 4]``.
        horizon: the hazard head's horizon in chunks.

    Example:
        >>> progress = torch.tensor([[[1.0] * 4, [2.0] * 4, [2.5] * 4, [2.5] * 4]])
        >>> hit = torch.tensor([[[0.0] * 4, [0.0] * 4, [0.0, 1, 1, 1], [1.0] * 4]])
        >>> gained, collided, time_to = chunk_labels(progress, hit, horizon=5)
        >>> gained.tolist(), collided.tolist(), time_to.tolist()[0][:2]
        ([[1.0, 1.0, 0.5, 0.0]], [[False, False, True, True]], [2, 1])
    """
    last = progress[..., -1]
    gained = last - torch.cat([torch.zeros_like(last[:, :1]), last[:, :-1]], dim=1)
    hit = collided.gt(0.5).any(-1)
    chunks = hit.shape[1]
    steps = torch.arange(chunks).unsqueeze(0)
    first = torch.where(hit.any(1), hit.float().argmax(1), torch.tensor(chunks)).unsqueeze(1)
    until = first - steps
    remaining = chunks - 1 - steps
    time_to = torch.where(until <= horizon, until, torch.zeros_like(until))
    censored = (first == chunks) & (remaining < horizon)
    time_to = torch.where(censored, -remaining, time_to)
    time_to = torch.where(steps >= first, torch.full_like(until, UNLABELLED), time_to)
    time_to = torch.where(censored & (remaining == 0), torch.full_like(until, UNLABELLED), time_to)
    return gained, hit, time_to
