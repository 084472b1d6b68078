"""LeRobot configuration of the oasis driving policy (policy type ``oasis``).

Inputs: ``observation.images.<camera>`` (any number of cameras; the world model's three are
``left_forward``, ``front``, ``right_forward``) and ``observation.state`` (the previous
``[throttle, steering]``), over ``n_obs_steps`` frames one world-model chunk apart (2 by
default: the current frame and the one 4 rows earlier show the motion a single frame cannot).
Output: ``action`` ``[throttle, steering]`` per row at the world model's 20 fps; the policy
predicts ``chunk_size`` of them per call (4 = one world-model call).

Why one chunk apart: in LeRobot's per-frame loops over the world model (``lerobot-eval``,
``lerobot-record``, ``lerobot-rollout`` with ``--env.type=oasis`` or ``--robot.type=oasis``)
a new frame arrives every 4 ticks (:mod:`oasis_torchrl.envs.per_frame`), so at a chunk boundary
the two newest frames a policy has seen are the last frames of the two previous chunks. The
same spacing in training (these delta indices), in TorchRL (``ChunkFrameStack``) and here makes
one policy act the same in every tool.

Normalisation runs in LeRobot's processor pipeline (:mod:`.processor_oasis`). The defaults are
``IDENTITY`` on purpose: images arrive in ``[0, 1]`` and the network centres them itself, and
state and action already live in the env's ``[-1, 1]`` box, which the tanh-bounded chunk head
targets directly. That keeps one set of weights valid in TorchRL PPO, which feeds the env's raw
values. Any LeRobot mode can still be chosen per feature type with ``normalization_mapping``.
"""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass, field, fields
from typing import Any

from lerobot.configs.policies import PreTrainedConfig
from lerobot.configs.types import FeatureType, NormalizationMode, PolicyFeature
from lerobot.optim.optimizers import AdamWConfig
from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE

from oasis_torchrl.config.training import BCPolicyConfig, OptimiserConfig
from oasis_torchrl.models import DrivingNetConfig
from oasis_torchrl.models.privileged import PRIVILEGED_FIELDS
from oasis_torchrl.protocol import ACTION_DIM, CHUNK, POLICY_CAMERAS

POLICY_TYPE = "oasis"
FRAME_SPACING = CHUNK
"""Rows (world frames at 20 fps) between two frames the policy sees: one world-model chunk."""
LOSSES = ("nll", "manoeuvre")
NETWORK_FIELDS = (
    "image_size",
    "shared_encoder",
    "encoder_channels",
    "encoder_strides",
    "pool_grid",
    "camera_features",
    "hidden_dim",
    "use_state",
    "head",
    "components",
    "init_action",
    "init_spread",
    "init_scale",
    "min_scale",
    "front_crop",
)
"""The :class:`DrivingNetConfig` fields a LeRobot config sets as its own. The others come from
LeRobot's fields (``frames``: ``n_obs_steps``, ``chunk``: ``chunk_size``, ``cameras`` and
``state_dim``: the input features, ``aux_outputs``: ``aux_weight``) or belong to PPO's
training-only critic (``critic_inputs``)."""
TRAINING_FIELDS = tuple(
    item.name for item in fields(BCPolicyConfig) if item.name not in NETWORK_FIELDS
)
"""Behaviour cloning's own settings (loss, auxiliary weight): those of
:class:`~oasis_torchrl.config.training.BCPolicyConfig` that are no network field."""
OPTIMIZER_FIELDS = {
    "optimizer_lr": "lr",
    "optimizer_weight_decay": "weight_decay",
    "optimizer_grad_clip_norm": "max_grad_norm",
}
"""The project's one optimiser section
(:class:`~oasis_torchrl.config.training.OptimiserConfig`) under LeRobot's names: its policy
configs keep their optimiser preset's settings as ``optimizer_<name>`` fields, where
``lerobot-train`` reads them (:meth:`OasisConfig.get_optimizer_preset`), and the shipped
policies' ``config.json`` holds them so. This mapping is the one place the two spellings meet."""


def lerobot_optimizer(optim: Any) -> dict[str, float]:
    """An optimiser section's settings (:class:`OptimiserConfig`, or a config of its keys) as
    the LeRobot config's fields.

    Example:
        >>> lerobot_optimizer(OptimiserConfig())["optimizer_grad_clip_norm"]
        10.0
    """
    return {lerobot: getattr(optim, own) for lerobot, own in OPTIMIZER_FIELDS.items()}


