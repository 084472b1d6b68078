"""TorchRL modules around :class:`~oasis_torchrl.models.DrivingNet`: the PPO actor and critic.

Keys in: each camera's frames and ``"state"`` ``[*B, 2]``. Frames are read from
``("frame_stack", <camera>)`` by default: uint8 ``[*B, K, H, W, 3]``, the last frame of each of
the last ``K`` chunks, oldest first (:class:`oasis_torchrl.envs.transforms.ChunkFrameStack`,
which :func:`oasis_torchrl.envs.make_env` adds), converted to float by the encoder, so rollouts
store compact uint8 frames; ``image_key="images"`` reads float ``[*B, (K,) 3, H, W]`` in
``[0, 1]`` instead (e.g. TorchRL's ``ToTensorImage`` writing ``("images", <camera>)``).
With ``critic_inputs`` configured, the critic also reads ``"critic_inputs"`` ``[*B, k]``.
Keys out: ``"features"`` (shared), the chunk distribution's parameters (``"loc"``,
``"scale"``, and ``"logits"`` for the mixture head), ``"action"`` ``[*B, 4, 2]``,
``"action_log_prob"`` and ``"state_value"``.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.data import Bounded, Composite
from torchrl.modules import ActorValueOperator, ProbabilisticActor, ValueOperator

from oasis_torchrl.models.network import DrivingNet

PIXELS = "pixels"
"""The env's frames of a chunk: ``("pixels", <camera>)``."""
FRAME_STACK = "frame_stack"
"""The frames a policy reads, one chunk apart: ``("frame_stack", <camera>)``."""
IMAGES = "images"
STATE = "state"
FEATURES = "features"
CRITIC_INPUTS = "critic_inputs"


