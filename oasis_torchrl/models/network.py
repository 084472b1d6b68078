"""The driving network: multi-camera encoder, action-chunk head and value head.

One definition serves both ecosystems: TorchRL PPO samples the chunk distribution and reads the
value (:mod:`oasis_torchrl.models.actor_critic`); LeRobot behaviour cloning fits the same
distribution to demonstrations (by likelihood, or by regression of the deterministic chunk) and
acts with the deterministic chunk (``policies/lerobot_policy_oasis``), which is also the
distribution's deterministic sample, so a cloned policy acts the same under PPO's evaluation.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import torch
from torch import distributions as D
from torch import nn
from torchrl.modules import TanhNormal

from oasis_torchrl.models.config import MIXTURE, DrivingNetConfig
from oasis_torchrl.models.distributions import TanhNormalMixture
from oasis_torchrl.models.encoder import MultiCameraEncoder


def _mlp(in_features: int, hidden: int, out_features: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Linear(in_features, hidden), nn.ReLU(inplace=True), nn.Linear(hidden, out_features)
    )


LOC_BOUND = 3.0
"""Bound of the chunk location before the tanh: ``tanh(3) = 0.995``, close to full throttle and
far enough from 1 for float32 log-probabilities."""
SPREAD_PRIOR = 2.0
"""A fresh mixture's outer components are ``e^-SPREAD_PRIOR`` as likely as its middle one."""
TARGET_BOUND = 0.99
"""Demonstrated actions are clamped to this for their likelihood: ``atanh(0.99) = 2.65`` is a
location the bounded head reaches (full throttle, exactly 1, would need an infinite one)."""


