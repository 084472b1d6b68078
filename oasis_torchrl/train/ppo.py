"""PPO on :class:`~oasis_torchrl.envs.OasisEnv`, the TorchRL recipe.

A :class:`~torchrl.collectors.Collector` steps the batched env with the stochastic actor (a
distribution over the 4-action chunk); :class:`~oasis_torchrl.train.ppo_update.PPOUpdate`
turns each batch into new weights (GAE advantages with the critic, then
:class:`~torchrl.objectives.ClipPPOLoss` on both heads, the shared encoder run once per
minibatch, for a few epochs of minibatches; optionally an auxiliary replay). Around that:
TorchRL loggers (CSV or TensorBoard), a tqdm bar, checkpoints with resume, periodic
deterministic evaluation episodes (recorded to rerun and/or a LeRobot dataset when configured;
on ``eval.selection_seeds``, if set, they choose the policy the run keeps: early stopping that
never looks at the seeds reported at the end), a warm start from a behaviour-cloning policy,
and the kept policy exported as a LeRobot policy folder. Config:
:class:`~oasis_torchrl.config.PPOConfig`.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDictBase
from torchrl.collectors import Collector
from torchrl.record.loggers import Logger, get_logger
from tqdm import tqdm

from oasis_torchrl.config import save_config, section
from oasis_torchrl.config.run import resume_point
from oasis_torchrl.config.training import AUX_COEFF
from oasis_torchrl.drivers import DriverSpec
from oasis_torchrl.drivers.folders import export_lerobot, load_net
from oasis_torchrl.envs.capabilities import env_capabilities
from oasis_torchrl.envs.factory import make_env
from oasis_torchrl.envs.transforms import PRIVILEGED_FIELDS, ChunkFrameStack
from oasis_torchrl.evaluation import EvalReport, Evaluator, beats, selection_figure, selection_key
from oasis_torchrl.models import DrivingNet, DrivingNetConfig, make_actor_critic
from oasis_torchrl.models.checkpoint import (
    BEST,
    LATEST,
    load_checkpoint,
    net_from_checkpoint,
    save_checkpoint,
)
from oasis_torchrl.protocol import FRONT_CROP
from oasis_torchrl.train.perception_warmup import PerceptionWarmup
from oasis_torchrl.train.ppo_update import PPOUpdate

logger = logging.getLogger(__name__)


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
        crop = {"front_crop": cfg.env.front_crop} if FRONT_CROP in cameras else {}
        config = {"cameras": cameras, "image_size": image_size, **crop, **network}
        net = DrivingNet(DrivingNetConfig.from_dict(config))
    critic_inputs = len(PRIVILEGED_FIELDS) if cfg.privileged_critic else 0
    aux_outputs = len(PRIVILEGED_FIELDS) if cfg.loss.aux_coeff else 0
    if (net.config.critic_inputs, net.config.aux_outputs) != (critic_inputs, aux_outputs):
        net = net.with_training_heads(critic_inputs, aux_outputs)
    if net.config.cameras != cameras or tuple(net.config.image_size) != image_size:
        raise ValueError(
            f"the network reads cameras {net.config.cameras} at {net.config.image_size}, the env "
            f"gives {cameras} at {image_size}: set env.image_size to the network's size (and "
            f"env.front_crop to its front_crop, {net.config.front_crop})"
        )
    return net


def with_capabilities(cfg: DictConfig) -> DictConfig:
    """A copy of ``cfg`` (read-only if it is) whose null ``privileged_critic`` and
    ``loss.aux_coeff`` follow what its endpoint sends (:mod:`~oasis_torchrl.envs.capabilities`):
    on with ground truth, off on frames alone (explicit values are kept; on a frames-only
    endpoint :func:`~oasis_torchrl.envs.make_env` refuses them).

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> resolved = with_capabilities(load_config("ppo", ["env.server.hosted=true"]))
        >>> resolved.privileged_critic, resolved.loss.aux_coeff
        (False, 0.0)
    """
    ground_truth = env_capabilities(cfg.env).ground_truth
    privileged = ground_truth if cfg.privileged_critic is None else cfg.privileged_critic
    aux = cfg.loss.aux_coeff
    aux = (AUX_COEFF if ground_truth else 0.0) if aux is None else aux
    return OmegaConf.merge(cfg, {"privileged_critic": privileged, "loss": {"aux_coeff": aux}})


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
        resume: a checkpoint to continue from (``latest``: this run's own), whatever
            ``cfg.resume`` says; None: as ``cfg.resume`` says.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> cfg = load_config("ppo", ["collector.total_frames=0"])  # doctest: +SKIP
        >>> PPOTrainer(cfg).run()  # doctest: +SKIP
    """

    def __init__(self, cfg: DictConfig, *, resume: str | None = None) -> None:
        self.cfg = cfg = with_capabilities(cfg)
        self.resume = resume or cfg.resume
        self.output_dir = Path(cfg.output_dir)
        self.checkpoint_dir = self.output_dir / "checkpoints"
        torch.manual_seed(cfg.seed)
        resumed = self._resume_state()
        self.iteration = resumed.get("iteration", 0)
        self.frames = resumed.get("frames", 0)
        self.history: list[dict[str, Any]] = resumed.get("history", [])
        # Wall time over every session of the run (resumes add theirs): a shipped policy's card
        # states what it took to train.
        self._started = time.perf_counter() - resumed.get("wall_seconds", 0.0)
        # The evaluation (on the selection seeds) of the policy kept so far, episodes included.
        self.kept_selection: dict[str, Any] | None = resumed.get("kept_selection")
        # The last frame of each chunk is all the policy reads: the server sends only that.
        self.env = make_env(
            cfg.env, all_frames=False, frame_stack=None, privileged=uses_ground_truth(cfg)
        )
        try:
            self._build(resumed)
        except BaseException:  # a refused network, optimizer or setting leaves no server behind
            self.env.close()
            raise
        self._evaluator: Evaluator | None = None
        # Updates that changed what the policy does (the critic-only warm-up does not); with
        # the seeds, what tells whether the last evaluation already measured this policy.
        self._actor_updates = 0
        self._last_eval: tuple[int, tuple[int, ...], EvalReport] | None = None

    def _build(self, resumed: dict[str, Any]) -> None:
        """The network, its TorchRL modules, the collecting policy, the update and the logger."""
        cfg = self.cfg
        self.env.set_seed(cfg.seed + self.iteration)
        cameras = tuple(self.env.base_env.layout.cameras)
        self.net = net_from_checkpoint(resumed) if resumed else build_net(cfg, cameras)
        self.env.append_transform(ChunkFrameStack(cameras, depth=self.net.config.frames))
        self.modules = make_actor_critic(self.net)
        anneal_frames = cfg.optim.anneal_frames or cfg.collector.total_frames
        self.update = PPOUpdate(self.modules, cfg, anneal_frames)
        if resumed:
            try:
                self.update.optimizer.load_state_dict(resumed["optimizer"])
            except ValueError as error:  # e.g. one parameter group, before optim.critic_lr
                raise ValueError(
                    f"cannot resume the optimizer of {self.resume}: {error}; start a new run "
                    "(init_from=<the checkpoint> keeps its weights)"
                ) from error
        self.logger: Logger = get_logger(
            cfg.logger.backend,
            logger_name=str(self.output_dir / "logs"),
            experiment_name=cfg.logger.exp_name,
        )

    def _resume_state(self) -> dict[str, Any]:
        path = resume_point(self.resume, self.checkpoint_dir / LATEST)
        if path is None:
            return {}
        state = load_checkpoint(path)
        logger.info("resuming from %s at iteration %d", path, state["iteration"])
        return state

    # -- training ----------------------------------------------------------------------------

    def run(self) -> PPOResult:
        """Train until ``collector.total_frames`` env steps; evaluate and export at the end."""
        cfg = self.cfg
        save_config(cfg, self.output_dir / "config.yaml")
        try:
            if self._selects_the_warm_start():
                self._periodic_evaluation()
            if self.frames < cfg.warmup.frames:
                self._warm_up_perception()
            remaining = max(cfg.collector.total_frames - self.frames, 0)
            if remaining:
                self._train(remaining)
            kept, kept_checkpoint, kept_frames = self._kept_net()
            final_wanted = cfg.eval.episodes and cfg.eval.final
            final = self._final_evaluation(kept, kept_frames) if final_wanted else None
            checkpoint = self._save_checkpoint()
            policy_dir = self._export(kept)
        finally:
            self.close()
        return PPOResult(kept, kept_checkpoint or checkpoint, policy_dir, final, self.history)

    def _selects_the_warm_start(self) -> bool:
        """A warm-started run with selection seeds rates its starting policy first: fine-tuning
        then keeps a policy only if it beats the one it started from on those seeds."""
        return bool(self.cfg.init_from and self.cfg.eval.get("selection_seeds")) and not self.frames

    def _warm_up_perception(self) -> None:
        """The initial policy (or ``warmup.driver``) drives the rest of ``warmup.frames`` env
        steps, and the encoder and the auxiliary head are fitted to their privileged state
        (:mod:`~oasis_torchrl.train.perception_warmup`); PPO's first update follows."""
        cfg = self.cfg.warmup
        warmup = PerceptionWarmup(self.update.loss, cfg.frames, cfg.mini_batch_size, cfg.lr)
        driver = DriverSpec(cfg.driver) if cfg.driver else None
        if driver is not None and driver().needs_expert:
            raise ValueError(
                f"warmup.driver={cfg.driver!r} drives with the embedded server's expert, which "
                "PPO's env does not ask for: name a driver that needs no expert"
            )
        with self._collection(cfg.frames - self.frames, driver) as collector:
            for batch in tqdm(collector, desc="warm-up drives", disable=not self.cfg.progress):
                batch = self._rows(batch)
                flat = batch.exclude("next").reshape(-1)
                warmup.extend(flat)
                if self.update.aux_replay is not None:  # PPO's replay starts with these rows
                    self.update.aux_replay.extend(flat)
                self.frames += batch.numel()
                self._log(_prefixed("train", episode_stats(batch)))
        self._log_warmup(warmup.fit(cfg.steps, self.cfg.progress), len(warmup))
        self._actor_updates += 1
        self._save_checkpoint()

    def _log_warmup(self, losses: list[float], rows: int) -> None:
        """The warm-up's auxiliary loss over its first and its last tenth of steps."""
        if not losses:
            return
        window = max(len(losses) // 10, 1)
        first, last = float(np.mean(losses[:window])), float(np.mean(losses[-window:]))
        self._log({"warmup/aux_loss_first": first, "warmup/aux_loss_last": last})
        logger.info(
            "perception warm-up on %d rows: auxiliary loss %.4f -> %.4f in %d steps",
            rows,
            first,
            last,
            len(losses),
        )

    def _train(self, remaining: int) -> None:
        cfg = self.cfg
        progress = tqdm(
            total=cfg.collector.total_frames,
            initial=self.frames,
            desc="ppo",
            unit="step",
            disable=not cfg.progress,
        )
        with progress as bar, self._collection(remaining) as collector:
            started = waiting = time.perf_counter()
            first_frame = self.frames
            for batch in collector:
                collected = time.perf_counter()
                batch = self._rows(batch)
                self.frames += batch.numel()
                self.iteration += 1
                critic_only = self.iteration <= cfg.loss.critic_warmup_iters
                updated_metrics = self.update(batch, self.frames, critic_only)
                self._actor_updates += not critic_only
                metrics = {**_prefixed("train", episode_stats(batch)), **updated_metrics}
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
                    collector.update_policy_weights_(self.modules.policy)
                waiting = time.perf_counter()

    @contextmanager
    def _collection(self, frames: int, driver: DriverSpec | None = None) -> Iterator[Any]:
        """A collector of ``frames`` env steps, shut down afterwards (this process's env stays
        open for the next collection and the evaluations)."""
        collector = self._collector(frames, driver)
        try:
            yield collector
        finally:
            if self.cfg.ray.enabled:
                collector.close()
            else:
                collector.shutdown(close_env=False)

    def _rows(self, batch: TensorDictBase) -> TensorDictBase:
        """A collected batch as ``[rows, time]`` (Ray's ``[collectors, rows, time]`` flattened)."""
        return batch.flatten(0, 1) if self.cfg.ray.enabled else batch

    def _collector(self, remaining: int, driver: DriverSpec | None = None) -> Any:
        """TorchRL's Collector over this process's env, or its RayCollector (``ray.enabled``),
        driven by the collecting policy or ``driver`` (built in each Ray worker)."""
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
                None if driver else self.modules.policy,
                frames_per_batch=cfg.collector.frames_per_batch,
                total_frames=remaining,
                auto_register_policy_transforms=False,
                policy_factory=driver,
            )
        return Collector(
            self.env,
            driver() if driver else self.modules.policy,
            frames_per_batch=cfg.collector.frames_per_batch,
            total_frames=remaining,
            auto_register_policy_transforms=False,
        )

    # -- evaluation, logging, files ----------------------------------------------------------

    @property
    def best_selection(self) -> float | None:
        """Mean distance of the kept policy on the selection seeds, or on frames alone its mean
        return (None: none chosen yet)."""
        if self.kept_selection is None:
            return None
        return selection_figure(self.kept_selection)

    def _periodic_evaluation(self) -> EvalReport:
        """Evaluate on ``eval.selection_seeds`` if set, keeping the policy as
        ``checkpoints/best.pt`` if it beats the kept one (by ``eval.selection_margin`` standard
        errors, :func:`~oasis_torchrl.evaluation.beats`); otherwise on ``eval.seeds``. With
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
            "keeping the policy of %d env steps (%s %.2f on the selection seeds)",
            state["frames"],
            selection_key(self.kept_selection),
            self.best_selection,
        )
        return net_from_checkpoint(state), path, state["frames"]

    def _final_evaluation(self, net: DrivingNet, policy_frames: int) -> EvalReport:
        """The evaluation of the kept policy on ``eval.seeds`` (the last one if it evaluated
        the same policy on those seeds)."""
        seeds = tuple(int(seed) for seed in self.cfg.eval.seeds)
        unchanged = self._unchanged_evaluation(net, seeds)
        if unchanged is not None:
            return unchanged
        return self._evaluate(net, policy_frames=policy_frames)

    def _unchanged_evaluation(self, net: DrivingNet, seeds: tuple[int, ...]) -> EvalReport | None:
        """The last evaluation's report if it evaluated this policy as it is now on ``seeds``.
        Evaluations are deterministic, so running it again would repeat it to the digit (e.g.
        a warm start rated again after the critic-only warm-up)."""
        last = self._last_eval
        if net is self.net and last is not None and last[:2] == (self._actor_updates, seeds):
            return last[2]
        return None

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
                front_crop=self.net.config.front_crop,
                progress=self.cfg.progress,
                name=self.cfg.logger.exp_name,
            )
        policy = self.modules.policy if net is self.net else make_actor_critic(net).policy
        seeds = tuple(int(seed) for seed in (seeds or self.cfg.eval.seeds))
        report = self._unchanged_evaluation(net, seeds)
        if report is None:
            net.eval()
            try:
                report = self._evaluator.evaluate(policy, seeds)
            finally:
                net.train()
            self._last_eval = (self._actor_updates, seeds, report)
        else:
            logger.info("the policy is unchanged since its last evaluation on seeds %s", seeds)
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
            optimizer=self.update.optimizer.state_dict(),
            iteration=self.iteration,
            frames=self.frames,
            history=self.history,
            best_selection=self.best_selection,
            kept_selection=self.kept_selection,
            config=OmegaConf.to_container(self.cfg),
            wall_seconds=time.perf_counter() - self._started,
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
    """The progress bar's figures; the evaluation's distance where the endpoint sends ground
    truth, else its return (a frames-only endpoint's distance is NaN).

    >>> _postfix({"eval/mean_distance": float("nan"), "eval/mean_return": 41.0})
    {'eval_ret': '41.0'}
    """
    shown = {
        "dist": "train/episode_distance",
        "ret": "train/episode_reward",
        "eval": "eval/mean_distance",
        "eval_ret": "eval/mean_return",
    }
    if math.isfinite(metrics.get("eval/mean_distance", math.nan)):
        del shown["eval_ret"]
    return {
        name: f"{metrics[key]:.1f}"
        for name, key in shown.items()
        if key in metrics and math.isfinite(metrics[key])
    }


def train_ppo(cfg: DictConfig, *, resume: str | None = None) -> PPOResult:
    """Run PPO as configured (:class:`~oasis_torchrl.config.PPOConfig`), resuming ``resume`` if
    given; see :class:`PPOTrainer`.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> result = train_ppo(load_config("ppo", ["env.num_envs=2"]))  # doctest: +SKIP
    """
    return PPOTrainer(cfg, resume=resume).run()