def _policy_fields() -> type:
    """A dataclass of :data:`NETWORK_FIELDS` (:class:`DrivingNetConfig`'s types),
    :data:`TRAINING_FIELDS` and :data:`OPTIMIZER_FIELDS`, each field's default behaviour
    cloning's (:class:`~oasis_torchrl.config.training.BCPolicyConfig` and
    :class:`~oasis_torchrl.config.training.OptimiserConfig`, what ``oasis-torchrl train bc``
    uses) where it has one, else the network's: one definition, so ``lerobot-train
    --policy.type=oasis`` and ``oasis-torchrl train bc`` train the same policy."""
    types = {**typing.get_type_hints(BCPolicyConfig), **typing.get_type_hints(DrivingNetConfig)}
    cloning, network = BCPolicyConfig(), DrivingNetConfig()
    optimiser_types = typing.get_type_hints(OptimiserConfig)
    specs = []
    for name in (*NETWORK_FIELDS, *TRAINING_FIELDS):
        default = getattr(cloning, name, getattr(network, name, None))
        default = tuple(default) if isinstance(default, list) else default
        specs.append((name, types[name], field(default=default)))
    for name, default in lerobot_optimizer(OptimiserConfig()).items():
        specs.append((name, optimiser_types[OPTIMIZER_FIELDS[name]], field(default=default)))
    return dataclasses.make_dataclass("OasisPolicyFields", specs)


OasisPolicyFields = _policy_fields()


def _identity_mapping() -> dict[str, NormalizationMode]:
    return {
        "VISUAL": NormalizationMode.IDENTITY,
        "STATE": NormalizationMode.IDENTITY,
        "ACTION": NormalizationMode.IDENTITY,
    }


