"""Evaluation: fixed prompts and seeds in; mean distance before collision, collision rate and
return out.

Each env row drives exactly one episode (no resets) until it ends (collision, or ``max_steps``)
or every row has ended. The distance is the embedded server's odometer at the episode's last
step (``("truth", "distance")``; NaN on servers without ground truth); a collision is the
episode ending *terminated* (the ground-truth collision, or the reward's termination); the
return sums the rewards up to and including that step. With the same policy, prompts, seeds
and server, the numbers are the same run after run.

Every endpoint also gets what frames give: the return under the frames-only reward (the env's
reward on frames alone, else scored beside it: :class:`ReferenceScore`; the motion reward unless
``env.reward.kind`` names the reference's depth reward), the episode length, the likely-collision
terminations (that reward's) and its progress term (the sum of its first term: ``seen_progress``,
or the depth reward's ``forward``). On an endpoint that sends frames only (the hosted
service, a hosted-like server) there is no distance and no ground-truth collision, and the
report says ``ground_truth: false``. Such an endpoint ignores seeds, so its
episodes cannot be paired across policies: comparisons (:func:`difference`) then use the
unpaired (Welch) standard error of the difference in mean return.

The ``eval`` config section: ``prompts``, ``episodes`` (rows per prompt), ``seeds`` (one batch of
episodes per seed), ``max_steps``, and optionally ``rerun`` (an ``.rrd`` path, ``spawn`` or a
viewer URL) and ``lerobot`` (a dataset folder) to record the episodes.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch
from omegaconf import DictConfig, OmegaConf
from tensordict import NonTensorData, TensorDict, TensorDictBase
from torchrl.envs import EnvBase
from tqdm import tqdm

from oasis_torchrl.client import SceneLookup
from oasis_torchrl.config.env import RewardConfig
from oasis_torchrl.drivers.base import Driver
from oasis_torchrl.envs.capabilities import (
    FRAMES_ONLY_REWARD,
    env_capabilities,
    resolve_reward_kind,
)
from oasis_torchrl.envs.driving import drive
from oasis_torchrl.envs.factory import make_env, make_frames_reward
from oasis_torchrl.models.actor_critic import FRAME_STACK, PIXELS
from oasis_torchrl.models.config import POLICY_FRAMES
from oasis_torchrl.rewards import DepthCollisionReward, MotionReward

if TYPE_CHECKING:
    from oasis_torchrl.viz import RolloutLogger
    from oasis_torchrl.viz.side_by_side import SideBySide

logger = logging.getLogger(__name__)

Policy = Callable[[TensorDictBase], TensorDictBase]
NEXT = "next"
REFERENCE = "reference"
"""Where :class:`ReferenceScore` puts the frames-only reward's entries of a step."""
_PAIRED_KEYS = ("prompt", "episode_seed", "distance")


@dataclass(frozen=True)
class EpisodeResult:
    """One evaluation episode.

    Example:
        >>> EpisodeResult("urban", 7, distance=120.5, collided=True, episode_return=2.0, steps=60)
        EpisodeResult(prompt='urban', episode_seed=7, distance=120.5, collided=True, \
episode_return=2.0, steps=60, progress=None, likely_collision=False, reference_return=None)
    """

    prompt: str
    episode_seed: int
    distance: float
    collided: bool
    episode_return: float
    steps: int
    progress: float | None = None
    """The frames-only reward's progress term summed (None: not scored)."""
    likely_collision: bool = False
    """The frames-only reward terminated within the episode (a likely collision, from frames)."""
    reference_return: float | None = None
    """The return under the frames-only reward (None: not scored)."""


