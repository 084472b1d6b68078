"""Rollouts to episodes: every env row drives one episode (no resets) until it ends, and each
row becomes an :class:`~oasis_torchrl.evaluation.reports.EpisodeResult`.

Every endpoint also gets what frames give: the return under the frames-only reward (the env's
reward on frames alone, else scored beside it at every step: :class:`ReferenceScore`; the motion
reward unless ``env.reward.kind`` names the reference's depth reward), the likely-collision
terminations (that reward's) and its progress term (the sum of its first term:
``seen_progress``, or the depth reward's ``forward``).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch
from omegaconf import DictConfig
from tensordict import NonTensorData, TensorDict, TensorDictBase
from torchrl.envs import EnvBase

from oasis_torchrl.config.env import RewardConfig
from oasis_torchrl.envs.capabilities import FRAMES_ONLY_REWARD
from oasis_torchrl.envs.driving import drive
from oasis_torchrl.envs.factory import make_frames_reward
from oasis_torchrl.evaluation.reports import EpisodeResult
from oasis_torchrl.models.actor_critic import FRAME_STACK, PIXELS
from oasis_torchrl.rewards import DepthCollisionReward, MotionReward

Policy = Callable[[TensorDictBase], TensorDictBase]
NEXT = "next"
REFERENCE = "reference"
"""Where :class:`ReferenceScore` puts the frames-only reward's entries of a step."""


def rollout_episodes(
    env: EnvBase,
    policy: Policy,
    max_steps: int,
    *,
    keep_pixels: bool = False,
    on_reset: Callable[[TensorDictBase], None] | None = None,
    on_step: Callable[[TensorDictBase], None] | None = None,
) -> TensorDictBase:
    """One episode per env row, no resets: steps ``[N, T]`` until every row is done.

    Camera frames are dropped from the returned steps unless ``keep_pixels`` (a LeRobot
    recording needs them), so memory stays small. ``on_reset(td)`` and ``on_step(td)`` see every
    reset and step (recorders). The policy acts deterministically
    (``ExplorationType.DETERMINISTIC``).

    Example:
        >>> from oasis_torchrl.drivers import ScriptedDriver
        >>> from oasis_torchrl.config import load_config
        >>> from oasis_torchrl.envs import make_env
        >>> env = make_env(load_config("eval").env, num_envs=2, prompts="urban", max_steps=3)
        >>> rollout = rollout_episodes(env, ScriptedDriver.from_spec("throttle=1"), 3)
        >>> env.close()
        >>> rollout.batch_size, ("next", "pixels") in rollout.keys(True)
        (torch.Size([2, 3]), False)
    """
    frames = (FRAME_STACK, (NEXT, FRAME_STACK))
    dropped = frames if keep_pixels else (*frames, PIXELS, (NEXT, PIXELS))
    ended = torch.zeros(int(env.batch_size[0]), dtype=torch.bool)
    steps: list[TensorDictBase] = []

    def keep(td: TensorDictBase) -> None:
        if on_step is not None:
            on_step(td)
        steps.append(td.exclude(*dropped))
        ended.logical_or_(td.get((NEXT, "done")).reshape(ended.shape).cpu())

    drive(
        env,
        policy,
        keep,
        until=lambda: bool(ended.all()),
        max_steps=max_steps,
        reset_finished=False,
        on_reset=on_reset,
    )
    return torch.stack(steps, dim=1)


def _row_prompts(rollout: TensorDictBase) -> list[str]:
    value = rollout[:, 0].get("prompt")
    if isinstance(value, NonTensorData):
        value = value.data
    if isinstance(value, str):
        return [value] * rollout.batch_size[0]
    return [str(prompt) for prompt in value.tolist()]


