"""Perception before PPO: the encoder fitted to the privileged state of the run's first env steps.

Why: PPO from scratch on the cameras learns to see and to act at once, and its encoders never
learn to read the obstacle in the car's own lane, the one number a lane change hangs on; handed
the privileged state, or started from an encoder fitted first to the autopilot's drives, the
same PPO drives much farther (docs/experiments/2026-11-28-ppo-from-scratch.md).

How: the first ``warmup.frames`` env steps are driven, by the initial policy or by a named driver
that needs no expert (``warmup.driver``), and counted in ``collector.total_frames``; their
observations and privileged state go into a ring
(:class:`~oasis_torchrl.train.aux_replay.AuxiliaryReplay`), and the encoder and the auxiliary head
take ``warmup.steps`` minibatches of the auxiliary loss alone, with an Adam of their own. Then PPO
starts, its actor and critic fresh on features that already see (its learning rates anneal over
the whole budget, the warm-up's env steps included). No demonstration: only the simulator's
privileged state is a label. Off by default; the ``ppo_scratch`` preset turns it on, driven by
the best constant action (docs/experiments/2026-11-28-ppo-from-scratch.md).
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tqdm import tqdm

from oasis_torchrl.train.aux_replay import AuxiliaryReplay
from oasis_torchrl.train.ppo_loss import DrivingPPOLoss


class PerceptionWarmup:
    """The encoder and the auxiliary head of ``loss`` fitted to the privileged state of the rows
    given to :meth:`extend`.

    Args:
        loss: the PPO loss whose encoder and auxiliary head are fitted (it needs an auxiliary
            head and a positive ``aux_coeff``).
        capacity: rows kept (the oldest are overwritten): the warm-up's env steps.
        mini_batch_size: rows per minibatch.
        lr: Adam's learning rate for the warm-up.

    Example:
        >>> from tensordict import TensorDict
        >>> from oasis_torchrl.models import DrivingNet, DrivingNetConfig, make_actor_critic
        >>> net = DrivingNet(DrivingNetConfig(image_size=(32, 48), aux_outputs=10))
        >>> loss = DrivingPPOLoss(make_actor_critic(net), aux_coeff=1.0)
        >>> warmup = PerceptionWarmup(loss, capacity=64, mini_batch_size=8, lr=1e-3)
        >>> frames = torch.randint(0, 256, (16, 2, 32, 48, 3), dtype=torch.uint8)
        >>> warmup.extend(TensorDict({"frame_stack": {c: frames for c in net.config.cameras},
        ...     "state": torch.zeros(16, 2), "critic_inputs": torch.ones(16, 10)}, [16]))
        >>> losses = warmup.fit(steps=20, progress=False)
        >>> len(losses), losses[-1] < losses[0]
        (20, True)
    """

    def __init__(
        self, loss: DrivingPPOLoss, capacity: int, mini_batch_size: int, lr: float
    ) -> None:
        self.replay = AuxiliaryReplay(loss, capacity, mini_batch_size)
        net = loss.net
        parameters = [*net.encoder.parameters(), *net.aux.parameters()]
        self.optimizer = torch.optim.Adam(parameters, lr=lr)

    def __len__(self) -> int:
        return len(self.replay)

    def extend(self, flat: TensorDictBase) -> None:
        """Add the rows of a flat batch (``[N]``; only what the auxiliary loss reads is kept)."""
        self.replay.extend(flat)

    def fit(self, steps: int, progress: bool = True) -> list[float]:
        """``steps`` minibatches of the auxiliary loss alone; each step's loss."""
        losses = []
        for _ in tqdm(range(steps), desc="perception warm-up", unit="step", disable=not progress):
            loss = self.replay.loss()
            self.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            self.optimizer.step()
            losses.append(loss.item())
        return losses