@dataclass
class EvalReport:
    """Episodes of an evaluation and their aggregates.

    Example:
        >>> report = EvalReport([EpisodeResult("urban", 1, 10.0, True, -5.0, 7),
        ...                      EpisodeResult("urban", 2, 30.0, False, 3.0, 20)])
        >>> report.mean_distance, report.collision_rate, report.mean_return
        (20.0, 0.5, -1.0)
    """

    episodes: list[EpisodeResult] = field(default_factory=list)
    ground_truth: bool = True
    """Whether the endpoint sent ground truth (distance, collisions) and honoured the seeds."""

    @property
    def mean_distance(self) -> float:
        """Mean distance before collision, metres (NaN without ground truth)."""
        return _mean([episode.distance for episode in self.episodes])

    @property
    def collision_rate(self) -> float:
        """Fraction of episodes that ended in a collision."""
        return _mean([float(episode.collided) for episode in self.episodes])

    @property
    def mean_return(self) -> float:
        """Mean episode return."""
        return _mean([episode.episode_return for episode in self.episodes])

    @property
    def mean_steps(self) -> float:
        """Mean episode length, steps (chunks)."""
        return _mean([float(episode.steps) for episode in self.episodes])

    @property
    def mean_progress(self) -> float | None:
        """Mean of the frames-only reward's progress term (None: not scored)."""
        progress = [episode.progress for episode in self.episodes]
        return None if None in progress else _mean(progress)

    @property
    def mean_reference_return(self) -> float | None:
        """Mean return under the frames-only reward (None: not scored)."""
        values = [episode.reference_return for episode in self.episodes]
        return None if None in values else _mean(values)

    @property
    def likely_collision_rate(self) -> float:
        """Fraction of episodes the frames-only reward ended (its likely collisions)."""
        return _mean([float(episode.likely_collision) for episode in self.episodes])

    def progress_figure(self) -> dict[str, str]:
        """The progress bar's figure: the distance with ground truth, else the return.

        >>> EvalReport([EpisodeResult("urban", 1, 10.0, True, -5.0, 7)]).progress_figure()
        {'distance': '10.0'}
        """
        if self.ground_truth and math.isfinite(self.mean_distance):
            return {"distance": f"{self.mean_distance:.1f}"}
        return {"return": f"{self.mean_return:.1f}"}

    def summary(self) -> dict[str, float]:
        """The aggregates (for loggers and progress bars; ``mean_progress`` where a frames-only
        reward was scored)."""
        progress, reference = self.mean_progress, self.mean_reference_return
        return {
            "mean_distance": self.mean_distance,
            "collision_rate": self.collision_rate,
            "mean_return": self.mean_return,
            "mean_steps": self.mean_steps,
            **({} if reference is None else {"mean_reference_return": reference}),
            **({} if progress is None else {"mean_progress": progress}),
            "likely_collision_rate": self.likely_collision_rate,
            "episodes": float(len(self.episodes)),
        }

    def per_prompt(self) -> dict[str, EvalReport]:
        """The episodes of each prompt (scene) as a report of their own, in the order the
        prompts first appear.

        Example:
            >>> report = EvalReport([EpisodeResult("urban", 1, 10.0, True, 0.0, 7),
            ...                      EpisodeResult("highway", 1, 30.0, False, 0.0, 20)])
            >>> {prompt: part.mean_distance for prompt, part in report.per_prompt().items()}
            {'urban': 10.0, 'highway': 30.0}
        """
        reports: dict[str, EvalReport] = {}
        for episode in self.episodes:
            part = reports.setdefault(episode.prompt, EvalReport(ground_truth=self.ground_truth))
            part.episodes.append(episode)
        return reports

    def to_dict(self, **extra: Any) -> dict[str, Any]:
        """``extra`` items, the aggregates (and, over several prompts, each prompt's under
        ``per_prompt``) and every episode, JSON-ready; a frames-only report says what its
        figures are."""
        labels = {"ground_truth": self.ground_truth}
        if not self.ground_truth:
            labels["note"] = FRAMES_ONLY_NOTE
        parts = self.per_prompt()
        scenes = {prompt: part.summary() for prompt, part in parts.items()}
        return {
            **extra,
            **labels,
            **self.summary(),
            **({"per_prompt": scenes} if len(parts) > 1 else {}),
            "per_episode": [asdict(e) for e in self.episodes],
        }

    def write_json(self, path: str | Path, **extra: Any) -> Path:
        """Write :meth:`to_dict` as JSON."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(**extra), indent=2))
        return path


FRAMES_ONLY_NOTE = (
    "frames only: no ground-truth distance or collisions (collision_rate counts the reward's "
    "likely-collision terminations); the endpoint ignores seeds, so episodes are not paired"
)


def difference(treated: dict[str, Any], baseline: dict[str, Any]) -> dict[str, Any]:
    """``treated - baseline`` (two :meth:`EvalReport.to_dict` results): the paired distance
    difference where both had ground truth and seeds, else the unpaired (Welch) difference in
    mean return (a frames-only endpoint ignores seeds, so no episode pairs with another).

    Example:
        >>> def report(*returns):
        ...     runs = [EpisodeResult("urban", 0, math.nan, False, r, 9) for r in returns]
        ...     return EvalReport(runs, ground_truth=False).to_dict()
        >>> gain = difference(report(3.0, 5.0), report(1.0, 2.0, 3.0))
        >>> gain["mean"], round(gain["stderr"], 3), gain["metric"], gain["paired"]
        (2.0, 1.155, 'episode_return', False)
    """
    if treated.get("ground_truth", True) and baseline.get("ground_truth", True):
        return {**paired_difference(treated, baseline), "metric": "distance", "paired": True}
    return {
        **unpaired_difference(treated, baseline, "episode_return"),
        "metric": "episode_return",
        "paired": False,
    }


def unpaired_difference(
    treated: dict[str, Any], baseline: dict[str, Any], key: str
) -> dict[str, float]:
    """Difference in the mean of episode ``key`` and its Welch standard error
    ``sqrt(s1^2/n1 + s2^2/n2)``: no pairing of episodes assumed.

    Example:
        >>> def report(*values):
        ...     return {"per_episode": [{"episode_return": v} for v in values]}
        >>> unpaired_difference(report(2.0, 4.0), report(1.0, 1.0), "episode_return")
        {'mean': 2.0, 'stderr': 1.0, 'episodes': 4.0}
    """
    groups = [[float(e[key]) for e in report["per_episode"]] for report in (treated, baseline)]
    if min(len(values) for values in groups) < 2:
        raise ValueError(
            f"an unpaired difference needs at least 2 episodes on each side, got "
            f"{len(groups[0])} and {len(groups[1])}"
        )
    means = [sum(values) / len(values) for values in groups]
    variances = [
        sum((v - mean) ** 2 for v in values) / (len(values) - 1) / len(values)
        for values, mean in zip(groups, means, strict=True)
    ]
    return {
        "mean": means[0] - means[1],
        "stderr": math.sqrt(sum(variances)),
        "episodes": float(len(groups[0]) + len(groups[1])),
    }


def paired_difference(treated: dict[str, Any], baseline: dict[str, Any]) -> dict[str, float]:
    """Mean and standard error of the per-episode distance differences ``treated - baseline``
    (two :meth:`EvalReport.to_dict` results) over the episodes both ran, matched by prompt and
    episode seed.

    Example:
        >>> def report(*metres):
        ...     runs = [EpisodeResult("urban", i, d, False, 0.0, 9) for i, d in enumerate(metres)]
        ...     return EvalReport(runs).to_dict()
        >>> paired_difference(report(12.0, 25.0, 31.0), report(10.0, 20.0, 30.0))
        {'mean': 2.666..., 'stderr': 1.201..., 'episodes': 3.0}
    """
    before = {(e["prompt"], e["episode_seed"]): e["distance"] for e in baseline["per_episode"]}
    differences = [
        episode["distance"] - before[(episode["prompt"], episode["episode_seed"])]
        for episode in treated["per_episode"]
        if (episode["prompt"], episode["episode_seed"]) in before
    ]
    count = len(differences)
    if count < 2:
        raise ValueError(f"a paired difference needs at least 2 shared episodes, got {count}")
    mean = sum(differences) / count
    variance = sum((d - mean) ** 2 for d in differences) / (count - 1)
    return {"mean": mean, "stderr": math.sqrt(variance / count), "episodes": float(count)}


def load_report(path: str | Path) -> dict[str, Any]:
    """An evaluation report written by :meth:`EvalReport.write_json` (``oasis-torchrl eval
    output=...``), checked to hold what :func:`paired_difference` reads.

    Example:
        >>> import tempfile
        >>> folder = Path(tempfile.mkdtemp())
        >>> path = EvalReport([EpisodeResult("urban", 3, 50.0, True, 1.0, 9)]).write_json(
        ...     folder / "report.json")
        >>> load_report(path)["per_episode"][0]["distance"]
        50.0
        >>> _ = (folder / "other.json").write_text('{"mean_distance": 50.0}')
        >>> load_report(folder / "other.json")
        Traceback (most recent call last):
        ...
        ValueError: .../other.json is not an evaluation report: it has no per_episode list
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no evaluation report at {path}")
    try:
        report = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise ValueError(f"{path} is not an evaluation report: not JSON ({error})") from None
    episodes = report.get("per_episode") if isinstance(report, dict) else None
    if not isinstance(episodes, list):
        raise ValueError(f"{path} is not an evaluation report: it has no per_episode list")
    for index, episode in enumerate(episodes):
        missing = [
            key for key in _PAIRED_KEYS if not isinstance(episode, dict) or key not in episode
        ]
        if missing:
            raise ValueError(
                f"{path} is not an evaluation report: episode {index} lacks {', '.join(missing)}"
            )
    return report


