"""TorchRL modules around :class:`~oasis_torchrl.models.DrivingNet`: the PPO actor and critic.

Keys (those of :func:`oasis_torchrl.envs.make_training_env`): ``("images", <camera>)`` float
``[*B, 3, H, W]`` and ``"state"`` ``[*B, 2]`` in; ``"features"`` (shared), ``"loc"``, ``"scale"``,
``"action"`` ``[*B, 4, 2]``, ``"action_log_prob"`` and ``"state_value"`` out.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.data import Bounded
from torchrl.modules import ActorValueOperator, ProbabilisticActor, TanhNormal, ValueOperator

from oasis_torchrl.models.network import DrivingNet

IMAGES = "images"
STATE = "state"
FEATURES = "features"


class _Features(nn.Module):
    """``(*images, state) -> features`` for a TensorDictModule (positional in_keys)."""

    def __init__(self, net: DrivingNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        return self.net.features(inputs[:-1], inputs[-1])


class _ChunkParams(nn.Module):
    """``features -> (loc, scale)`` of the chunk distribution."""

    def __init__(self, net: DrivingNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        loc = self.net.action_loc(features)
        return loc, self.net.action_scale(loc)


class _Value(nn.Module):
    """``features -> value``."""

    def __init__(self, net: DrivingNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return self.net.value(features)


def observation_keys(net: DrivingNet) -> list[str | tuple[str, str]]:
    """The observation keys the network reads, in its order.

    Example:
        >>> observation_keys(DrivingNet())
        [('images', 'left_forward'), ('images', 'front'), ('images', 'right_forward'), 'state']
    """
    return [(IMAGES, camera) for camera in net.config.cameras] + [STATE]


@dataclass
class ActorCritic:
    """The PPO modules of one :class:`DrivingNet` (the three share its parameters).

    Attributes:
        operator: the :class:`~torchrl.modules.ActorValueOperator` (features, action and value).
        policy: the stochastic actor (a TanhNormal over the chunk in ``[-1, 1]``); call it under
            ``set_exploration_type(ExplorationType.DETERMINISTIC)`` for ``tanh(loc)``.
        value: the critic, writing ``"state_value"``.
    """

    operator: ActorValueOperator
    policy: ProbabilisticActor
    value: ValueOperator


def make_actor_critic(net: DrivingNet) -> ActorCritic:
    """Wrap ``net`` as the TorchRL actor and critic of the PPO recipe.

    Example:
        >>> from tensordict import TensorDict
        >>> from oasis_torchrl.models import DrivingNetConfig
        >>> net = DrivingNet(DrivingNetConfig(image_size=(32, 48)))
        >>> modules = make_actor_critic(net)
        >>> td = TensorDict({"images": {c: torch.rand(3, 3, 32, 48) for c in net.config.cameras},
        ...                  "state": torch.zeros(3, 2)}, batch_size=[3])
        >>> td = modules.policy(td)
        >>> td["action"].shape, td["action_log_prob"].shape
        (torch.Size([3, 4, 2]), torch.Size([3]))
        >>> modules.value(td)["state_value"].shape
        torch.Size([3, 1])
    """
    cfg = net.config
    common = TensorDictModule(_Features(net), in_keys=observation_keys(net), out_keys=[FEATURES])
    params = TensorDictModule(_ChunkParams(net), in_keys=[FEATURES], out_keys=["loc", "scale"])
    spec = Bounded(-1.0, 1.0, (cfg.chunk, cfg.action_dim))
    actor_head = ProbabilisticActor(
        params,
        in_keys=["loc", "scale"],
        spec=spec,
        distribution_class=TanhNormal,
        distribution_kwargs={"low": -1.0, "high": 1.0, "event_dims": 2},
        return_log_prob=True,
    )
    value_head = ValueOperator(_Value(net), in_keys=[FEATURES])
    operator = ActorValueOperator(common, actor_head, value_head)
    return ActorCritic(operator, operator.get_policy_operator(), operator.get_value_operator())
