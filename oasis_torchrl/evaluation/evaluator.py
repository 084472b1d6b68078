"""The :class:`Evaluator`: policies evaluated on fixed prompts and seeds over one env (and
server), each batch of episodes scored, reported and recorded.

The ``eval`` config section: ``prompts``, ``episodes`` (rows per prompt), ``seeds`` (one batch of
episodes per seed), ``max_steps``, and optionally ``rerun`` (an ``.rrd`` path, ``spawn`` or a
viewer URL) and ``lerobot`` (a dataset folder) to record the episodes.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import TYPE_CHECKING

from omegaconf import DictConfig
from tensordict import TensorDictBase
from tqdm import tqdm

from oasis_torchrl.closing import Closing
from oasis_torchrl.drivers.base import Driver
from oasis_torchrl.envs.capabilities import env_capabilities, resolve_reward_kind
from oasis_torchrl.envs.factory import make_env
from oasis_torchrl.evaluation.recorders import EpisodeRecorders
from oasis_torchrl.evaluation.reports import EvalReport
from oasis_torchrl.evaluation.rollouts import (
    Policy,
    ReferenceScore,
    episode_results,
    rollout_episodes,
)
from oasis_torchrl.models.config import POLICY_FRAMES

if TYPE_CHECKING:
    from oasis_torchrl.viz import RolloutLogger

logger = logging.getLogger(__name__)


class Evaluator(Closing):
    """Evaluates policies on fixed prompts and seeds, reusing one env (and server).

    Args:
        env_cfg: the ``env`` config section (endpoint, image size, server, reward).
        eval_cfg: the ``eval`` section (prompts, episodes, seeds, max_steps, rerun, lerobot).
        image_size: policy image size (default: ``env_cfg.image_size``).
        expert: run the embedded server's expert (for a policy that drives with it, see
            :attr:`~oasis_torchrl.drivers.Driver.needs_expert`).
        front_crop: the front crop a policy reads (see
            :attr:`~oasis_torchrl.drivers.Driver.front_crop`; None: ``env.front_crop``).
        progress: show a progress bar per evaluation.
        rerun_logger: record the episodes with this logger instead of ``eval.rerun``'s (a
            policy's logger of a side-by-side recording).
        name: the evaluated policy's name, which titles every panel of ``eval.rerun``'s
            recording.

    Example:
        >>> from oasis_torchrl.drivers import ScriptedDriver
        >>> from oasis_torchrl.config import load_config
        >>> cfg = load_config("eval", ["episodes=1", "max_steps=2", "env.image_size=[32,48]"])
        >>> with Evaluator(cfg.env, cfg, progress=False) as evaluator:
        ...     report = evaluator.evaluate(ScriptedDriver.from_spec("throttle=1"))
        >>> len(report.episodes), report.mean_distance > 0
        (1, True)
    """

    def __init__(
        self,
        env_cfg: DictConfig,
        eval_cfg: DictConfig,
        *,
        image_size: tuple[int, int] | None = None,
        frame_stack: int = POLICY_FRAMES,
        expert: bool = False,
        front_crop: float | None = None,
        progress: bool = True,
        rerun_logger: RolloutLogger | None = None,
        name: str = "",
    ) -> None:
        if eval_cfg.episodes < 1 or not eval_cfg.seeds or not eval_cfg.prompts:
            raise ValueError("eval needs episodes >= 1 and at least one prompt and one seed")
        self.cfg = eval_cfg
        self.progress = progress
        self._batches = 0
        row_prompts = [str(prompt) for prompt in eval_cfg.prompts for _ in range(eval_cfg.episodes)]
        frames_scored = resolve_reward_kind(env_cfg.reward.kind, env_capabilities(env_cfg))
        self.reference = None if frames_scored != "ground_truth" else ReferenceScore(env_cfg.reward)
        self.env = make_env(
            env_cfg,
            num_envs=len(row_prompts),
            prompts=row_prompts,
            max_steps=eval_cfg.max_steps,
            image_size=image_size,
            # A dataset keeps every frame, and the frames-only reward scored beside reads them;
            # the metrics, the policies and rerun need the last alone.
            all_frames=bool(eval_cfg.get("lerobot")) or self.reference is not None,
            frame_stack=frame_stack,
            expert=expert,
            front_crop=front_crop,
        )
        self.recorders = EpisodeRecorders(
            rerun_logger or eval_cfg.get("rerun"),
            eval_cfg.get("lerobot"),
            scenes=self.env.scene_source(),
            name=name,
        )
        if rerun_logger is not None and self.frames_only:
            logger.warning(
                "policies side by side on a frames-only endpoint: it ignores seeds, so each "
                "policy drives other scenes (recorded all the same)"
            )

    @classmethod
    def for_driver(
        cls,
        env_cfg: DictConfig,
        eval_cfg: DictConfig,
        driver: Driver,
        *,
        progress: bool = True,
        rerun_logger: RolloutLogger | None = None,
        name: str = "",
    ) -> Evaluator:
        """An evaluator whose env serves what ``driver`` reads: its image size, its frame
        stack, its front crop and, if it drives with it, the embedded server's expert
        (``name``: the driver's, for the recording's panels).

        Example:
            >>> from oasis_torchrl.drivers import load_driver
            >>> from oasis_torchrl.config import load_config
            >>> cfg = load_config("eval", ["episodes=1", "max_steps=2"])
            >>> autopilot = load_driver("autopilot")
            >>> with Evaluator.for_driver(cfg.env, cfg, autopilot, progress=False) as evaluator:
            ...     evaluator.evaluate(autopilot).collision_rate
            0.0
        """
        return cls(
            env_cfg,
            eval_cfg,
            image_size=driver.image_size,
            frame_stack=driver.frame_stack,
            expert=driver.needs_expert,
            front_crop=driver.front_crop,
            progress=progress,
            rerun_logger=rerun_logger,
            name=name,
        )

    def evaluate(self, policy: Policy, seeds: Sequence[int] | None = None) -> EvalReport:
        """Run one batch of episodes per seed (``seeds``, default ``eval.seeds``); the report
        holds all of them."""
        report = EvalReport(ground_truth=not self.frames_only)
        seeds = [int(seed) for seed in (self.cfg.seeds if seeds is None else seeds)]
        if not seeds:
            raise ValueError("evaluate needs at least one seed")
        steps = len(seeds) * self.cfg.max_steps
        with tqdm(total=steps, desc="evaluating", unit="step", disable=not self.progress) as bar:

            def on_reset(td: TensorDictBase) -> None:
                if self.reference is not None:
                    self.reference.on_reset(td)
                self.recorders.on_reset(td)

            def on_step(td: TensorDictBase) -> None:
                if self.reference is not None:
                    self.reference.on_step(td)
                self.recorders.on_step(td)
                bar.update()

            for index, seed in enumerate(seeds):
                # Each batch of episodes gets a reset's tick and max_steps ticks of the recording.
                self.recorders.align(self._batches * (self.cfg.max_steps + 1))
                self._batches += 1
                self.env.set_seed(seed)
                rollout = rollout_episodes(
                    self.env,
                    policy,
                    self.cfg.max_steps,
                    keep_pixels=self.recorders.lerobot is not None,
                    on_reset=on_reset,
                    on_step=on_step,
                )
                results = episode_results(rollout)
                self.recorders.write_episodes(rollout, results)
                report.episodes.extend(results)
                bar.update((index + 1) * self.cfg.max_steps - bar.n)
                bar.set_postfix(report.progress_figure())
        return report

    @property
    def frames_only(self) -> bool:
        """Whether the endpoint sends frames alone (no ground truth), as the hosted service
        does, which ignores seeds: its episodes of one seed are not the same scene twice."""
        return self.env.observation_spec.get("truth", None) is None

    def close(self) -> None:
        """Close the recorders and the env."""
        try:
            self.recorders.close()
        finally:
            self.env.close()