@PreTrainedConfig.register_subclass(POLICY_TYPE)
@dataclass
class OasisConfig(PreTrainedConfig, OasisPolicyFields):
    """Configuration of :class:`~lerobot_policy_oasis.modeling_oasis.OasisPolicy`.

    The network's fields (:data:`NETWORK_FIELDS`: ``image_size``, ``shared_encoder``,
    ``encoder_channels``, ``encoder_strides``, ``pool_grid``, ``camera_features``,
    ``hidden_dim``, ``use_state``, ``head``, ``components``, ``init_action``, ``init_spread``,
    ``init_scale``, ``min_scale``, ``front_crop``)
    are :class:`oasis_torchrl.models.DrivingNetConfig`'s, with its types and meaning
    (:meth:`net_config` builds it), so a LeRobot checkpoint loads into TorchRL PPO unchanged.
    ``image_size`` is also the size the preprocessor resizes frames to. Their defaults, and
    those of the training settings below (:data:`TRAINING_FIELDS`), are behaviour cloning's
    (:class:`oasis_torchrl.config.training.BCPolicyConfig`, e.g. ``use_state`` off), so
    ``lerobot-train --policy.type=oasis`` trains what ``oasis-torchrl train bc`` does.

    Args:
        n_obs_steps: frames per camera the network sees, :data:`FRAME_SPACING` rows apart (its
            ``frames``).
        chunk_size: actions predicted per call.
        n_action_steps: actions of each chunk executed before predicting again.
        loss: behaviour-cloning loss on the chunk: ``"nll"`` (the negative log-likelihood of
            the demonstrated chunk under the network's chunk distribution, per action number:
            with the mixture head each manoeuvre gets its own component and the clone commits
            to one; it also fits the distribution's scale), ``"manoeuvre"`` (the same, jointly
            with the chunk's manoeuvre: the mixture component whose initial steering is nearest
            the chunk's, so the components are left, keep and right and the weights a
            classifier of them, :meth:`~oasis_torchrl.models.DrivingNet.manoeuvre`).
        aux_weight: weight of an auxiliary loss (0: none): the network's auxiliary head
            predicts each frame's privileged state (``privileged_state``: speed, offsets, heading
            error, obstacle distances ahead in the car's path, its lane and the lanes beside it,
            recorded by the embedded server) from the camera features, mean squared error.
            Dense labels on every frame teach the encoder to see obstacles and free lanes, which
            the rare lane changes of the action labels alone do not; at deployment the head is
            unused.
        optimizer_lr, optimizer_weight_decay, optimizer_grad_clip_norm: AdamW preset (a
            constant learning rate: no scheduler preset); ``oasis-torchrl train bc``'s ``optim``
            section (:class:`oasis_torchrl.config.training.OptimiserConfig`) under LeRobot's
            names (:data:`OPTIMIZER_FIELDS`).

    Example:
        >>> config = OasisConfig(device="cpu")
        >>> config.type, config.observation_delta_indices, config.action_delta_indices
        ('oasis', [-4, 0], [0, 1, 2, 3])
        >>> config.head == DrivingNetConfig().head, config.use_state
        (True, False)
    """

    n_obs_steps: int = 2
    chunk_size: int = 4
    n_action_steps: int = 4
    normalization_mapping: dict[str, NormalizationMode] = field(default_factory=_identity_mapping)

    # Nothing is uploaded unless asked for, so `lerobot-train` needs no `policy.repo_id`.
    push_to_hub: bool = False

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.n_obs_steps < 1:
            raise ValueError(f"OasisConfig.n_obs_steps must be >= 1, got {self.n_obs_steps}")
        if not 1 <= self.n_action_steps <= self.chunk_size:
            raise ValueError(
                f"OasisConfig.n_action_steps must be in [1, chunk_size={self.chunk_size}], "
                f"got {self.n_action_steps}"
            )
        if self.loss not in LOSSES:
            raise ValueError(f"OasisConfig.loss must be one of {LOSSES}, got {self.loss!r}")
        if not self.aux_weight >= 0:
            raise ValueError(f"OasisConfig.aux_weight must be >= 0, got {self.aux_weight}")

    @property
    def cameras(self) -> tuple[str, ...]:
        """Camera names of the image inputs, the world model's order first."""
        prefix = f"{OBS_IMAGES}."
        names = [key.removeprefix(prefix) for key in self.image_features]
        known = [camera for camera in POLICY_CAMERAS if camera in names]
        return (*known, *sorted(set(names) - set(known)))

    def net_config(self) -> DrivingNetConfig:
        """The :class:`DrivingNetConfig` of this policy (needs the input features set)."""
        self.validate_features()
        return DrivingNetConfig.from_dict(
            {
                **{name: getattr(self, name) for name in NETWORK_FIELDS},
                "cameras": self.cameras,
                "frames": self.n_obs_steps,
                "state_dim": self.robot_state_feature.shape[0],
                "chunk": self.chunk_size,
                "action_dim": ACTION_DIM,
                "aux_outputs": len(PRIVILEGED_FIELDS) if self.aux_weight else 0,
            }
        )

    @classmethod
    def from_settings(cls, policy: dict[str, Any], optim: Any, device: str = "cpu") -> OasisConfig:
        """The policy config of ``oasis-torchrl train bc``'s ``policy`` settings (plain values)
        and ``optim`` section (:func:`lerobot_optimizer`).

        Example:
            >>> config = OasisConfig.from_settings({"pool_grid": [2, 3]}, OptimiserConfig(lr=0.01))
            >>> config.pool_grid, config.optimizer_lr
            ((2, 3), 0.01)
        """
        values = {key: tuple(v) if isinstance(v, list) else v for key, v in policy.items()}
        return cls(device=device, **values, **lerobot_optimizer(optim))

    @classmethod
    def from_net_config(cls, net: DrivingNetConfig, device: str = "cpu") -> OasisConfig:
        """The policy config of a network (e.g. one trained with PPO), features included.

        Example:
            >>> net = DrivingNetConfig(image_size=(32, 48), head="tanh_normal")
            >>> config = OasisConfig.from_net_config(net)
            >>> config.net_config() == net, config.cameras[0]
            (True, 'left_forward')
        """
        if net.action_dim != ACTION_DIM:
            raise ValueError(f"the network's action_dim must be {ACTION_DIM}, got {net.action_dim}")
        inputs = {
            f"{OBS_IMAGES}.{camera}": PolicyFeature(FeatureType.VISUAL, (3, *net.image_size))
            for camera in net.cameras
        }
        inputs[OBS_STATE] = PolicyFeature(FeatureType.STATE, (net.state_dim,))
        return cls(
            device=device,
            input_features=inputs,
            output_features={ACTION: PolicyFeature(FeatureType.ACTION, (ACTION_DIM,))},
            n_obs_steps=net.frames,
            chunk_size=net.chunk,
            n_action_steps=net.chunk,
            **{name: getattr(net, name) for name in NETWORK_FIELDS},
        )

    def validate_features(self) -> None:
        """Check for at least one camera, ``observation.state`` and a 2-number ``action``."""
        if not self.image_features:
            raise ValueError(f"the oasis policy needs at least one '{OBS_IMAGES}.<camera>' input")
        if self.robot_state_feature is None:
            raise ValueError(f"the oasis policy needs an '{OBS_STATE}' input")
        action = self.action_feature
        if action is None or tuple(action.shape) != (ACTION_DIM,):
            shape = None if action is None else tuple(action.shape)
            raise ValueError(
                f"the oasis policy needs '{ACTION}' of shape ({ACTION_DIM},) (one [throttle, "
                f"steering] per row: record with all frames), got {shape}"
            )
        visual = [ft for ft in self.input_features.values() if ft.type is FeatureType.VISUAL]
        if any(len(ft.shape) != 3 or ft.shape[0] != 3 for ft in visual):
            raise ValueError(f"camera inputs must be RGB [3, H, W], got {visual}")

    def get_optimizer_preset(self) -> AdamWConfig:
        """AdamW with this config's learning rate, weight decay and clipping."""
        return AdamWConfig(
            lr=self.optimizer_lr,
            weight_decay=self.optimizer_weight_decay,
            grad_clip_norm=self.optimizer_grad_clip_norm,
        )

    def get_scheduler_preset(self) -> None:
        """No schedule: the learning rate stays ``optimizer_lr``."""
        return None

    @property
    def observation_delta_indices(self) -> list[int] | None:
        """``n_obs_steps`` rows :data:`FRAME_SPACING` apart, the current one last (None: only
        the current one)."""
        if self.n_obs_steps == 1:
            return None
        return list(range((1 - self.n_obs_steps) * FRAME_SPACING, 1, FRAME_SPACING))

    @property
    def action_delta_indices(self) -> list[int]:
        """The next ``chunk_size`` actions."""
        return list(range(self.chunk_size))

    @property
    def reward_delta_indices(self) -> None:
        """Rewards are not used."""
        return None
