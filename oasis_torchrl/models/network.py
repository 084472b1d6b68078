"""The driving network: multi-camera encoder, action-chunk head and value head.

One definition serves both ecosystems: TorchRL PPO reads ``loc``/``scale`` of a TanhNormal over
the chunk and the value (:mod:`oasis_torchrl.models.actor_critic`); LeRobot behaviour cloning
reads the deterministic chunk ``tanh(loc)`` (``policies/lerobot_policy_oasis``), which is also the
TanhNormal's deterministic sample, so a cloned policy acts the same under PPO's evaluation.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import torch
from torch import nn

from oasis_torchrl.models.config import DrivingNetConfig
from oasis_torchrl.models.encoder import MultiCameraEncoder


def _mlp(in_features: int, hidden: int, out_features: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Linear(in_features, hidden), nn.ReLU(inplace=True), nn.Linear(hidden, out_features)
    )


LOC_BOUND = 3.0
"""Bound of the chunk location before the tanh: ``tanh(3) = 0.995``, close to full throttle and
far enough from 1 for float32 log-probabilities."""


class DrivingNet(nn.Module):
    """Camera frames and the previous action in; an action chunk distribution and a value out.

    Images per camera are float in ``[0, 1]``, ``[*B, K, 3, H, W]`` with ``K >= frames`` (the
    last ``frames`` are used, oldest first), or ``[*B, 3, H, W]`` when ``frames`` is 1, or the
    env's uint8 frames in the same shapes with the colour last (``[*B, K, H, W, 3]``); the state
    is ``[*B, state_dim]``. ``features`` (shared) = camera features ++ state (if ``use_state``).
    The actor MLP gives ``loc`` ``[..., 4, 2]`` (before the tanh); the scale is a learned,
    observation-independent ``[4, 2]`` parameter (the usual choice for PPO; behaviour cloning
    leaves it untouched). The critic MLP gives the value (from the features, plus
    ``critic_inputs`` extra numbers when configured: an asymmetric actor-critic whose critic may
    use privileged simulator state). With ``aux_outputs``, an auxiliary head predicts that many
    numbers from the camera features (a training-only loss; see :meth:`predict_aux`).

    Example:
        >>> net = DrivingNet(DrivingNetConfig(image_size=(32, 48), frames=2))
        >>> images = [torch.rand(2, 2, 3, 32, 48) for _ in net.config.cameras]
        >>> chunk = net(images, torch.zeros(2, 2))
        >>> chunk.shape, bool(chunk.abs().max() < 1)
        (torch.Size([2, 4, 2]), True)
        >>> net.value(net.features(images, torch.zeros(2, 2))).shape
        torch.Size([2, 1])
    """

    def __init__(self, config: DrivingNetConfig | None = None) -> None:
        super().__init__()
        self.config = config or DrivingNetConfig()
        cfg = self.config
        self.encoder = MultiCameraEncoder(cfg)
        self.actor = _mlp(cfg.features_dim, cfg.hidden_dim, cfg.chunk * cfg.action_dim)
        self.critic = _mlp(cfg.features_dim + cfg.critic_inputs, cfg.hidden_dim, 1)
        camera_features = self.encoder.out_features
        self.aux = (
            _mlp(camera_features, cfg.hidden_dim, cfg.aux_outputs) if cfg.aux_outputs else None
        )
        self.log_scale = nn.Parameter(torch.empty(cfg.chunk, cfg.action_dim))
        self.set_scale(cfg.init_scale)
        # A small last actor layer starts PPO near one chunk (init_action) for every input,
        # instead of saturated tanh ends.
        with torch.no_grad():
            self.actor[-1].weight.mul_(0.01)
            self.actor[-1].bias.copy_(self._raw_location(cfg.init_action).repeat(cfg.chunk))

    @staticmethod
    def _raw_location(action: Sequence[float]) -> torch.Tensor:
        """The actor output whose chunk location is ``atanh(action)`` (inverse of the bound)."""
        loc = torch.atanh(torch.tensor(action, dtype=torch.float32))
        return LOC_BOUND * torch.atanh(loc / LOC_BOUND)

    def features(self, images: Sequence[torch.Tensor], state: torch.Tensor) -> torch.Tensor:
        """Shared features ``[..., features_dim]`` from each camera's frames and the state."""
        if state.shape[-1] != self.config.state_dim:
            raise ValueError(
                f"state must end in {self.config.state_dim} values, got {list(state.shape)}"
            )
        frames = [self.last_frames(image, state.dim() - 1) for image in images]
        encoded = self.encoder(frames)
        if not self.config.use_state:
            return encoded
        return torch.cat([encoded, state.to(encoded.dtype)], dim=-1)

    def last_frames(self, image: torch.Tensor, batch_dims: int) -> torch.Tensor:
        """The last ``frames`` of a camera's frames, ``[*B, K, ...]`` with three image
        dimensions (``3, H, W`` or the env's ``H, W, 3``) -> ``[*B, frames, ...]``; a single
        frame ``[*B, ...]`` gets its time axis."""
        wanted = self.config.frames
        if image.dim() == batch_dims + 3:  # a single frame, no time axis
            image = image.unsqueeze(-4)
        if image.dim() != batch_dims + 4 or image.shape[-4] < wanted:
            raise ValueError(
                f"camera frames must be [*B, >={wanted}, 3, H, W] (or H, W, 3) with "
                f"{batch_dims} batch dims (or one frame [*B, 3, H, W] when frames is 1), "
                f"got {list(image.shape)}"
            )
        return image[..., -wanted:, :, :, :]

    def action_loc(self, features: torch.Tensor) -> torch.Tensor:
        """Location ``[..., chunk, action_dim]`` of the chunk distribution, before the tanh,
        softly bounded to ``(-LOC_BOUND, LOC_BOUND)``.

        Why bounded: demonstrations hold actions at exactly +-1 (full throttle), which push a
        clone's location far out; float32 ``atanh`` of PPO's samples there saturates near 8.4,
        so the log-probability of a stored action swings by tens of nats per small update and
        PPO's ratio overflows (measured: 15 of 16 fine-tuning minibatches non-finite).
        """
        raw = self.actor(features).unflatten(-1, (self.config.chunk, self.config.action_dim))
        return LOC_BOUND * torch.tanh(raw / LOC_BOUND)

    def action_scale(self, loc: torch.Tensor) -> torch.Tensor:
        """Scale of the chunk distribution, broadcast to ``loc``'s shape."""
        scale = self.log_scale.exp().clamp_min(self.config.min_scale)
        return scale.expand_as(loc)

    def value(self, features: torch.Tensor, extra: torch.Tensor | None = None) -> torch.Tensor:
        """State value ``[..., 1]`` (``extra``: the ``critic_inputs`` numbers, if configured)."""
        wanted = self.config.critic_inputs
        if (extra is None) != (wanted == 0) or (extra is not None and extra.shape[-1] != wanted):
            got = None if extra is None else list(extra.shape)
            raise ValueError(f"the critic takes {wanted} extra inputs, got {got}")
        return self.critic(features if extra is None else torch.cat([features, extra], dim=-1))

    def predict_aux(self, features: torch.Tensor) -> torch.Tensor:
        """The auxiliary head's ``[..., aux_outputs]`` from the shared features (it reads their
        camera part only, so its loss shapes the encoder)."""
        if self.aux is None:
            raise ValueError("this network has no auxiliary head (DrivingNetConfig.aux_outputs=0)")
        return self.aux(features[..., : self.encoder.out_features])

    def with_training_heads(self, critic_inputs: int, aux_outputs: int) -> DrivingNet:
        """A copy with fresh training-only heads, a critic taking ``critic_inputs`` extra
        inputs and an auxiliary head of ``aux_outputs`` (encoder, actor and scale kept), e.g.
        to fine-tune a cloned policy with privileged state, or ``(0, 0)`` to deploy it."""
        config = dataclasses.replace(
            self.config, critic_inputs=critic_inputs, aux_outputs=aux_outputs
        )
        net = DrivingNet(config)
        net.load_policy_weights(self)
        return net

    def load_policy_weights(self, other: DrivingNet) -> None:
        """Copy ``other``'s encoder, actor and scale (what acts) into this network; the
        training-only heads (critic, auxiliary) are kept. Both must share the architecture of
        the acting parts."""
        training_only = ("critic.", "aux.")
        acting = {k: v for k, v in other.state_dict().items() if not k.startswith(training_only)}
        try:
            missing, _ = self.load_state_dict(acting, strict=False)
        except RuntimeError as error:
            raise ValueError(f"the networks' acting parts differ: {error}") from error
        unexpected = [key for key in missing if not key.startswith(training_only)]
        if unexpected:
            raise ValueError(f"the source network lacks {unexpected}")

    def forward(self, images: Sequence[torch.Tensor], state: torch.Tensor) -> torch.Tensor:
        """The deterministic chunk ``tanh(loc)`` ``[..., chunk, action_dim]`` in ``[-1, 1]``."""
        return torch.tanh(self.action_loc(self.features(images, state)))

    @torch.no_grad()
    def set_scale(self, scale: float) -> None:
        """Reset the action distribution's scale (e.g. before PPO fine-tuning of a BC policy)."""
        if scale <= 0:
            raise ValueError(f"scale must be positive, got {scale}")
        self.log_scale.fill_(math.log(scale))
