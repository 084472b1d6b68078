"""PPO on :class:`~oasis_torchrl.envs.OasisEnv`, the TorchRL recipe.

A :class:`~torchrl.collectors.Collector` steps the batched env with the stochastic actor (a
distribution over the 4-action chunk, its noise drawn afresh every chunk or held over several:
:mod:`oasis_torchrl.train.exploration`); :class:`~torchrl.objectives.value.GAE` computes advantages
with the critic; :class:`~torchrl.objectives.ClipPPOLoss` trains both (shared encoder, run once
per minibatch: :mod:`oasis_torchrl.train.ppo_loss`) for a few epochs of minibatches per batch.
Around that: TorchRL loggers (CSV or TensorBoard), a tqdm bar, checkpoints with resume,
periodic deterministic evaluation episodes (recorded to rerun and/or a LeRobot dataset when
configured; on ``eval.selection_seeds``, if set, they choose the policy the run keeps: early
stopping that never looks at the seeds reported at the end), a warm start from a
behaviour-cloning policy, and the kept policy exported as a LeRobot policy folder. Config:
:class:`~oasis_torchrl.config.PPOConfig`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDictBase
from torchrl.collectors import Collector
from torchrl.objectives.value import GAE
from torchrl.record.loggers import Logger, get_logger
from tqdm import tqdm

from oasis_torchrl.config import save_config, section
from oasis_torchrl.drivers.folders import export_lerobot, load_net
from oasis_torchrl.envs.factory import make_env
from oasis_torchrl.envs.transforms import PRIVILEGED_FIELDS, ChunkFrameStack
from oasis_torchrl.models import DrivingNet, DrivingNetConfig, make_actor_critic
from oasis_torchrl.models.checkpoint import (
    BEST,
    LATEST,
    load_checkpoint,
    net_from_checkpoint,
    save_checkpoint,
)
from oasis_torchrl.protocol import ACTION_NAMES
from oasis_torchrl.train.aux_replay import AuxiliaryReplay
from oasis_torchrl.train.evaluate import EvalReport, Evaluator, beats
from oasis_torchrl.train.exploration import HeldNoisePolicy
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


@dataclass
class PPOResult:
    """What a PPO run leaves: the trained network, its files and its evaluation history.

    Example:
        >>> result = train_ppo(load_config("ppo"))  # doctest: +SKIP
        >>> result.history[-1]["mean_distance"]  # doctest: +SKIP
    """

    net: DrivingNet
    checkpoint: Path
    policy_dir: Path | None
    final_eval: EvalReport | None
    history: list[dict[str, Any]] = field(default_factory=list)


def build_net(cfg: DictConfig, cameras: tuple[str, ...]) -> DrivingNet:
    """A fresh network from ``cfg.network``, or the ``cfg.init_from`` one with its scale reset
    to ``cfg.warm_start_scale`` (one value or one per action number; null keeps the source's);
    with ``cfg.privileged_critic``, its critic also reads the env's ``"critic_inputs"``; with
    ``cfg.loss.aux_coeff``, an auxiliary head predicts them from the camera features.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> net = build_net(load_config("ppo"), ("left_forward", "front", "right_forward"))
        >>> net.config.image_size
        (64, 96)
    """
    image_size = tuple(int(size) for size in cfg.env.image_size)
    if cfg.init_from:
        net = load_net(cfg.init_from)
        if cfg.warm_start_scale is not None:
            net.set_scale(OmegaConf.to_object(cfg.warm_start_scale))
        logger.info("warm start from %s (scale %s)", cfg.init_from, cfg.warm_start_scale)
    else:
        network = OmegaConf.to_container(cfg.network)
        config = {"cameras": cameras, "image_size": image_size, **network}
        net = DrivingNet(DrivingNetConfig.from_dict(config))
    critic_inputs = len(PRIVILEGED_FIELDS) if cfg.privileged_critic else 0
    aux_outputs = len(PRIVILEGED_FIELDS) if cfg.loss.aux_coeff else 0
    if (net.config.critic_inputs, net.config.aux_outputs) != (critic_inputs, aux_outputs):
        net = net.with_training_heads(critic_inputs, aux_outputs)
    if net.config.cameras != cameras or tuple(net.config.image_size) != image_size:
        raise ValueError(
            f"the network reads cameras {net.config.cameras} at {net.config.image_size}, the env "
            f"gives {cameras} at {image_size}: set env.image_size to the network's size"
        )
    return net


def uses_ground_truth(cfg: DictConfig) -> bool:
    """Whether the run reads the simulator's privileged state (critic inputs or auxiliary
    targets), which only the embedded server sends.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> uses_ground_truth(load_config("ppo", ["privileged_critic=false", "loss.aux_coeff=0"]))
        False
    """
    return bool(cfg.privileged_critic or cfg.loss.aux_coeff)


def episode_stats(batch: TensorDictBase) -> dict[str, float]:
    """Mean return, distance and collision rate of the episodes that ended in ``batch``.

    Example:
        >>> from tensordict import TensorDict
        >>> batch = TensorDict({"next": {"done": torch.tensor([[[False], [True]]]),
        ...     "terminated": torch.tensor([[[False], [True]]]),
        ...     "episode_reward": torch.tensor([[[1.0], [2.0]]])}}, batch_size=[1, 2])
        >>> episode_stats(batch)
        {'episodes': 1.0, 'episode_reward': 2.0, 'collision_rate': 1.0}
    """
    done = batch.get(("next", "done")).squeeze(-1)
    ended = int(done.sum())
    if not ended:
        return {"episodes": 0.0}
    stats = {
        "episodes": float(ended),
        "episode_reward": batch.get(("next", "episode_reward")).squeeze(-1)[done].mean().item(),
        "collision_rate": batch.get(("next", "terminated")).squeeze(-1)[done].float().mean().item(),
    }
    truth = batch.get(("next", "truth"), None)
    if truth is not None:
        stats["episode_distance"] = truth.get("distance")[..., -1][done].mean().item()
    return stats


class PPOTrainer:
    """One PPO run; :meth:`run` trains, evaluates, checkpoints and exports.

    Args:
        cfg: the resolved :class:`~oasis_torchrl.config.PPOConfig` (with overrides).

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> cfg = load_config("ppo", ["collector.total_frames=0"])  # doctest: +SKIP
        >>> PPOTrainer(cfg).run()  # doctest: +SKIP
    """

    def __init__(self, cfg: DictConfig) -> None:
        target_kl = cfg.optim.get("target_kl")
        if target_kl is not None and not target_kl > 0:
            raise ValueError(f"optim.target_kl must be positive or null, got {target_kl}")
        self.cfg = cfg
        self.output_dir = Path(cfg.output_dir)
        self.checkpoint_dir = self.output_dir / "checkpoints"
        torch.manual_seed(cfg.seed)
        resumed = self._resume_state()
        self.iteration = resumed.get("iteration", 0)
        self.frames = resumed.get("frames", 0)
        self.history: list[dict[str, Any]] = resumed.get("history", [])
        # The evaluation (on the selection seeds) of the policy kept so far, episodes included.
        self.kept_selection: dict[str, Any] | None = resumed.get("kept_selection")
        # The last frame of each chunk is all the policy reads: the server sends only that.
        self.env = make_env(
            cfg.env, all_frames=False, frame_stack=None, privileged=uses_ground_truth(cfg)
        )
        self.env.set_seed(cfg.seed + self.iteration)
        cameras = tuple(self.env.base_env.layout.cameras)
        self.net = net_from_checkpoint(resumed) if resumed else build_net(cfg, cameras)
        self.env.append_transform(ChunkFrameStack(cameras, depth=self.net.config.frames))
        if cfg.optim.pool_scale:
            self.net.pool_scale_gradients()
        self.modules = make_actor_critic(self.net)
        hold = cfg.exploration.hold_chunks
        self.collecting_policy = (
            HeldNoisePolicy(self.modules.policy, hold) if hold > 1 else self.modules.policy
        )
        self.loss = DrivingPPOLoss(
            self.modules,
            aux_coeff=cfg.loss.aux_coeff,
            clip_epsilon=cfg.loss.clip_epsilon,
            entropy_coeff=cfg.loss.entropy_coeff,
            critic_coeff=cfg.loss.critic_coeff,
            loss_critic_type=cfg.loss.loss_critic_type,
            normalize_advantage=True,
        )
        self.aux_replay = (
            AuxiliaryReplay(self.loss, cfg.aux_replay.capacity, cfg.aux_replay.mini_batch_size)
            if cfg.aux_replay.capacity
            else None
        )
        # Without vmap the critic runs on the batch and on its next observations as two plain
        # calls: under vmap the encoder's input preparation was a third of an update's time.
        self.advantage = GAE(
            gamma=cfg.loss.gamma,
            lmbda=cfg.loss.lmbda,
            value_network=self.modules.value,
            deactivate_vmap=True,
        )
        self.optimizer = torch.optim.Adam(self._param_groups(), lr=cfg.optim.lr)
        if resumed:
            try:
                self.optimizer.load_state_dict(resumed["optimizer"])
            except ValueError as error:  # e.g. one parameter group, before optim.critic_lr
                self.env.close()
                raise ValueError(
                    f"cannot resume the optimizer of {cfg.resume}: {error}; start a new run "
                    "(init_from=<the checkpoint> keeps its weights)"
                ) from error
        self.logger: Logger = get_logger(
            cfg.logger.backend,
            logger_name=str(self.output_dir / "logs"),
            experiment_name=cfg.logger.exp_name,
        )
        self._evaluator: Evaluator | None = None
        self._last_eval: tuple[int, tuple[int, ...], EvalReport] | None = None

    def _param_groups(self) -> list[dict[str, Any]]:
        """Three groups: the acting parts (encoder, actor) at ``optim.lr``; the fresh heads
        (critic, auxiliary) at ``optim.critic_lr``; the action scale at ``optim.scale_lr``
        (``null``: ``optim.lr``).

        Why the heads: a fresh critic on a warm-started encoder (whose features are small,
        ~0.08) moves too slowly at the actor's fine-tuning rate: measured on 1536 steps of the
        cloned policy, a critic fitted for 320 minibatches explains 31% of the returns' variance
        at 1e-4 and 61% at 1e-3; PPO's advantages are only as good as that fit.

        Why the scale: its policy gradient is a weak, noisy signal (whether samples far from
        the mean did worse), so at the actor's rate Adam moves it by little more than a random
        walk: measured, PPO's scale stayed at its initial 0.5 through 184k env steps, and the
        policy drove 260 m deterministically but 224 m with that noise. With the scale pooled
        per action number (``optim.pool_scale``) and this rate, a clone fine-tuned from a
        scale of 1.0 cut its steering scale to 0.67 in 20,480 env steps and kept its throttle
        scale near 0.94 (BENCHMARKS.md, "Exploration that shrinks").
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

    def _resume_state(self) -> dict[str, Any]:
        resume = self.cfg.resume
        if not resume:
            return {}
        path = self.checkpoint_dir / LATEST if resume == "latest" else Path(resume)
        state = load_checkpoint(path)
        logger.info("resuming from %s at iteration %d", path, state["iteration"])
        return state

    # -- training ----------------------------------------------------------------------------

    def run(self) -> PPOResult:
        """Train until ``collector.total_frames`` env steps; evaluate and export at the end."""
        cfg = self.cfg
        save_config(cfg, self.output_dir / "config.yaml")
        remaining = max(cfg.collector.total_frames - self.frames, 0)
        try:
            if self._selects_the_warm_start():
                self._periodic_evaluation()
            if remaining:
                self._train(remaining)
            kept, kept_checkpoint, kept_frames = self._kept_net()
            final = self._final_evaluation(kept, kept_frames) if cfg.eval.episodes else None
            checkpoint = self._save_checkpoint()
            policy_dir = self._export(kept)
        finally:
            self.close()
        return PPOResult(kept, kept_checkpoint or checkpoint, policy_dir, final, self.history)

    def _selects_the_warm_start(self) -> bool:
        """A warm-started run with selection seeds rates its starting policy first: fine-tuning
        then keeps a policy only if it beats the one it started from on those seeds."""
        return bool(self.cfg.init_from and self.cfg.eval.get("selection_seeds")) and not self.frames

    def _train(self, remaining: int) -> None:
        cfg = self.cfg
        collector = self._collector(remaining)
        bar = tqdm(
            total=cfg.collector.total_frames,
            initial=self.frames,
            desc="ppo",
            unit="step",
            disable=not cfg.progress,
        )
        try:
            started = waiting = time.perf_counter()
            first_frame = self.frames
            for batch in collector:
                collected = time.perf_counter()
                if cfg.ray.enabled:  # [collectors, rows, time] -> [rows, time]
                    batch = batch.flatten(0, 1)
                self.frames += batch.numel()
                self.iteration += 1
                metrics = {**_prefixed("train", episode_stats(batch)), **self._update(batch)}
                updated = time.perf_counter()
                metrics["time/collect_s"] = collected - waiting
                metrics["time/update_s"] = updated - collected
                metrics["time/env_steps_per_s"] = (self.frames - first_frame) / (updated - started)
                if cfg.eval.every and self.iteration % cfg.eval.every == 0:
                    metrics.update(_prefixed("eval", self._periodic_evaluation().summary()))
                if self.iteration % cfg.checkpoint.every == 0:
                    self._save_checkpoint()
                self._log(metrics)
                bar.update(batch.numel())
                bar.set_postfix(_postfix(metrics))
                if cfg.ray.enabled:  # TorchRL's Ray weight sync: new weights to every worker
                    collector.update_policy_weights_(self.collecting_policy)
                waiting = time.perf_counter()
        finally:
            bar.close()
            if cfg.ray.enabled:
                collector.close()
            else:
                collector.shutdown(close_env=False)

    def _collector(self, remaining: int) -> Any:
        """TorchRL's Collector over this process's env, or its RayCollector (``ray.enabled``)."""
        cfg = self.cfg
        if cfg.ray.enabled:
            from oasis_torchrl.config.ray import RayCollectionConfig
            from oasis_torchrl.distributed import RayCollection, env_factory

            ray_cfg = section(cfg.ray, RayCollectionConfig)
            return RayCollection(
                ray_cfg,
                env_factory(
                    cfg.env,
                    ray_cfg,
                    all_frames=False,
                    frame_stack=self.net.config.frames,
                    privileged=uses_ground_truth(cfg),
                ),
                self.collecting_policy,
                frames_per_batch=cfg.collector.frames_per_batch,
                total_frames=remaining,
                auto_register_policy_transforms=False,
            )
        return Collector(
            self.env,
            self.collecting_policy,
            frames_per_batch=cfg.collector.frames_per_batch,
            total_frames=remaining,
            auto_register_policy_transforms=False,
        )

    def _update(self, batch: TensorDictBase) -> dict[str, float]:
        """Advantages, then ``optim.epochs`` passes of minibatch PPO updates (fewer when the
        approximate KL to the collecting policy passes ``optim.target_kl``)."""
        cfg = self.cfg
        critic_only = self.iteration <= cfg.loss.critic_warmup_iters
        factor = self._anneal()
        with torch.no_grad():
            batch = self.advantage(batch)
        flat = batch.exclude("next").reshape(-1)  # the loss reads no next observation
        sums: dict[str, float] = {}
        updates = skipped = 0
        for minibatch in self._minibatches(flat):
            losses = self.loss(minibatch)
            if not critic_only and self._kl_exceeded(losses):
                break
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
            logger.warning(
                "iteration %d: %d minibatches with a non-finite loss or gradient skipped",
                self.iteration,
                skipped,
            )
        metrics = {key: value / max(updates, 1) for key, value in sums.items()}
        if self.aux_replay is not None and not critic_only:
            metrics.update(self._replay_aux(flat))
        metrics["optim/skipped_minibatches"] = float(skipped)
        metrics["optim/updates"] = float(updates)
        metrics["optim/lr"] = cfg.optim.lr * factor
        metrics.update(self._scale_metrics())
        return metrics

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

    def _scale_metrics(self) -> dict[str, float]:
        """The action scale's mean per action number (over chunk and components)."""
        scale = self.net.log_scale.detach().exp().reshape(-1, self.net.config.action_dim)
        means = zip(ACTION_NAMES, scale.mean(0).tolist(), strict=True)
        return {f"policy/scale_{name}": value for name, value in means}

    def _anneal(self) -> float:
        """Set this iteration's learning rates (linear decay to 5%); the decay factor."""
        cfg = self.cfg
        factor = 1.0
        if cfg.optim.anneal_lr:
            factor = max(1.0 - self.frames / cfg.collector.total_frames, 0.05)
        for group, base_lr in zip(self.optimizer.param_groups, self._base_lrs(), strict=True):
            group["lr"] = base_lr * factor
        return factor

    def _minibatches(self, flat: TensorDictBase) -> Iterator[TensorDictBase]:
        """``optim.epochs`` shuffled passes over ``flat`` in ``optim.mini_batch_size`` pieces."""
        for _ in range(self.cfg.optim.epochs):
            for index in torch.randperm(flat.numel()).split(self.cfg.optim.mini_batch_size):
                yield flat[index]

    def _kl_exceeded(self, losses: TensorDictBase) -> bool:
        """Whether the minibatch's approximate KL passes ``optim.target_kl`` (``null``: never).

        Why: a clone's near-saturated actions make single updates jump (approximate KL up to
        2.5 measured while fine-tuning at lr 3e-4); stopping the iteration's remaining
        minibatches then, as Stable-Baselines3's ``target_kl`` does, keeps PPO's trust region.
        """
        target = self.cfg.optim.get("target_kl")
        return target is not None and float(losses["kl_approx"].mean()) > target

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

    # -- evaluation, logging, files ----------------------------------------------------------

    @property
    def best_selection(self) -> float | None:
        """Mean distance of the kept policy on the selection seeds (None: none chosen yet)."""
        return None if self.kept_selection is None else self.kept_selection["mean_distance"]

    def _periodic_evaluation(self) -> EvalReport:
        """Evaluate on ``eval.selection_seeds`` if set, keeping the policy as
        ``checkpoints/best.pt`` if it beats the kept one (by ``eval.selection_margin`` standard
        errors, :func:`~oasis_torchrl.train.evaluate.beats`); otherwise on ``eval.seeds``. With
        ``checkpoint.keep_evaluated``, the evaluated policy is also saved as
        ``checkpoints/frames_<env steps>.pt`` (to choose among them later, e.g. the best within
        a smaller budget)."""
        selection_seeds = self.cfg.eval.get("selection_seeds")
        report = self._evaluate(self.net, selection_seeds)
        if self.cfg.checkpoint.keep_evaluated:
            save_checkpoint(
                self.checkpoint_dir / evaluated_checkpoint_name(self.frames),
                self.net,
                iteration=self.iteration,
                frames=self.frames,
                evaluation=report.summary(),
            )
        if selection_seeds:
            self._keep_if_better(report)
        return report

    def _keep_if_better(self, report: EvalReport) -> None:
        """Keep the evaluated policy as ``checkpoints/best.pt`` if its selection evaluation
        beats the kept one's by ``eval.selection_margin`` standard errors."""
        evaluated = report.to_dict()
        if beats(evaluated, self.kept_selection, self.cfg.eval.selection_margin):
            self.kept_selection = evaluated
            save_checkpoint(
                self.checkpoint_dir / BEST,
                self.net,
                iteration=self.iteration,
                frames=self.frames,
                selection=report.summary(),
            )

    def _kept_net(self) -> tuple[DrivingNet, Path | None, int]:
        """The policy a run leaves, its checkpoint and the env steps it trained for: the best
        on the selection seeds when ``eval.selection_seeds`` chose one, else the last."""
        if self.best_selection is None:
            return self.net, None, self.frames
        path = self.checkpoint_dir / BEST
        state = load_checkpoint(path)
        logger.info(
            "keeping the policy of %d env steps (mean distance %.1f on the selection seeds)",
            state["frames"],
            self.best_selection,
        )
        return net_from_checkpoint(state), path, state["frames"]

    def _final_evaluation(self, net: DrivingNet, policy_frames: int) -> EvalReport:
        """The evaluation of the kept policy on ``eval.seeds`` (reusing the last one if it
        evaluated the same policy on those seeds)."""
        seeds = tuple(self.cfg.eval.seeds)
        last = self._last_eval
        if net is self.net and last is not None and last[:2] == (self.frames, seeds):
            return last[2]
        return self._evaluate(net, policy_frames=policy_frames)

    def _evaluate(
        self,
        net: DrivingNet,
        seeds: Sequence[int] | None = None,
        *,
        policy_frames: int | None = None,
    ) -> EvalReport:
        """Evaluate ``net`` (trained for ``policy_frames`` env steps, default: all of this run's)
        on ``seeds`` (default ``eval.seeds``) and add its report (aggregates and episodes) to
        the history."""
        if self._evaluator is None:
            self._evaluator = Evaluator(
                self.cfg.env,
                self.cfg.eval,
                frame_stack=self.net.config.frames,
                progress=self.cfg.progress,
            )
        policy = self.modules.policy if net is self.net else make_actor_critic(net).policy
        seeds = tuple(int(seed) for seed in (seeds or self.cfg.eval.seeds))
        net.eval()
        try:
            report = self._evaluator.evaluate(policy, seeds)
        finally:
            net.train()
        self._last_eval = (self.frames, seeds, report)
        self.history.append(
            report.to_dict(
                iteration=self.iteration,
                frames=self.frames,
                policy_frames=self.frames if policy_frames is None else policy_frames,
                seeds=list(seeds),
            )
        )
        logger.info(
            "evaluation at %d env steps on seeds %s: %s", self.frames, seeds, report.summary()
        )
        return report

    def _log(self, metrics: dict[str, float]) -> None:
        for name, value in metrics.items():
            self.logger.log_scalar(name, value, step=self.frames)

    def _save_checkpoint(self) -> Path:
        return save_checkpoint(
            self.checkpoint_dir / LATEST,
            self.net,
            optimizer=self.optimizer.state_dict(),
            iteration=self.iteration,
            frames=self.frames,
            history=self.history,
            best_selection=self.best_selection,
            kept_selection=self.kept_selection,
            config=OmegaConf.to_container(self.cfg),
        )

    def _export(self, net: DrivingNet) -> Path | None:
        try:
            return export_lerobot(net, self.output_dir / "policy")
        except ImportError as error:
            logger.warning("not exporting a LeRobot policy folder: %s", error)
            return None

    def close(self) -> None:
        """Close the envs (and their embedded servers) and the evaluation recorders."""
        try:
            if self._evaluator is not None:
                self._evaluator.close()
        finally:
            self._evaluator = None
            if not self.env.is_closed:
                self.env.close()


def evaluated_checkpoint_name(frames: int) -> str:
    """The checkpoint file of the policy evaluated at ``frames`` env steps
    (``checkpoint.keep_evaluated``).

    Example:
        >>> evaluated_checkpoint_name(10240)
        'frames_10240.pt'
    """
    return f"frames_{frames}.pt"


def _prefixed(prefix: str, values: dict[str, float]) -> dict[str, float]:
    return {f"{prefix}/{key}": value for key, value in values.items()}


def _postfix(metrics: dict[str, float]) -> dict[str, str]:
    shown = {
        "dist": "train/episode_distance",
        "ret": "train/episode_reward",
        "eval": "eval/mean_distance",
    }
    return {name: f"{metrics[key]:.1f}" for name, key in shown.items() if key in metrics}


def train_ppo(cfg: DictConfig) -> PPOResult:
    """Run PPO as configured (:class:`~oasis_torchrl.config.PPOConfig`); see :class:`PPOTrainer`.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> result = train_ppo(load_config("ppo", ["env.num_envs=2"]))  # doctest: +SKIP
    """
    return PPOTrainer(cfg).run()
