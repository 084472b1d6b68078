"""A replay of past observations for the auxiliary loss: perception trained beside PPO.

Why: PPO's encoder learns to see only from the batch it is updating on, the last 512 env steps,
and only as far as the policy gradient and the auxiliary head need it there. The same PPO
handed the privileged state learns to drive, while on the cameras its auxiliary head barely
reads the obstacle in the car's own lane, and an encoder fitted to the privileged state reads
it better the more rows it sees (docs/experiments/: the state_ppo, perception and
perception_data pages). So the encoder needs more frames than one batch.

How: every batch PPO collects also goes into a ring of ``capacity`` rows (the observations the
encoder reads and their ``"critic_inputs"``, the frames kept as uint8), and after each PPO
update the encoder and the auxiliary head take ``steps`` extra gradient steps on the auxiliary
loss alone, on minibatches drawn uniformly from the ring. Only the simulator's privileged state
is a label, so this uses no demonstrations: every row is an env step PPO counted. The ring is
not checkpointed (a resumed run refills it). Off by default; the ``ppo_scratch`` preset turns it
on (docs/experiments/2026-11-28-ppo-from-scratch.md).
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torchrl.data import LazyTensorStorage, ReplayBuffer
from torchrl.data.replay_buffers import RandomSampler

from oasis_torchrl.models.actor_critic import CRITIC_INPUTS, observation_keys
from oasis_torchrl.train.ppo_loss import DrivingPPOLoss


class AuxiliaryReplay:
    """Past observations with their privileged state, replayed for the auxiliary loss.

    Args:
        loss: the PPO loss whose encoder and auxiliary head are trained (it needs an auxiliary
            head and a positive ``aux_coeff``; the replayed loss has the same weight).
        capacity: rows kept (the oldest are overwritten).
        mini_batch_size: rows per replayed minibatch.

    Raises:
        ValueError: no auxiliary loss to replay, or a capacity below one minibatch.

    Example:
        >>> from tensordict import TensorDict
        >>> from oasis_torchrl.models import DrivingNet, DrivingNetConfig, make_actor_critic
        >>> net = DrivingNet(DrivingNetConfig(image_size=(32, 48), aux_outputs=10))
        >>> replay = AuxiliaryReplay(DrivingPPOLoss(make_actor_critic(net), aux_coeff=1.0),
        ...                          capacity=64, mini_batch_size=8)
        >>> frames = torch.zeros(16, 2, 32, 48, 3, dtype=torch.uint8)
        >>> replay.extend(TensorDict({"frame_stack": {c: frames for c in net.config.cameras},
        ...     "state": torch.zeros(16, 2), "critic_inputs": torch.zeros(16, 10)}, [16]))
        >>> len(replay), replay.loss().shape
        (16, torch.Size([]))
    """

    def __init__(self, loss: DrivingPPOLoss, capacity: int, mini_batch_size: int) -> None:
        if not loss.aux_coeff:
            raise ValueError(
                "the auxiliary replay trains the auxiliary loss: set loss.aux_coeff > 0 "
                "(the network then has its auxiliary head)"
            )
        if not capacity >= mini_batch_size > 0:
            raise ValueError(
                f"the auxiliary replay's capacity ({capacity}) must hold at least one "
                f"minibatch ({mini_batch_size} rows, > 0)"
            )
        self._loss = loss
        self.keys = [*observation_keys(loss.net), CRITIC_INPUTS]
        self.buffer = ReplayBuffer(
            storage=LazyTensorStorage(capacity),
            sampler=RandomSampler(),
            batch_size=mini_batch_size,
        )

    def __len__(self) -> int:
        return len(self.buffer)

    def extend(self, flat: TensorDictBase) -> None:
        """Add the rows of a flat batch (``[N]``; its other keys are left out)."""
        self.buffer.extend(flat.select(*self.keys))

    def minibatch(self) -> TensorDictBase:
        """One minibatch drawn uniformly from the replay."""
        if not len(self.buffer):
            raise RuntimeError("the auxiliary replay is empty: extend it with a batch first")
        return self.buffer.sample()

    def loss(self) -> torch.Tensor:
        """The weighted auxiliary loss on one :meth:`minibatch` (with gradients to the encoder
        and the auxiliary head)."""
        return self._loss.aux_loss(self._loss.features(self.minibatch()))