def episode_results(rollout: TensorDictBase) -> list[EpisodeResult]:
    """Per-row results of a :func:`rollout_episodes` output ``[N, T]``: each row's episode ends
    at its first ``done`` (or at ``T``).

    Example:
        >>> from oasis_torchrl.evaluation import EvalReport
        >>> results = episode_results(rollout)  # doctest: +SKIP
        >>> EvalReport(results).mean_distance  # doctest: +SKIP
    """
    done = rollout.get((NEXT, "done")).reshape(rollout.batch_size).cpu()
    horizon = done.shape[1]
    end = torch.where(done.any(1), done.float().argmax(1), horizon - 1)
    rows = torch.arange(done.shape[0])
    within = torch.arange(horizon).unsqueeze(0) <= end.unsqueeze(1)
    reward = rollout.get((NEXT, "reward")).reshape(rollout.batch_size).cpu()
    returns = (reward * within).sum(1)
    collided = rollout.get((NEXT, "terminated")).reshape(rollout.batch_size).cpu()[rows, end]
    reference, progress, likely = _reference_sums(rollout, within)
    if likely is None:  # nothing scored the reference: the env's terminations are all there is
        likely = collided.clone()
    truth = rollout.get((NEXT, "truth"), None)
    if truth is not None:
        distance = truth.get("distance")[rows, end, -1].cpu()
        collided = collided | (truth.get("collided")[rows, end, -1].cpu() > 0.5)
    else:
        distance = torch.full((done.shape[0],), math.nan)
    seeds = rollout.get("episode_seed")[:, 0].reshape(-1).tolist()
    rows_of = zip(
        _row_prompts(rollout),
        seeds,
        distance,
        collided,
        returns,
        end,
        [None] * len(seeds) if progress is None else progress.tolist(),
        likely,
        [None] * len(seeds) if reference is None else reference.tolist(),
        strict=True,
    )
    return [
        EpisodeResult(
            prompt,
            int(seed),
            float(dist),
            bool(hit),
            float(ret),
            int(last) + 1,
            gone,
            bool(ended),
            score,
        )
        for prompt, seed, dist, hit, ret, last, gone, ended, score in rows_of
    ]


def _reference_sums(
    rollout: TensorDictBase, within: torch.Tensor
) -> tuple[torch.Tensor | None, torch.Tensor | None, torch.Tensor | None]:
    """Per row: the frames-only reward's return, its progress term and whether it terminated
    within the episode, from :class:`ReferenceScore`'s entries or, where the env's reward is a
    frames-only one, from the env's own; all None when neither is there."""
    scored = rollout.get((NEXT, REFERENCE), None)
    if scored is not None:
        forward = scored.get("progress")
    else:
        scored = rollout.get(NEXT)
        terms = scored.get("reward_terms", None)
        names = () if terms is None else [key for key in terms.keys() if key in PROGRESS_TERMS]
        if not names:
            return None, None, None
        forward = terms.get(names[0])
    shape = rollout.batch_size
    reference = (scored.get("reward").reshape(shape).cpu() * within).sum(1)
    progress = (forward.reshape(shape).cpu() * within).sum(1)
    likely = (scored.get("terminated").reshape(shape).cpu() & within).any(1)
    return reference, progress, likely


PROGRESS_TERMS = (MotionReward.terms[0], DepthCollisionReward.terms[0])
"""The progress terms of the frames-only rewards (the motion reward's, the depth reward's)."""


class ReferenceScore:
    """The frames-only reward scored beside an env whose own reward is another (the
    ground-truth reward): every step gets ``("next", "reference", <reward | terminated |
    progress>)``, so an evaluation reports what frames give on every endpoint.

    It reads all 4 frames of each chunk: the :class:`Evaluator` observes them for it.

    Example:
        >>> score = ReferenceScore(RewardConfig())
        >>> score.reward.terms[0]
        'seen_progress'
    """

    def __init__(self, reward_cfg: RewardConfig | DictConfig) -> None:
        kind = "depth" if reward_cfg.kind == "depth" else FRAMES_ONLY_REWARD
        self.reward = make_frames_reward(reward_cfg, kind)

    def on_reset(self, td: TensorDictBase) -> None:
        """New episodes on every row: the reward's per-row state restarts."""
        self.reward.reset(torch.ones(int(td.batch_size[0]), dtype=torch.bool))

    def on_step(self, td: TensorDictBase) -> None:
        """Score the step (``td`` holds the action and ``"next"``) into ``("next", REFERENCE)``."""
        step = td.get(NEXT)
        scored = self.reward(step.clone(False).set("action", td.get("action")))
        entries = {
            "reward": scored.get("reward").float(),
            "terminated": scored.get("terminated"),
            "progress": scored.get(("reward_terms", self.reward.terms[0])).float(),
        }
        step.set(REFERENCE, TensorDict(entries, batch_size=step.batch_size))