def selection_figure(report: dict[str, Any]) -> float:
    """What a selection compares in an evaluation (:meth:`EvalReport.to_dict`): the mean
    distance where the endpoint sent ground truth, else the mean return.

    >>> selection_figure({"mean_distance": float("nan"), "mean_return": 3.0, "ground_truth": False})
    3.0
    """
    return report["mean_distance" if report.get("ground_truth", True) else "mean_return"]


def beats(candidate: dict[str, Any], kept: dict[str, Any] | None, margin: float) -> bool:
    """Whether an evaluation (:meth:`EvalReport.to_dict`) should replace the kept one: with
    ``margin`` 0, any higher mean distance; otherwise a paired gain of more than ``margin``
    standard errors over the episodes both ran (a gain within an evaluation's noise keeps the
    kept policy).

    Example:
        >>> kept = EvalReport([EpisodeResult("urban", i, 100.0 * i, False, 0.0, 9)
        ...                    for i in range(4)]).to_dict()
        >>> lucky = {**kept, "mean_distance": 160.0, "per_episode": [
        ...     {**e, "distance": e["distance"] + g}
        ...     for e, g in zip(kept["per_episode"], (-30.0, 40.0, -20.0, 50.0))]}
        >>> beats(lucky, kept, margin=0.0), beats(lucky, kept, margin=2.0)
        (True, False)
    """
    if kept is None:
        return True
    if not margin:
        return selection_figure(candidate) > selection_figure(kept)
    if len(kept["per_episode"]) < 2:
        raise ValueError(
            f"a selection margin ({margin} standard errors) needs at least 2 evaluation "
            f"episodes on the selection seeds, got {len(kept['per_episode'])}: raise "
            "eval.episodes or set eval.selection_margin=0"
        )
    gain = difference(candidate, kept)
    return gain["mean"] > margin * gain["stderr"]