class _Features(nn.Module):
    """``(*frames, state) -> features`` for a TensorDictModule (positional in_keys)."""

    def __init__(self, net: DrivingNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        return self.net.features(inputs[:-1], inputs[-1])


class _Chunk(nn.Module):
    """``(*frames, state) -> tanh(loc)``: the deterministic chunk, no distribution."""

    def __init__(self, net: DrivingNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        return self.net(inputs[:-1], inputs[-1])


class _ChunkParams(nn.Module):
    """``features -> `` the chunk distribution's parameters, in ``net.action_params`` order."""

    def __init__(self, net: DrivingNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, ...]:
        return tuple(self.net.action_params(features).values())


class _Value(nn.Module):
    """``(features[, critic inputs]) -> value``."""

    def __init__(self, net: DrivingNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, features: torch.Tensor, extra: torch.Tensor | None = None) -> torch.Tensor:
        return self.net.value(features, extra)


def observation_keys(net: DrivingNet, image_key: str = FRAME_STACK) -> list[str | tuple[str, str]]:
    """The observation keys the network reads, in its order.

    Example:
        >>> observation_keys(DrivingNet())[1:]
        [('frame_stack', 'front'), ('frame_stack', 'right_forward'), 'state']
    """
    return [(image_key, camera) for camera in net.config.cameras] + [STATE]


def make_deterministic_actor(net: DrivingNet, image_key: str = FRAME_STACK) -> TensorDictModule:
    """The actor that deploys: observations -> ``"action"``, the chunk ``tanh(loc)`` (what the
    PPO actor gives under ``ExplorationType.DETERMINISTIC``, without building a distribution
    and its log-probability on every call).

    Example:
        >>> from tensordict import TensorDict
        >>> from oasis_torchrl.models import DrivingNetConfig
        >>> net = DrivingNet(DrivingNetConfig(image_size=(32, 48)))
        >>> frames = torch.zeros(3, 2, 32, 48, 3, dtype=torch.uint8)
        >>> td = TensorDict({"frame_stack": {c: frames for c in net.config.cameras},
        ...                  "state": torch.zeros(3, 2)}, batch_size=[3])
        >>> make_deterministic_actor(net)(td)["action"].shape
        torch.Size([3, 4, 2])
    """
    return TensorDictModule(
        _Chunk(net), in_keys=observation_keys(net, image_key), out_keys=["action"]
    )


def observation_spec(net: DrivingNet) -> Composite:
    """What the actor reads of one row (no batch dimensions): ``frames`` uint8 frames one chunk
    apart of each camera (``("frame_stack", <camera>)``, ``[frames, H, W, 3]``) and ``"state"``.

    Example:
        >>> spec = observation_spec(DrivingNet())
        >>> spec["frame_stack", "front"].shape, spec["state"].shape
        (torch.Size([2, 64, 96, 3]), torch.Size([2]))
    """
    cfg = net.config
    frame = Bounded(0, 255, (cfg.frames, *cfg.image_size, 3), dtype=torch.uint8)
    return Composite(
        {
            FRAME_STACK: Composite({camera: frame.clone() for camera in cfg.cameras}),
            STATE: Bounded(-1.0, 1.0, (cfg.state_dim,)),
        }
    )


@dataclass
class ActorCritic:
    """The PPO modules of one :class:`DrivingNet` (the three share its parameters).

    Attributes:
        operator: the :class:`~torchrl.modules.ActorValueOperator` (features, action and value).
        policy: the stochastic actor (the network's chunk distribution over ``[-1, 1]``); call
            it under ``set_exploration_type(ExplorationType.DETERMINISTIC)`` for the chunk the
            policy commits to.
        value: the critic, writing ``"state_value"``.
        net: the network they wrap.

    Example:
        >>> modules = make_actor_critic(DrivingNet())
        >>> modules.value.out_keys[-1]
        'state_value'
        >>> modules.features.out_keys
        ['features']
    """

    operator: ActorValueOperator
    policy: ProbabilisticActor
    value: ValueOperator
    net: DrivingNet

    @property
    def features(self) -> TensorDictModule:
        """The shared part, observations -> ``"features"``, which the operator's heads
        (``operator.get_policy_head()``, ``operator.get_value_head()``) read."""
        return self.operator.module[0]


def make_actor_critic(
    net: DrivingNet, image_key: str = FRAME_STACK, features: TensorDictModule | None = None
) -> ActorCritic:
    """Wrap ``net`` as the TorchRL actor and critic of the PPO recipe.

    Args:
        net: the network (shared by the three modules).
        image_key: ``"frame_stack"`` (uint8 env frames) or ``"images"`` (float, see module
            doc).
        features: the shared part, writing ``"features"`` ``[*B, net.config.features_dim]``
            (default: ``net.features`` of the cameras and the state); another one gives the
            same heads other inputs, e.g. a teacher that reads the privileged state.

    Example:
        >>> from tensordict import TensorDict
        >>> from oasis_torchrl.models import DrivingNetConfig
        >>> net = DrivingNet(DrivingNetConfig(image_size=(32, 48)))
        >>> modules = make_actor_critic(net)
        >>> frames = torch.zeros(3, 2, 32, 48, 3, dtype=torch.uint8)
        >>> td = TensorDict({"frame_stack": {c: frames for c in net.config.cameras},
        ...                  "state": torch.zeros(3, 2)}, batch_size=[3])
        >>> td = modules.policy(td)
        >>> td["action"].shape, td["action_log_prob"].shape
        (torch.Size([3, 4, 2]), torch.Size([3]))
        >>> modules.value(td)["state_value"].shape
        torch.Size([3, 1])
    """
    cfg = net.config
    common = features or TensorDictModule(
        _Features(net), in_keys=observation_keys(net, image_key), out_keys=[FEATURES]
    )
    param_keys = list(net.action_params(torch.zeros(cfg.features_dim)))
    params = TensorDictModule(_ChunkParams(net), in_keys=[FEATURES], out_keys=param_keys)
    spec = Bounded(-1.0, 1.0, (cfg.chunk, cfg.action_dim))
    actor_head = ProbabilisticActor(
        params,
        in_keys=param_keys,
        spec=spec,
        distribution_class=net.distribution_class,
        distribution_kwargs=net.distribution_kwargs,
        return_log_prob=True,
    )
    value_keys = [FEATURES, CRITIC_INPUTS] if cfg.critic_inputs else [FEATURES]
    value_head = ValueOperator(_Value(net), in_keys=value_keys)
    operator = ActorValueOperator(common, actor_head, value_head)
    return ActorCritic(operator, operator.get_policy_operator(), operator.get_value_operator(), net)
