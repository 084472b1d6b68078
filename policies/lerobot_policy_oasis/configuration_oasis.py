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
from dataclasses import dataclass, field

from lerobot.configs.policies import PreTrainedConfig
from lerobot.configs.types import FeatureType, NormalizationMode, PolicyFeature
from lerobot.optim.optimizers import AdamWConfig
from lerobot.optim.schedulers import CosineAnnealingWithWarmupSchedulerConfig
from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE

from oasis_torchrl.models import CAMERAS, DrivingNetConfig
from oasis_torchrl.models.privileged import PRIVILEGED_FIELDS
from oasis_torchrl.protocol import ACTION_DIM, CHUNK

POLICY_TYPE = "oasis"
FRAME_SPACING = CHUNK
"""Rows (world frames at 20 fps) between two frames the policy sees: one world-model chunk."""
LOSSES = ("nll", "manoeuvre", "l1", "mse")
SCHEDULERS = (None, "cosine")
"""Learning-rate schedules: ``None`` (constant) or ``"cosine"`` (warm-up, then annealing to 0)."""
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
)
"""The :class:`DrivingNetConfig` fields a LeRobot config sets as its own. The others come from
LeRobot's fields (``frames``: ``n_obs_steps``, ``chunk``: ``chunk_size``, ``cameras`` and
``state_dim``: the input features, ``aux_outputs``: ``aux_weight``) or belong to PPO's
training-only critic (``critic_inputs``)."""


def _network_fields() -> type:
    """A dataclass of :data:`NETWORK_FIELDS` with :class:`DrivingNetConfig`'s types and
    defaults, so the policy config follows the network's without a copy."""
    types = typing.get_type_hints(DrivingNetConfig)
    defaults = DrivingNetConfig()
    fields = [
        (name, types[name], field(default=getattr(defaults, name))) for name in NETWORK_FIELDS
    ]
    return dataclasses.make_dataclass("DrivingNetFields", fields)


DrivingNetFields = _network_fields()


def _identity_mapping() -> dict[str, NormalizationMode]:
    return {
        "VISUAL": NormalizationMode.IDENTITY,
        "STATE": NormalizationMode.IDENTITY,
        "ACTION": NormalizationMode.IDENTITY,
    }


@PreTrainedConfig.register_subclass(POLICY_TYPE)
@dataclass
class OasisConfig(PreTrainedConfig, DrivingNetFields):
    """Configuration of :class:`~lerobot_policy_oasis.modeling_oasis.OasisPolicy`.

    The network's fields (:data:`NETWORK_FIELDS`: ``image_size``, ``shared_encoder``,
    ``encoder_channels``, ``encoder_strides``, ``pool_grid``, ``camera_features``,
    ``hidden_dim``, ``use_state``, ``head``, ``components``, ``init_action``, ``init_spread``,
    ``init_scale``, ``min_scale``)
    are :class:`oasis_torchrl.models.DrivingNetConfig`'s, with its types, defaults and meaning
    (:meth:`net_config` builds it), so a LeRobot checkpoint loads into TorchRL PPO unchanged.
    ``image_size`` is also the size the preprocessor resizes frames to.

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
            classifier of them, :meth:`~oasis_torchrl.models.DrivingNet.manoeuvre`), ``"l1"``
            or ``"mse"`` (regression of the deterministic chunk, ``action_loss_weights``
            weighted).
        action_loss_weights: weight of the throttle and steering errors of ``"l1"`` and
            ``"mse"``. Actions are not normalised (see above), so with equal weights the loss
            follows the dimension that varies most: in autopilot demonstrations throttle drowns
            steering, whose rare lane changes are what avoids
            obstacles. (``"nll"`` weighs each number by its fitted scale instead.)
        manoeuvre_weight: extra weight of the demonstrations that steer: each sample's action
            loss is weighted ``1 + manoeuvre_weight * s``, ``s`` the mean absolute steering of
            its demonstrated chunk. Lane changes are a few percent of an autopilot's chunks, and
            unweighted a clone steers in fewer of them than the autopilot and drives into what
            it should change lanes for.
        aux_weight: weight of an auxiliary loss (0: none): the network's auxiliary head
            predicts each frame's privileged state (``privileged_state``: speed, offsets, heading
            error, obstacle distances ahead in the car's path, its lane and the lanes beside it,
            recorded by the embedded server) from the camera features, mean squared error.
            Dense labels on every frame teach the encoder to see obstacles and free lanes, which
            the rare lane changes of the action labels alone do not; at deployment the head is
            unused.
        optimizer_lr, optimizer_weight_decay, optimizer_grad_clip_norm: AdamW preset.
        scheduler_name: the learning-rate schedule: ``None`` keeps ``optimizer_lr`` throughout;
            ``"cosine"`` warms up linearly over ``scheduler_warmup_steps`` to ``optimizer_lr``,
            then anneals to zero at the last training step (LeRobot's
            ``cosine_annealing_with_warmup``; ``lerobot-train`` builds it with its ``steps``).
        scheduler_warmup_steps: the cosine schedule's warm-up.

    Example:
        >>> config = OasisConfig(device="cpu")
        >>> config.type, config.observation_delta_indices, config.action_delta_indices
        ('oasis', [-4, 0], [0, 1, 2, 3])
        >>> config.head == DrivingNetConfig().head
        True
    """

    n_obs_steps: int = 2
    chunk_size: int = 4
    n_action_steps: int = 4
    normalization_mapping: dict[str, NormalizationMode] = field(default_factory=_identity_mapping)

    loss: str = "nll"
    action_loss_weights: tuple[float, float] = (1.0, 1.0)
    manoeuvre_weight: float = 0.0
    aux_weight: float = 0.0
    optimizer_lr: float = 1e-3
    optimizer_weight_decay: float = 1e-4
    optimizer_grad_clip_norm: float = 10.0
    scheduler_name: str | None = None
    scheduler_warmup_steps: int = 0

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
        for name in ("aux_weight", "manoeuvre_weight"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"OasisConfig.{name} must be >= 0, got {getattr(self, name)}")
        if self.scheduler_name not in SCHEDULERS:
            raise ValueError(
                f"OasisConfig.scheduler_name must be one of {SCHEDULERS}, "
                f"got {self.scheduler_name!r}"
            )
        if self.scheduler_warmup_steps < 0:
            raise ValueError(
                "OasisConfig.scheduler_warmup_steps must be >= 0, "
                f"got {self.scheduler_warmup_steps}"
            )
        weights = tuple(self.action_loss_weights)
        if len(weights) != ACTION_DIM or min(weights) < 0 or max(weights) == 0:
            raise ValueError(
                "OasisConfig.action_loss_weights must be two non-negative weights, not both 0, "
                f"got {self.action_loss_weights!r}"
            )

    @property
    def cameras(self) -> tuple[str, ...]:
        """Camera names of the image inputs, the world model's order first."""
        prefix = f"{OBS_IMAGES}."
        names = [key.removeprefix(prefix) for key in self.image_features]
        known = [camera for camera in CAMERAS if camera in names]
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

    def get_scheduler_preset(self) -> CosineAnnealingWithWarmupSchedulerConfig | None:
        """The ``scheduler_name`` schedule, or ``None`` for a constant learning rate.

        Example:
            >>> OasisConfig(device="cpu", scheduler_name="cosine").get_scheduler_preset()
            CosineAnnealingWithWarmupSchedulerConfig(num_warmup_steps=0)
        """
        if self.scheduler_name is None:
            return None
        return CosineAnnealingWithWarmupSchedulerConfig(
            num_warmup_steps=self.scheduler_warmup_steps
        )

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