class DrivingNet(nn.Module):
    """Camera frames and the previous action in; an action chunk distribution and a value out.

    Images per camera are float in ``[0, 1]``, ``[*B, K, 3, H, W]`` with ``K >= frames`` frames
    one chunk apart (the last ``frames`` are used, oldest first), or ``[*B, 3, H, W]`` when
    ``frames`` is 1, or the env's uint8 frames in the same shapes with the colour last
    (``[*B, K, H, W, 3]``, :class:`~oasis_torchrl.envs.transforms.ChunkFrameStack`); the state
    is ``[*B, state_dim]``. ``features`` (shared) = camera features ++ state (if ``use_state``).
    The actor MLP gives the chunk distribution's parameters (:meth:`action_params`): ``loc``
    ``[..., 4, 2]`` (before the tanh) for the tanh-normal head; ``logits`` ``[..., K]`` and ``loc``
    ``[..., K, 4, 2]`` for the mixture head. The scale is a learned, observation-independent
    parameter of the same shape as one ``loc`` (the usual choice for PPO; behaviour cloning by
    likelihood fits it too). The critic MLP gives the value (from the features, plus
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
        >>> params = net.action_params(torch.zeros(2, net.config.features_dim))
        >>> {key: list(value.shape) for key, value in params.items()}
        {'logits': [2, 3], 'loc': [2, 3, 4, 2], 'scale': [2, 3, 4, 2]}
    """

    def __init__(self, config: DrivingNetConfig | None = None) -> None:
        super().__init__()
        self.config = config or DrivingNetConfig()
        cfg = self.config
        self.encoder = MultiCameraEncoder(cfg)
        self.components = cfg.mixture_components
        self.logit_outputs = self.components if cfg.head == MIXTURE else 0
        chunk_outputs = self.components * cfg.chunk * cfg.action_dim
        self.actor = _mlp(cfg.features_dim, cfg.hidden_dim, self.logit_outputs + chunk_outputs)
        self.critic = _mlp(cfg.features_dim + cfg.critic_inputs, cfg.hidden_dim, 1)
        camera_features = self.encoder.out_features
        self.aux = (
            _mlp(camera_features, cfg.hidden_dim, cfg.aux_outputs) if cfg.aux_outputs else None
        )
        self.log_scale = nn.Parameter(torch.empty(self._chunk_shape))
        self.set_scale(cfg.init_scale)
        # A small last actor layer starts PPO near one chunk (init_action) for every input,
        # instead of saturated tanh ends; the mixture's components around it (init_spread).
        with torch.no_grad():
            self.actor[-1].weight.mul_(0.01)
            bias = self.actor[-1].bias
            if self.components > 1:
                bias[: self.logit_outputs] = -SPREAD_PRIOR * self._spread_offsets().square()
            location = self._raw_location(self.initial_actions())
            bias[self.logit_outputs :] = location.unsqueeze(1).expand(-1, cfg.chunk, -1).flatten()

    def _spread_offsets(self) -> torch.Tensor:
        """Each component's place in ``init_spread``, ``[K]``: -1 (left) to 1 (right), evenly;
        a single component at 0."""
        if self.components == 1:
            return torch.zeros(1)
        return torch.linspace(-1.0, 1.0, self.components)

    def initial_actions(self) -> torch.Tensor:
        """A fresh network's mean action per component, ``[K, action_dim]``: ``init_action``
        spread by ``init_spread`` (left to right for the mixture's keep, left and right).

        Example:
            >>> DrivingNet(DrivingNetConfig(init_spread=(0.0, 0.3))).initial_actions()[:, 1]
            tensor([-0.3000,  0.0000,  0.3000])
        """
        cfg = self.config
        spread = self._spread_offsets().unsqueeze(1) * torch.tensor(cfg.init_spread)
        return torch.tensor([cfg.init_action]) + spread

    @property
    def _chunk_shape(self) -> tuple[int, ...]:
        """Shape of one observation's chunk locations: ``[K, chunk, action_dim]`` for the
        mixture head, ``[chunk, action_dim]`` for the tanh-normal head."""
        chunk = (self.config.chunk, self.config.action_dim)
        return (self.components, *chunk) if self.config.head == MIXTURE else chunk

    @staticmethod
    def _raw_location(action: torch.Tensor) -> torch.Tensor:
        """The actor output whose chunk location is ``atanh(action)`` (inverse of the bound)."""
        return LOC_BOUND * torch.atanh(torch.atanh(action.float()) / LOC_BOUND)

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

    def action_params(self, features: torch.Tensor) -> dict[str, torch.Tensor]:
        """The chunk distribution's parameters (the keyword arguments of
        :attr:`distribution_class`): ``loc`` before the tanh, softly bounded to
        ``(-LOC_BOUND, LOC_BOUND)``, ``scale`` broadcast to it, and for the mixture head the
        component ``logits``.

        Why bounded: demonstrations hold actions at exactly +-1 (full throttle), which push a
        clone's location far out; float32 ``atanh`` of PPO's samples there saturates near 8.4,
        so the log-probability of a stored action swings by tens of nats per small update and
        PPO's ratio overflows (non-finite fine-tuning minibatches).
        """
        raw = self.actor(features)
        loc = raw[..., self.logit_outputs :].unflatten(-1, self._chunk_shape)
        loc = LOC_BOUND * torch.tanh(loc / LOC_BOUND)
        scale = self.log_scale.exp().clamp_min(self.config.min_scale).expand_as(loc)
        if self.config.head != MIXTURE:
            return {"loc": loc, "scale": scale}
        return {"logits": raw[..., : self.logit_outputs], "loc": loc, "scale": scale}

    @property
    def distribution_class(self) -> type[D.Distribution]:
        """The chunk distribution: TorchRL's ``TanhNormal`` or :class:`TanhNormalMixture`."""
        return TanhNormalMixture if self.config.head == MIXTURE else TanhNormal

    @property
    def distribution_kwargs(self) -> dict[str, float | int]:
        """Its fixed arguments besides :meth:`action_params` (a ``[chunk, action_dim]`` event
        in ``[-1, 1]``)."""
        if self.config.head == MIXTURE:
            return {"event_dims": 2}
        return {"low": -1.0, "high": 1.0, "event_dims": 2}

    def distribution(self, features: torch.Tensor) -> D.Distribution:
        """The chunk distribution for ``features``."""
        return self.distribution_class(**self.action_params(features), **self.distribution_kwargs)

    def chunk_log_likelihood(
        self, features: torch.Tensor, target: torch.Tensor, observed: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Log-likelihood ``[...]`` of demonstrated chunks ``target`` ``[..., chunk,
        action_dim]`` (behaviour cloning by likelihood), clamped to ``TARGET_BOUND``.

        ``observed`` (bool ``[..., chunk]``) leaves out actions past an episode's end. The
        tanh-normal head is scored as a mixture of one component (the same density).
        """
        mask = None if observed is None else observed.unsqueeze(-1)
        bounded = target.clamp(-TARGET_BOUND, TARGET_BOUND)
        return self._chunk_mixture(features).log_prob(bounded, mask)

    def manoeuvre_log_likelihood(
        self, features: torch.Tensor, target: torch.Tensor, observed: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Behaviour cloning by manoeuvre: for demonstrated chunks ``target`` ``[..., chunk,
        action_dim]``, the log-density ``[...]`` of each under the component of its manoeuvre
        (:meth:`manoeuvre`), and the log-probability ``[...]`` the network gives that
        manoeuvre. Maximising both makes the components left, keep and right and the weights a
        classifier of them; the marginal likelihood (:meth:`chunk_log_likelihood`) lets the
        components split on whatever varies most (throttle) instead.

        Example:
            >>> net = DrivingNet(DrivingNetConfig(image_size=(32, 48)))
            >>> features = torch.rand(2, net.config.features_dim)
            >>> chunk, manoeuvre = net.manoeuvre_log_likelihood(features, torch.zeros(2, 4, 2))
            >>> chunk.shape, bool((manoeuvre < 0).all())
            (torch.Size([2]), True)
        """
        dist = self._chunk_mixture(features)
        mask = None if observed is None else observed.unsqueeze(-1)
        bounded = target.clamp(-TARGET_BOUND, TARGET_BOUND)
        if self.config.head != MIXTURE:  # one manoeuvre, certain
            return dist.log_prob(bounded, mask), bounded.new_zeros(bounded.shape[:-2])
        component = self.manoeuvre(target, observed)
        weight = dist.log_weights.gather(-1, component.unsqueeze(-1)).squeeze(-1)
        return dist.component_log_prob(bounded, component, mask), weight

    def _chunk_mixture(self, features: torch.Tensor) -> TanhNormalMixture:
        """The chunk distribution as a mixture (of one component for the tanh-normal head)."""
        return TanhNormalMixture.of_params(**self.action_params(features), event_dims=2)

    def manoeuvre(self, chunk: torch.Tensor, observed: torch.Tensor | None = None) -> torch.Tensor:
        """The component ``[...]`` (int) whose manoeuvre a chunk ``[..., chunk, action_dim]``
        is: the one whose initial steering (:meth:`initial_actions`) is nearest the
        chunk's mean steering over its ``observed`` actions.

        Example:
            >>> net = DrivingNet(DrivingNetConfig(components=3, init_spread=(0.0, 0.3)))
            >>> steering = torch.tensor([-0.4, -0.05, 0.2])
            >>> chunks = torch.stack([torch.zeros(3), steering], -1)[:, None].expand(3, 4, 2)
            >>> net.manoeuvre(chunks).tolist()  # left, keep, right
            [0, 1, 2]
        """
        cfg = self.config
        if self.components > 1 and cfg.init_spread[1] <= 0:
            raise ValueError(
                "manoeuvres need the mixture's components spread over steering "
                f"(DrivingNetConfig.init_spread[1] > 0), got {list(cfg.init_spread)}"
            )
        steering = chunk[..., 1]
        if observed is None:
            mean = steering.mean(-1)
        else:
            weights = observed.to(steering.dtype)
            mean = (steering * weights).sum(-1) / weights.sum(-1).clamp_min(1.0)
        anchors = self.initial_actions()[:, 1].to(mean.dtype)
        return (mean.unsqueeze(-1) - anchors).abs().argmin(-1)

    def deterministic_chunk(self, features: torch.Tensor) -> torch.Tensor:
        """The chunk ``[..., chunk, action_dim]`` the policy commits to: ``tanh(loc)`` of the
        tanh-normal head, of the most probable component for the mixture head."""
        params = self.action_params(features)
        if self.config.head != MIXTURE:
            return torch.tanh(params["loc"])
        return TanhNormalMixture(**params, event_dims=2).deterministic_sample

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
        """A copy with a critic taking ``critic_inputs`` extra inputs and an auxiliary head of
        ``aux_outputs`` (encoder, actor and scale kept), e.g. to fine-tune a cloned policy with
        privileged state, or ``(0, 0)`` to deploy it. A head whose size changes starts afresh;
        one whose size stays keeps its weights (a clone's auxiliary head goes on into PPO).

        Example:
            >>> clone = DrivingNet(DrivingNetConfig(aux_outputs=6))
            >>> tuned = clone.with_training_heads(6, 6)
            >>> torch.equal(tuned.aux[0].weight, clone.aux[0].weight)
            True
        """
        config = dataclasses.replace(
            self.config, critic_inputs=critic_inputs, aux_outputs=aux_outputs
        )
        net = DrivingNet(config)
        net.warm_start(self)
        return net

    def warm_start(self, other: DrivingNet) -> None:
        """Go on from ``other``: its encoder, actor and scale (what acts), which must share this
        network's architecture, and each training-only head (critic, auxiliary) of the same
        size here (a DAgger round keeps the auxiliary head its previous round trained); a head
        of another size keeps this network's weights.

        Example:
            >>> net, trained = DrivingNet(DrivingNetConfig(aux_outputs=6)), DrivingNet(
            ...     DrivingNetConfig(aux_outputs=6))
            >>> net.warm_start(trained)
            >>> torch.equal(net.aux[0].weight, trained.aux[0].weight)
            True
        """
        sizes = (
            ("critic.", self.config.critic_inputs, other.config.critic_inputs),
            ("aux.", self.config.aux_outputs, other.config.aux_outputs),
        )
        resized = tuple(head for head, size, other_size in sizes if size != other_size)
        same_sized = {k: v for k, v in other.state_dict().items() if not k.startswith(resized)}
        try:
            missing, _ = self.load_state_dict(same_sized, strict=False)
        except RuntimeError as error:
            raise ValueError(f"the networks' acting parts differ: {error}") from error
        unexpected = [key for key in missing if not key.startswith(resized)]
        if unexpected:
            raise ValueError(f"the source network lacks {unexpected}")

    def forward(self, images: Sequence[torch.Tensor], state: torch.Tensor) -> torch.Tensor:
        """The deterministic chunk ``[..., chunk, action_dim]`` in ``[-1, 1]``
        (:meth:`deterministic_chunk`)."""
        return self.deterministic_chunk(self.features(images, state))

    def pool_scale_gradients(self) -> torch.utils.hooks.RemovableHandle:
        """Make the action scale learn as one value per action number: its gradient is averaged
        over the chunk's steps (and the mixture's components) before the optimiser sees it, so
        entries that start equal move together and unequal ones keep their ratios.

        Why: each entry's policy gradient is one sample's noise against the return, a weak
        signal that Adam turns into a random walk; pooled, each value learns from every action
        number of a kind in the chunk (12 per sample with the mixture's defaults).

        Example:
            >>> net = DrivingNet(DrivingNetConfig())
            >>> handle = net.pool_scale_gradients()
            >>> net.log_scale[0, 0].sum().backward()  # one entry per action number gets gradient
            >>> net.log_scale.grad[..., 0].unique().tolist()
            [0.0833333358168602]
        """
        dims = tuple(range(self.log_scale.dim() - 1))
        return self.log_scale.register_hook(
            lambda grad: grad.mean(dims, keepdim=True).expand_as(grad)
        )

    @torch.no_grad()
    def set_scale(self, scale: float | Sequence[float]) -> None:
        """Reset the action distribution's scale (e.g. before PPO fine-tuning of a BC policy):
        one value, or one per action number.

        Example:
            >>> net = DrivingNet(DrivingNetConfig(head="tanh_normal"))
            >>> net.set_scale([0.4, 0.1])
            >>> [round(value, 3) for value in net.log_scale.exp()[0].tolist()]
            [0.4, 0.1]
        """
        values = torch.as_tensor(scale, dtype=self.log_scale.dtype)
        if (values <= 0).any() or values.numel() not in (1, self.config.action_dim):
            raise ValueError(
                f"scale must be positive, one value or {self.config.action_dim}, got {scale}"
            )
        self.log_scale.copy_(values.log().expand_as(self.log_scale))