def _mean(values: Sequence[float]) -> float:
    return sum(values) / len(values) if values else math.nan


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


class EpisodeRecorders:
    """Where evaluation episodes go besides the metrics: rerun and/or a LeRobot dataset.

    Args:
        rerun: an ``.rrd`` path, ``"spawn"`` or a viewer URL (needs the ``rerun`` extra), or a
            logger of a side-by-side recording (:mod:`oasis_torchrl.viz.side_by_side`).
        lerobot: a dataset folder; episodes are appended (one row per frame at 20 fps).
        scenes: the top-down view's scene source (``env.scene_source()``; None: car and path).

    Example:
        >>> recorders = EpisodeRecorders()
        >>> recorders.close()
    """

    def __init__(
        self,
        rerun: str | RolloutLogger | None = None,
        lerobot: str | Path | None = None,
        scenes: SceneLookup | None = None,
    ) -> None:
        self.rerun = None
        self.lerobot = None
        if isinstance(rerun, str) and rerun:
            from oasis_torchrl.viz import RolloutLogger

            self.rerun = RolloutLogger(rerun, scenes=scenes)
        elif rerun:
            self.rerun = rerun
            if rerun.scenes is None:
                rerun.scenes = scenes
        if lerobot:
            from oasis_torchrl.data import LeRobotRecorder

            root = Path(lerobot)
            self.lerobot = LeRobotRecorder(root, append=(root / "meta").exists())

    def align(self, tick: int) -> None:
        """Start the next batch of episodes at ``tick`` of the recording (so the same batch
        starts at the same frame in every policy's recording)."""
        if self.rerun is not None:
            self.rerun.align(tick)

    def on_reset(self, td: TensorDictBase) -> None:
        """Log the reset observations."""
        if self.rerun is not None:
            self.rerun.log_reset(td)

    def on_step(self, td: TensorDictBase) -> None:
        """Log one step (``td`` holds the action and ``"next"``)."""
        if self.rerun is not None:
            self.rerun.log_step(td.get(NEXT), td.get("action"))

    def write_episodes(self, rollout: TensorDictBase, results: Sequence[EpisodeResult]) -> None:
        """Write each row's episode, up to its last step, to the LeRobot dataset."""
        if self.lerobot is None:
            return
        for row, result in enumerate(results):
            self.lerobot.write(rollout[row : row + 1, : result.steps])

    def close(self) -> None:
        """Finish the rerun recording and finalize the dataset."""
        if self.rerun is not None:
            self.rerun.close()
        if self.lerobot is not None:
            self.lerobot.close()


