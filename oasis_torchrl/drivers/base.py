"""The driver interface: a TorchRL-policy-like callable ``td -> td`` that sets ``"action"``."""

from __future__ import annotations

from abc import ABC, abstractmethod

import torch
from tensordict import TensorDictBase
from torchrl.data import Composite

from oasis_torchrl.models.config import POLICY_FRAMES
from oasis_torchrl.protocol import CHUNK


class Driver(ABC):
    """Base of the drivers: computes ``[N, 4, 2]`` chunks and writes them to ``"action"``.

    Args:
        chunk_actions: write ``[N, 4, 2]`` chunks; if false, ``[N, 2]`` (the chunk's first).

    Example:
        >>> from tensordict import TensorDict
        >>> class Stop(Driver):
        ...     def chunks(self, td):
        ...         return torch.zeros(td.batch_size[0], 4, 2)
        >>> Stop(chunk_actions=False)(TensorDict(batch_size=[3]))["action"].shape
        torch.Size([3, 2])
    """

    image_size: tuple[int, int] | None = None
    """``(height, width)`` of the frames the driver looks at (None: it does not look)."""
    frame_stack: int = POLICY_FRAMES
    """Frames one chunk apart the driver reads per camera (``("frame_stack", <camera>)``):
    build its env with that stack depth."""
    front_crop: float | None = None
    """The fraction of the front frame the driver's ``front_crop`` camera shows (None: it reads
    no crop): build its env with ``env.front_crop`` set to it."""
    needs_expert: bool = False
    """Whether the driver drives with the embedded server's expert: build its env with
    ``expert=True``."""
    observation_spec: Composite | None = None
    """What the driver reads of one row (shapes without batch dimensions; None: undeclared).
    A policy server describes its inputs with it."""
    n_action_steps: int = CHUNK
    """Actions of each :meth:`plan` a policy server queues for a row before planning again."""

    def __init__(self, *, chunk_actions: bool = True) -> None:
        self.chunk_actions = chunk_actions

    @abstractmethod
    def chunks(self, td: TensorDictBase) -> torch.Tensor:
        """float32 ``[N, 4, 2]`` action chunks for the observation rows of ``td``."""

    def plan(self, td: TensorDictBase) -> torch.Tensor:
        """The actions ``[N, K, 2]`` (``K >= n_action_steps``) each row would take from its
        observation alone, bounded to ``[-1, 1]``: what a policy server queues for a row. The
        chunk, unless the driver keeps state between calls (a queue, a history): then it
        plans without touching that state."""
        return bounded(self.chunks(td))

    def __call__(self, td: TensorDictBase) -> TensorDictBase:
        """Set ``td["action"]`` and return ``td`` (as a TorchRL policy does)."""
        chunk = bounded(self.chunks(td))
        td.set("action", chunk if self.chunk_actions else chunk[:, 0].contiguous())
        return td


def bounded(actions: torch.Tensor) -> torch.Tensor:
    """Actions as float32 in ``[-1, 1]``, the world model's box.

    Example:
        >>> bounded(torch.tensor([2.0, -0.5], dtype=torch.float64))
        tensor([ 1.0000, -0.5000])
    """
    return actions.to(torch.float32).clamp(-1.0, 1.0)
