"""The oasis driving policy as a LeRobot ``PreTrainedPolicy`` (behaviour cloning).

The network is :class:`oasis_torchrl.models.DrivingNet`, the one TorchRL PPO trains; this class
only adapts LeRobot batches to it: ``forward`` returns the behaviour-cloning loss against the
next ``chunk_size`` actions (padded actions past an episode's end are masked out): their
negative log-likelihood under the network's chunk distribution (a mixture: the clone keeps each
manoeuvre and commits to one);
``predict_action_chunk`` returns the chunk the policy commits to and ``select_action`` serves it
one action at a time from a queue.

Batches carry ``n_obs_steps`` frames per camera, ``FRAME_SPACING`` rows apart
(``[B, n_obs_steps, 3, H, W]``, LeRobot's observation delta indices) and states
``[B, n_obs_steps, 2]`` (the last one is used). ``select_action`` gets one observation per
call, as an env or robot gives it, and keeps the observations of the last
``(n_obs_steps - 1) * FRAME_SPACING + 1`` calls itself to pick the same spacing (the first
observation after a reset fills the history).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
from typing import Any

import torch
from lerobot.policies.pretrained import PreTrainedPolicy
from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE
from torch import Tensor, nn

from lerobot_policy_oasis.configuration_oasis import FRAME_SPACING, POLICY_TYPE, OasisConfig
from oasis_torchrl.data.features import image_key
from oasis_torchrl.models import DrivingNet
from oasis_torchrl.models.privileged import PRIVILEGED_FIELDS, PRIVILEGED_KEY
from oasis_torchrl.protocol import FRONT_CROP

ACTION_IS_PAD = f"{ACTION}_is_pad"


class OasisPolicy(PreTrainedPolicy):
    """Multi-camera action-chunk driving policy.

    Args:
        config: the policy configuration, with its input and output features set (LeRobot's
            ``make_policy`` sets them from a dataset).
        **kwargs: what LeRobot's factory also passes (``dataset_stats``, ``dataset_meta``);
            unused, normalisation is the processors' job.

    Example:
        >>> from lerobot.configs.types import FeatureType, PolicyFeature
        >>> features = {f"observation.images.{c}": PolicyFeature(FeatureType.VISUAL, (3, 64, 96))
        ...             for c in ("left_forward", "front", "right_forward")}
        >>> features["observation.state"] = PolicyFeature(FeatureType.STATE, (2,))
        >>> action = {"action": PolicyFeature(FeatureType.ACTION, (2,))}
        >>> config = OasisConfig(device="cpu", input_features=features, output_features=action)
        >>> policy = OasisPolicy(config)
        >>> observation = {key: torch.rand(1, *ft.shape) for key, ft in features.items()}
        >>> policy.select_action(observation).shape
        torch.Size([1, 2])
        >>> frames = {key: torch.stack([v, v], dim=1) for key, v in observation.items()}
        >>> policy.predict_action_chunk(frames).shape
        torch.Size([1, 4, 2])
    """

    config_class = OasisConfig
    name = POLICY_TYPE

    def __init__(self, config: OasisConfig, **kwargs: Any) -> None:
        super().__init__(config)
        self.config: OasisConfig = config
        self.model = DrivingNet(config.net_config())
        self._image_keys = [f"{OBS_IMAGES}.{camera}" for camera in self.model.config.cameras]
        self._queue: deque[Tensor] = deque(maxlen=config.n_action_steps)
        self._history: dict[str, deque[Tensor]] = {}

    def get_optim_params(self) -> Iterator[nn.Parameter]:
        """The parameters behaviour cloning trains: the encoder, the actor, the distribution's
        scale and, with ``aux_weight``, the auxiliary head."""
        yield from self.model.encoder.parameters()
        yield from self.model.actor.parameters()
        yield self.model.log_scale
        if self.model.aux is not None:
            yield from self.model.aux.parameters()

    def reset(self) -> None:
        """Drop queued actions and past observations (call at every episode start)."""
        self._queue.clear()
        self._history = {}

    def _get(self, batch: dict[str, Any], key: str) -> Tensor:
        if key not in batch:
            hint = (
                f": turn the env's narrow forward camera on (--env.front_crop="
                f"{self.config.front_crop} in lerobot-eval, --robot.front_crop in lerobot-record)"
                if key == image_key(FRONT_CROP)
                else ""
            )
            raise KeyError(
                f"the oasis policy needs batch[{key!r}]; the batch has {sorted(batch)}{hint}"
            )
        return batch[key]

    def _features(self, batch: dict[str, Any]) -> Tensor:
        images = [self._get(batch, key) for key in self._image_keys]
        state = self._get(batch, OBS_STATE)
        return self.model.features(images, state[:, -1] if state.dim() == 3 else state)

    def _remember(self, observation: dict[str, Tensor]) -> dict[str, Tensor]:
        """Add one observation to the history; ``n_obs_steps`` of them ``FRAME_SPACING`` calls
        apart, the newest last, stacked on dim 1."""
        length = (self.config.n_obs_steps - 1) * FRAME_SPACING + 1
        stacked = {}
        for key in [*self._image_keys, OBS_STATE]:
            value = self._get(observation, key)
            history = self._history.setdefault(key, deque(maxlen=length))
            if not history:
                history.extend([value] * (length - 1))
            history.append(value)
            stacked[key] = torch.stack(list(history)[::FRAME_SPACING], dim=1)
        return stacked

    @torch.no_grad()
    def predict_action_chunk(self, batch: dict[str, Tensor], **kwargs: Any) -> Tensor:
        """The chunk ``[B, chunk_size, 2]`` the policy commits to for a batch of
        (preprocessed) observations."""
        return self.model.deterministic_chunk(self._features(batch))

    @torch.no_grad()
    def select_action(self, batch: dict[str, Tensor], **kwargs: Any) -> Tensor:
        """The next action ``[B, 2]`` for one observation (``[B, 3, H, W]`` frames, ``[B, 2]``
        state): a new chunk when the queue is empty, else the next queued action."""
        frames = self._remember(batch)
        if not self._queue:
            chunk = self.predict_action_chunk(frames)[:, : self.config.n_action_steps]
            self._queue.extend(chunk.transpose(0, 1))
        return self._queue.popleft()

    def forward(
        self, batch: dict[str, Tensor], reduction: str = "mean"
    ) -> tuple[Tensor, dict[str, float]]:
        """Behaviour-cloning loss of the chunk vs ``batch["action"]`` ``[B, chunk_size, 2]``
        (``config.loss``), per action (padded actions past an episode's end left out).

        ``reduction="none"`` returns the per-sample loss ``[B]`` (LeRobot's weighted BC).
        """
        if reduction not in ("mean", "none"):
            raise ValueError(f"reduction must be 'mean' or 'none', got {reduction!r}")
        target = self._get(batch, ACTION)
        expected = (target.shape[0], self.config.chunk_size, self.model.config.action_dim)
        if tuple(target.shape) != expected:
            raise ValueError(
                f"batch[{ACTION!r}] must be [B, {self.config.chunk_size}, 2] (set the dataset's "
                f"delta timestamps from config.action_delta_indices), got {list(target.shape)}"
            )
        pad = batch.get(ACTION_IS_PAD)
        valid = torch.ones_like(target[..., 0]) if pad is None else (~pad).to(target.dtype)
        features = self._features(batch)
        numbers = valid.sum(-1).clamp_min(1.0) * target.shape[-1]
        if self.config.loss == "nll":
            log_likelihood = self.model.chunk_log_likelihood(features, target, valid.bool())
            per_sample = -log_likelihood / numbers
        else:  # the chunk per number, its manoeuvre once per sample (a classification)
            chunk, manoeuvre = self.model.manoeuvre_log_likelihood(features, target, valid.bool())
            per_sample = -chunk / numbers - manoeuvre
        info = {f"{self.config.loss}_loss": per_sample.mean().item()}
        if self.config.aux_weight:
            aux = self._aux_loss(batch, features)
            per_sample = per_sample + self.config.aux_weight * aux
            info["aux_loss"] = aux.mean().item()
        loss = per_sample if reduction == "none" else per_sample.mean()
        return loss, info

    def _aux_loss(self, batch: dict[str, Tensor], features: Tensor) -> Tensor:
        """Per-sample mean squared error of the auxiliary head against ``privileged_state``."""
        target = batch.get(PRIVILEGED_KEY)
        if target is None:
            raise KeyError(
                f"aux_weight={self.config.aux_weight} needs batch[{PRIVILEGED_KEY!r}]: a dataset "
                "that stores the privileged state (the pipeline's demonstrations do), trained "
                "with oasis-torchrl train bc (LeRobot's processors drop columns they do not "
                "know), or aux_weight=0"
            )
        predicted = self.model.predict_aux(features)
        if target.shape[-1] != predicted.shape[-1]:
            raise ValueError(
                f"the dataset's {PRIVILEGED_KEY} has {target.shape[-1]} numbers per frame, the "
                f"auxiliary head predicts {predicted.shape[-1]} ({', '.join(PRIVILEGED_FIELDS)}): "
                "record the dataset again with this version, or train with aux_weight=0"
            )
        return (predicted - target.to(features.dtype)).square().mean(-1)
