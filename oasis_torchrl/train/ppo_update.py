"""PPO's update of a :class:`~oasis_torchrl.models.DrivingNet` on collected batches, env-free.

:class:`PPOUpdate` owns what turns a batch of env steps into new weights: GAE advantages,
:class:`~oasis_torchrl.train.ppo_loss.DrivingPPOLoss` over shuffled minibatches for a few epochs,
Adam with three learning-rate groups annealed over the run, gradient clipping, the skipping of
non-finite steps, and the auxiliary replay (:mod:`~oasis_torchrl.train.aux_replay`). It knows
nothing of envs, evaluation or files, so the camera trainer
(:class:`~oasis_torchrl.train.ppo.PPOTrainer`) and any other collection loop update alike.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from typing import Any

import torch
from omegaconf import DictConfig
from tensordict import TensorDictBase
from torchrl.objectives.value import GAE

from oasis_torchrl.models import ActorCritic
from oasis_torchrl.protocol import ACTION_NAMES
from oasis_torchrl.train.aux_replay import AuxiliaryReplay
from oasis_torchrl.train.ppo_loss import AUX_TERM, PPO_TERMS, DrivingPPOLoss

logger = logging.getLogger(__name__)

LOGGED_LOSS_KEYS = (
    *PPO_TERMS,
    AUX_TERM,
    "entropy",
    "kl_approx",
    "clip_fraction",
    "explained_variance",
)


class PPOUpdate:
    """The PPO update of ``modules`` per :class:`~oasis_torchrl.config.PPOSettings` (its
    ``loss``, ``optim`` and ``aux_replay`` sections).

    Args:
        modules: the actor-critic modules of the network (:func:`make_actor_critic`).
        cfg: the PPO settings.
        anneal_frames: env steps over which the learning rates anneal (the run's, or the
            longer schedule it is the start of: ``optim.anneal_frames``).

    Raises:
        ValueError: an auxiliary replay without an auxiliary loss.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> from oasis_torchrl.models import DrivingNet, make_actor_critic
        >>> update = PPOUpdate(make_actor_critic(DrivingNet()), load_config("ppo"), 20480)
        >>> [group["lr"] for group in update.optimizer.param_groups]
        [0.0003, 0.001, 0.01]
        >>> metrics = update(batch, frames=512)  # doctest: +SKIP
    """

    def __init__(self, modules: ActorCritic, cfg: DictConfig, anneal_frames: int) -> None:
        self.cfg = cfg
        self.anneal_frames = anneal_frames
        self.net = modules.net
        if cfg.optim.pool_scale:
            self.net.pool_scale_gradients()
        self.loss = DrivingPPOLoss(
            modules,
            aux_coeff=cfg.loss.aux_coeff,
            clip_epsilon=cfg.loss.clip_epsilon,
            entropy_coeff=cfg.loss.entropy_coeff,
            critic_coeff=cfg.loss.critic_coeff,
            loss_critic_type=cfg.loss.loss_critic_type,
            normalize_advantage=True,
        )
        # Without vmap the critic runs on the batch and on its next observations as two plain
        # calls: under vmap the encoder's input preparation was a third of an update's time.
        self.advantage = GAE(
            gamma=cfg.loss.gamma,
            lmbda=cfg.loss.lmbda,
            value_network=modules.value,
            deactivate_vmap=True,
        )
        self.optimizer = torch.optim.Adam(
            self._param_groups(), lr=cfg.optim.lr, weight_decay=cfg.optim.weight_decay
        )
        self._anneal(0)
        replay = cfg.aux_replay
        self.aux_replay = (
            AuxiliaryReplay(self.loss, replay.capacity, replay.mini_batch_size)
            if replay.capacity
            else None
        )

    def _param_groups(self) -> list[dict[str, Any]]:
        """Three groups: the acting parts (encoder, actor) at ``optim.lr``; the fresh heads
        (critic, auxiliary) at ``optim.critic_lr``; the action scale at ``optim.scale_lr``
        (``null``: ``optim.lr``).

        Why the heads: a fresh critic on a warm-started encoder (whose features are small)
        moves too slowly at the actor's fine-tuning rate and explains less of the returns'
        variance; PPO's advantages are only as good as that fit
        (docs/experiments/2026-11-24-what-shapes-ppo.md).

        Why the scale: its policy gradient is a weak, noisy signal (whether samples far from
        the mean did worse), so at the actor's rate Adam moves it by little more than a random
        walk, and PPO's scale stays near its initial value. With the scale pooled per action
        number (``optim.pool_scale``) and its own rate, a fine-tuned clone cuts its steering
        scale and keeps its throttle scale
        (docs/experiments/2026-11-26-exploration-that-shrinks.md).
        """
        heads = [self.net.critic] + ([self.net.aux] if self.net.aux is not None else [])
        head_ids = {id(parameter) for head in heads for parameter in head.parameters()}
        scale_id = id(self.net.log_scale)
        parameters = list(self.loss.parameters())
        return [
            {"params": [p for p in parameters if id(p) not in head_ids and id(p) != scale_id]},
            {"params": [p for p in parameters if id(p) in head_ids]},
            {"params": [self.net.log_scale]},
        ]

    def _base_lrs(self) -> tuple[float, float, float]:
        """The un-annealed learning rates of the parameter groups (acting parts, heads,
        scale)."""
        optim = self.cfg.optim
        critic_lr = optim.lr if optim.critic_lr is None else optim.critic_lr
        return optim.lr, critic_lr, optim.lr if optim.scale_lr is None else optim.scale_lr

    def __call__(
        self, batch: TensorDictBase, frames: int, critic_only: bool = False
    ) -> dict[str, float]:
        """Update on ``batch`` (``[rows, time]`` as collected) after ``frames`` env steps of the
        run: advantages, then ``optim.epochs`` passes of minibatch PPO steps (only the critic's
        loss with ``critic_only``), then the auxiliary replay's steps. The mean losses and
        diagnostics."""
        factor = self._anneal(frames)
        with torch.no_grad():
            batch = self.advantage(batch)
        flat = batch.exclude("next").reshape(-1)  # the loss reads no next observation
        sums: dict[str, float] = {}
        updates = skipped = 0
        for minibatch in self._minibatches(flat):
            losses = self.loss(minibatch)
            terms = ("loss_critic",) if critic_only else self.loss.terms
            grad_norm = self._step(sum(losses[key] for key in terms), critic_only)
            if grad_norm is None:
                skipped += 1
                continue
            updates += 1
            sums["optim/grad_norm"] = sums.get("optim/grad_norm", 0.0) + grad_norm
            for key in LOGGED_LOSS_KEYS:
                if key in losses.keys():
                    name = f"loss/{key}"
                    sums[name] = sums.get(name, 0.0) + losses[key].mean().item()
        if skipped:
            # Near-saturated tanh actions (a fine-tuned clone's) can give an infinite ratio or
            # gradient; one such step turns every weight into NaN, so it is left out, as AMP
            # skips steps with non-finite gradients.
            logger.warning("%d minibatches with a non-finite loss or gradient skipped", skipped)
        metrics = {key: value / max(updates, 1) for key, value in sums.items()}
        if self.aux_replay is not None and not critic_only:
            metrics.update(self._replay_aux(flat))
        metrics["optim/skipped_minibatches"] = float(skipped)
        metrics["optim/updates"] = float(updates)
        metrics["optim/lr"] = self.cfg.optim.lr * factor
        metrics.update(self.scale_metrics())
        return metrics

    def _anneal(self, frames: int) -> float:
        """Set the learning rates for ``frames`` env steps into the run (linear decay to 5%);
        the decay factor."""
        factor = 1.0
        if self.cfg.optim.anneal_lr:
            factor = max(1.0 - frames / self.anneal_frames, 0.05)
        for group, base_lr in zip(self.optimizer.param_groups, self._base_lrs(), strict=True):
            group["lr"] = base_lr * factor
        return factor

    def _minibatches(self, flat: TensorDictBase) -> Iterator[TensorDictBase]:
        """``optim.epochs`` shuffled passes over ``flat`` in ``optim.mini_batch_size`` pieces."""
        for _ in range(self.cfg.optim.epochs):
            for index in torch.randperm(flat.numel()).split(self.cfg.optim.mini_batch_size):
                yield flat[index]

    def _step(self, total: torch.Tensor, critic_only: bool = False) -> float | None:
        """One optimizer step on the summed loss; the gradient norm, or ``None`` when the loss or
        gradient is not finite (the step is skipped)."""
        if not torch.isfinite(total):
            return None
        self.optimizer.zero_grad(set_to_none=True)
        total.backward()
        if critic_only:  # the encoder is the actor's too: warm up the critic head only
            self.net.encoder.zero_grad(set_to_none=True)
        grad_norm = torch.nn.utils.clip_grad_norm_(
            self.loss.parameters(), self.cfg.optim.max_grad_norm
        )
        if not torch.isfinite(grad_norm):
            return None
        self.optimizer.step()
        return float(grad_norm)

    def _replay_aux(self, flat: TensorDictBase) -> dict[str, float]:
        """Add the batch to the auxiliary replay, then ``aux_replay.steps`` auxiliary-only
        steps on minibatches drawn from it; their mean loss and the replay's size."""
        replay = self.aux_replay
        replay.extend(flat)
        values = []
        for _ in range(self.cfg.aux_replay.steps):
            loss = replay.loss()
            if self._step(loss) is not None:
                values.append(loss.item())
        mean = sum(values) / len(values) if values else float("nan")
        return {"loss/aux_replay": mean, "optim/aux_replay_rows": float(len(replay))}

    def scale_metrics(self) -> dict[str, float]:
        """The action scale's mean per action number (over chunk and components)."""
        scale = self.net.log_scale.detach().exp().reshape(-1, self.net.config.action_dim)
        means = zip(ACTION_NAMES, scale.mean(0).tolist(), strict=True)
        return {f"policy/scale_{name}": value for name, value in means}
