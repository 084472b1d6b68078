"""Hyper-parameters of the driving network, shared by TorchRL PPO and the LeRobot policy."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from oasis_torchrl.config.training import NetworkArchitectureConfig
from oasis_torchrl.protocol import ACTION_DIM, CAMERAS, CHUNK, FRONT_CROP

POLICY_IMAGE_SIZE: tuple[int, int] = (64, 96)
"""Default ``(height, width)`` the network sees."""
POLICY_FRAMES = 2
"""Default frames per camera the network sees, one chunk apart."""
MAX_INIT_ACTION = 0.99
"""Largest ``|init_action|``: its location before the tanh stays inside the network's bound."""
ENCODER_STRIDES = (1, 2, 4)
"""Strides an encoder convolution may have (4: a 4x4 patch convolution, else 3x3)."""
TANH_NORMAL = "tanh_normal"
MIXTURE = "mixture"
HEADS = (TANH_NORMAL, MIXTURE)
"""Action heads: one tanh-normal over the chunk, or a mixture of them (one per manoeuvre)."""
_SHAPE = NetworkArchitectureConfig()
"""The shape settings of PPO's and BC's commands: their defaults are the network's."""


@dataclass(frozen=True)
class DrivingNetConfig:
    """Architecture of :class:`~oasis_torchrl.models.DrivingNet`.

    Args:
        cameras: camera names, in the order the network reads them.
        image_size: ``(height, width)`` of the images (any size works: the encoder pools to a
            fixed grid; this is the size the policies resize to).
        frames: frames per camera the network sees, one chunk (4 world frames) apart: the
            last frame of each of the last ``frames`` chunks, oldest first (stacked along the
            channels). Two frames show motion: a single frame cannot tell a standing car from
            a moving one, and the speed decides whether to accelerate or brake. One chunk apart
            because that is what a policy has seen at a chunk boundary in LeRobot's per-frame
            loops (:mod:`oasis_torchrl.envs.per_frame`), and what TorchRL envs give
            (:class:`oasis_torchrl.envs.transforms.ChunkFrameStack`).
        shared_encoder: one convolutional encoder for every camera (``True``) or one per camera.
        encoder_channels: channels of the three convolutions.
        encoder_strides: strides of the three convolutions, each 1, 2 or 4: a stride of 4 is a
            4x4 patch convolution, 1 and 2 are 3x3 convolutions. The default ``(4, 2, 1)``
            reads 64x96 frames on a 16x24 then 8x12 grid; ``(2, 2, 2)`` keeps twice the
            resolution in the first two layers (an obstacle 60 m ahead is about a pixel tall
            at 64x96), at a higher cost per behaviour-cloning step.
        pool_grid: ``(rows, cols)`` the last feature map is average-pooled to; keeping a grid
            (not a global pool) keeps where things are, which steering needs.
        camera_features: features per camera after the projection.
        state_dim: length of ``"state"`` (the previous action).
        use_state: feed the state to the actor and critic. Off for behaviour cloning: actions
            change slowly, so a clone that sees the previous action learns to repeat it (the
            "copycat" shortcut, Wen et al., 2020): such a clone's actions barely depend on its
            cameras.
        hidden_dim: width of the actor and value MLPs.
        critic_inputs: extra inputs of the value head only, e.g. privileged simulator state
            for an asymmetric actor-critic (0: the critic sees what the actor sees).
        aux_outputs: numbers an auxiliary head predicts from the camera features, e.g. the
            same privileged state, as a training-only loss that shapes the encoder (0: none).
        chunk: actions per chunk.
        action_dim: numbers per action.
        head: the action distribution over a chunk: ``"tanh_normal"`` (one TanhNormal: its
            deterministic chunk answers the median of the demonstrations, straight ahead
            between a left and a right lane change) or ``"mixture"`` (``components``
            TanhNormals with observation-dependent weights; the deterministic chunk is the
            most probable component's, so the policy commits to one manoeuvre;
            :class:`~oasis_torchrl.models.distributions.TanhNormalMixture`).
        components: mixture components (``head="mixture"`` only).
        init_action: the fresh actor's mean action (after the tanh), one value per action
            number in ``[-0.99, 0.99]``, repeated over the chunk. ``(0.5, 0.0)`` starts PPO
            from scratch at half throttle, straight: with the default zero chunk a fresh car
            stands still and a run spends its first env steps learning to move.
        init_spread: mixture only: the fresh components' mean actions spread evenly from
            ``init_action - init_spread`` to ``init_action + init_spread`` (one value per action
            number), the outer ones ``e^-2`` as likely as the middle one, which the policy
            commits to. ``(0.0, 0.3)`` gives a fresh actor (and behaviour cloning's first
            steps) a keep, a left and a right manoeuvre: identical components would get
            identical gradients and stay one.
        init_scale: initial scale (before the tanh) of the action distribution, one value per
            action number (repeated over the chunk and the components): ``(0.5, 0.1)``
            explores throttle widely and steering by a tenth of a lane change, not a whole one.
        min_scale: lower bound of that scale.
        front_crop: the fraction of the front frame the ``front_crop`` camera shows (the
            ``env.front_crop`` its env must have); set exactly when ``cameras`` holds
            ``front_crop``.

    Example:
        >>> config = DrivingNetConfig(shared_encoder=False)
        >>> DrivingNetConfig.from_dict(config.to_dict()) == config
        True
    """

    cameras: tuple[str, ...] = CAMERAS
    image_size: tuple[int, int] = POLICY_IMAGE_SIZE
    frames: int = POLICY_FRAMES
    shared_encoder: bool = _SHAPE.shared_encoder
    encoder_channels: tuple[int, int, int] = tuple(_SHAPE.encoder_channels)
    encoder_strides: tuple[int, int, int] = tuple(_SHAPE.encoder_strides)
    pool_grid: tuple[int, int] = tuple(_SHAPE.pool_grid)
    camera_features: int = _SHAPE.camera_features
    state_dim: int = 2
    use_state: bool = True
    hidden_dim: int = _SHAPE.hidden_dim
    critic_inputs: int = 0
    aux_outputs: int = 0
    chunk: int = CHUNK
    action_dim: int = ACTION_DIM
    head: str = _SHAPE.head
    components: int = _SHAPE.components
    init_action: tuple[float, ...] = (0.0, 0.0)
    init_spread: tuple[float, ...] = (0.0, 0.3)
    init_scale: tuple[float, ...] = (0.5, 0.1)
    min_scale: float = 1e-3
    front_crop: float | None = None

    def __post_init__(self) -> None:
        if not self.cameras:
            raise ValueError("DrivingNetConfig.cameras must name at least one camera")
        if (FRONT_CROP in self.cameras) != (self.front_crop is not None):
            raise ValueError(
                f"DrivingNetConfig.front_crop ({self.front_crop}) is the fraction the "
                f"'{FRONT_CROP}' camera shows: set it exactly when cameras {list(self.cameras)} "
                f"hold '{FRONT_CROP}'"
            )
        if len(set(self.cameras)) != len(self.cameras):
            raise ValueError(f"DrivingNetConfig.cameras has duplicates: {list(self.cameras)}")
        if self.head not in HEADS:
            raise ValueError(f"DrivingNetConfig.head must be one of {HEADS}, got {self.head!r}")
        if len(self.init_scale) != self.action_dim:
            raise ValueError(
                f"DrivingNetConfig.init_scale needs {self.action_dim} values (one per action "
                f"number), got {list(self.init_scale)}"
            )
        for name in ("critic_inputs", "aux_outputs"):
            if getattr(self, name) < 0:
                raise ValueError(f"DrivingNetConfig.{name} must be >= 0, got {getattr(self, name)}")
        if len(self.init_action) != self.action_dim or any(
            abs(value) > MAX_INIT_ACTION for value in self.init_action
        ):
            raise ValueError(
                f"DrivingNetConfig.init_action needs {self.action_dim} values in "
                f"[-{MAX_INIT_ACTION}, {MAX_INIT_ACTION}], got {list(self.init_action)}"
            )
        if len(self.init_spread) != self.action_dim or any(
            spread < 0 or abs(action) + spread > MAX_INIT_ACTION
            for action, spread in zip(self.init_action, self.init_spread, strict=True)
        ):
            raise ValueError(
                f"DrivingNetConfig.init_spread needs {self.action_dim} values >= 0 that keep "
                f"init_action +- init_spread in [-{MAX_INIT_ACTION}, {MAX_INIT_ACTION}], got "
                f"{list(self.init_spread)} around {list(self.init_action)}"
            )
        if len(self.encoder_channels) != 3:
            raise ValueError(
                "DrivingNetConfig.encoder_channels needs 3 values, "
                f"got {list(self.encoder_channels)}"
            )
        if len(self.encoder_strides) != 3 or any(
            stride not in ENCODER_STRIDES for stride in self.encoder_strides
        ):
            raise ValueError(
                f"DrivingNetConfig.encoder_strides needs 3 values among {ENCODER_STRIDES}, "
                f"got {list(self.encoder_strides)}"
            )
        positive = {
            "image_size": self.image_size,
            "frames": (self.frames,),
            "encoder_channels": self.encoder_channels,
            "pool_grid": self.pool_grid,
            "camera_features": (self.camera_features,),
            "hidden_dim": (self.hidden_dim,),
            "chunk": (self.chunk,),
            "action_dim": (self.action_dim,),
            "components": (self.components,),
            "init_scale": self.init_scale,
            "min_scale": (self.min_scale,),
        }
        for name, values in positive.items():
            if any(value <= 0 for value in values):
                raise ValueError(f"DrivingNetConfig.{name} must be positive, got {values}")

    @property
    def mixture_components(self) -> int:
        """Components of the action distribution (1: the tanh-normal head)."""
        return self.components if self.head == MIXTURE else 1

    @property
    def features_dim(self) -> int:
        """Length of the shared feature vector: camera features plus the state."""
        return len(self.cameras) * self.camera_features + (self.state_dim if self.use_state else 0)

    def to_dict(self) -> dict[str, Any]:
        """Plain types (lists for tuples), for JSON and checkpoints."""
        return {
            key: list(value) if isinstance(value, tuple) else value
            for key, value in dataclasses.asdict(self).items()
        }

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> DrivingNetConfig:
        """Inverse of :meth:`to_dict`; unknown keys are an error naming them.

        Networks saved before the mixture head had one scale for every action number and no
        ``head`` (they are tanh-normal networks): both are read as such.

        Example:
            >>> old = DrivingNetConfig.from_dict({"init_scale": 0.5})
            >>> old.head, old.init_scale
            ('tanh_normal', (0.5, 0.5))
        """
        known = {field.name: field for field in dataclasses.fields(cls)}
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise ValueError(f"unknown DrivingNetConfig fields {unknown}; known: {sorted(known)}")
        values = {"head": TANH_NORMAL, "init_spread": [0.0] * ACTION_DIM, **values}
        if isinstance(values.get("init_scale"), (int, float)):
            values["init_scale"] = [values["init_scale"]] * values.get("action_dim", ACTION_DIM)
        return cls(
            **{
                key: tuple(value) if isinstance(value, list) else value
                for key, value in values.items()
            }
        )
