"""The PPO loss of a :class:`~oasis_torchrl.models.DrivingNet`: TorchRL's ClipPPOLoss with the
shared encoder run once per minibatch, plus the auxiliary loss.

``ClipPPOLoss(actor, critic)`` over the full actor and critic operators of an
:class:`~torchrl.modules.ActorValueOperator` runs the shared encoder twice per minibatch (once
for the log-probabilities, once for the values), and the encoder is most of an update's cost.
:class:`DrivingPPOLoss` encodes the minibatch once and hands ClipPPOLoss the two heads, which
read the fresh ``"features"``; gradients reach the encoder through them, so the result is the
same loss for one encoder pass instead of two (``benchmarks/ppo_update.py`` compares them).
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torch import nn
from torchrl.objectives import ClipPPOLoss

from oasis_torchrl.models import ActorCritic
from oasis_torchrl.models.actor_critic import CRITIC_INPUTS, FEATURES

PPO_TERMS = ("loss_objective", "loss_critic", "loss_entropy")
"""ClipPPOLoss's terms that are summed into the PPO loss."""
AUX_TERM = "loss_aux"


class DrivingPPOLoss(nn.Module):
    """ClipPPOLoss on the heads of ``modules`` over features encoded once per minibatch, plus
    ``aux_coeff`` x the auxiliary head's mean squared error on ``"critic_inputs"`` when the
    network has that head.

    Args:
        modules: the actor-critic modules of the network (:func:`make_actor_critic`).
        aux_coeff: weight of the auxiliary loss (ignored without an auxiliary head).
        **ppo_kwargs: :class:`~torchrl.objectives.ClipPPOLoss` arguments (``clip_epsilon``,
            ``entropy_coeff``, ``critic_coeff``, ``loss_critic_type``, ...).

    Example:
        >>> from tensordict import TensorDict
        >>> from oasis_torchrl.models import DrivingNet, DrivingNetConfig, make_actor_critic
        >>> net = DrivingNet(DrivingNetConfig(image_size=(32, 48), critic_inputs=4, aux_outputs=4))
        >>> modules = make_actor_critic(net)
        >>> frames = torch.zeros(6, 2, 32, 48, 3, dtype=torch.uint8)
        >>> batch = TensorDict({"frame_stack": {c: frames for c in net.config.cameras},
        ...     "state": torch.zeros(6, 2), "critic_inputs": torch.zeros(6, 4)}, [6])
        >>> with torch.no_grad():
        ...     batch = modules.policy(batch)
        >>> batch["advantage"], batch["value_target"] = torch.randn(6, 1), torch.randn(6, 1)
        >>> losses = DrivingPPOLoss(modules, aux_coeff=1.0)(batch)
        >>> sorted(key for key in losses.keys() if key.startswith("loss"))
        ['loss_aux', 'loss_critic', 'loss_entropy', 'loss_objective']
    """

    def __init__(self, modules: ActorCritic, aux_coeff: float = 0.0, **ppo_kwargs: object) -> None:
        super().__init__()
        self.features = modules.features
        self.net = modules.net
        self.ppo = ClipPPOLoss(
            modules.operator.get_policy_head(), modules.operator.get_value_head(), **ppo_kwargs
        )
        self.aux_coeff = aux_coeff if self.net.aux is not None else 0.0

    @property
    def terms(self) -> tuple[str, ...]:
        """The loss terms a full (not critic-only) step sums."""
        return (*PPO_TERMS, AUX_TERM) if self.aux_coeff else PPO_TERMS

    def forward(self, minibatch: TensorDictBase) -> TensorDictBase:
        """ClipPPOLoss's output (terms and diagnostics), with ``"loss_aux"`` when configured.

        ``minibatch`` needs the observations, ``"action"``, ``"action_log_prob"``,
        ``"advantage"`` and ``"value_target"``; its stored ``"features"`` (the collector's,
        detached) are replaced by a fresh encoding.
        """
        encoded = self.features(minibatch.clone(False))
        losses = self.ppo(encoded)
        if self.aux_coeff:
            losses[AUX_TERM] = self.aux_loss(encoded)
        return losses

    def aux_loss(self, encoded: TensorDictBase) -> torch.Tensor:
        """``aux_coeff`` x the auxiliary head's mean squared error on ``"critic_inputs"``, from
        the ``"features"`` of an encoded minibatch."""
        prediction = self.net.predict_aux(encoded.get(FEATURES))
        error = torch.nn.functional.mse_loss(prediction, encoded.get(CRITIC_INPUTS))
        return error * self.aux_coeff