class Evaluator:
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
    ) -> Evaluator:
        """An evaluator whose env serves what ``driver`` reads: its image size, its frame
        stack, its front crop and, if it drives with it, the embedded server's expert.

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

    def __enter__(self) -> Evaluator:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def side_by_side_for(eval_cfg: DictConfig, policies: Mapping[str, str]) -> SideBySide | None:
    """The side-by-side recording (``eval.rerun``) of an evaluation of named policy specs: the
    last policy's and those whose spec is in ``eval.compare``, each under the first name of its
    spec; None when ``eval.rerun`` is unset or that is one policy (recorded alone, as usual).

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> cfg = load_config("eval", ["compare=[autopilot]"])
        >>> side_by_side_for(cfg, {"autopilot": "autopilot", "bc": "out/bc"}) is None  # no rerun
        True
    """
    from oasis_torchrl.viz.side_by_side import SideBySide

    specs = list(policies.values())
    wanted = {str(spec) for spec in eval_cfg.get("compare", [])} | set(specs[-1:])
    firsts = {spec: name for name, spec in reversed(list(policies.items()))}
    names = [name for spec, name in firsts.items() if spec in wanted][::-1]
    if not eval_cfg.get("rerun") or len(names) < 2:
        return None
    return SideBySide(eval_cfg.rerun, names, threshold=eval_cfg.divergence)


def evaluate_side_by_side(
    env_cfg: DictConfig,
    eval_cfg: DictConfig,
    drivers: Mapping[str, Driver],
    *,
    progress: bool = True,
) -> dict[str, EvalReport]:
    """Evaluate each named driver on the same prompts and seeds, recording them side by side
    into ``eval.rerun`` (:class:`~oasis_torchrl.viz.side_by_side.SideBySide`; the first step
    where a policy's actions leave the first policy's by more than ``eval.divergence`` is an
    event).

    Example:
        >>> from oasis_torchrl.drivers import load_driver
        >>> from oasis_torchrl.config import load_config
        >>> import tempfile
        >>> cfg = load_config("eval", ["episodes=1", "max_steps=2",
        ...                            f"rerun={tempfile.mkdtemp()}/pair.rrd"])
        >>> drivers = {name: load_driver(name) for name in ("autopilot", "constant:throttle=1")}
        >>> reports = evaluate_side_by_side(cfg.env, cfg, drivers, progress=False)
        >>> sorted(reports)
        ['autopilot', 'constant:throttle=1']
    """
    from oasis_torchrl.viz.side_by_side import SideBySide

    # The others are compared, not evaluated for their own records (no LeRobot episodes).
    plain = OmegaConf.merge(eval_cfg, {"rerun": None, "lerobot": None})
    recording = SideBySide(eval_cfg.rerun, list(drivers), threshold=eval_cfg.divergence)
    reports = {}
    try:
        for index, (name, driver) in enumerate(drivers.items()):
            with Evaluator.for_driver(
                env_cfg,
                plain if index else eval_cfg,
                driver,
                progress=progress,
                rerun_logger=recording.logger(name),
            ) as evaluator:
                reports[name] = evaluator.evaluate(driver)
    finally:
        recording.close()
    return reports
