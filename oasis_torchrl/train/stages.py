"""The main job's stages: each takes its part of the :class:`~oasis_torchrl.train.plan.RunPlan`
and returns its product, reusing what an earlier run finished.

- :func:`gather_demonstrations`: the demonstrations dataset (given, imported or recorded);
- :func:`train_clone`: behaviour cloning and the DAgger rounds (:func:`record_dagger_round`);
- :func:`run_ppo`: PPO (fine-tuning, or from scratch in the learning benchmark);
- :func:`evaluate_and_record_best`: every policy on the same prompts and seeds, the best
  learned one recorded (:func:`evaluate_all`).

A folder a stage writes is written whole or not at all
(:func:`~oasis_torchrl.atomic.written_whole`); a training stopped half way resumes from its
saved state, which its function is told (``resume``), not its config.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from omegaconf import DictConfig

from oasis_torchrl.atomic import written_whole
from oasis_torchrl.config.run import LATEST as RESUME_LATEST
from oasis_torchrl.drivers import AUTOPILOT, load_driver
from oasis_torchrl.drivers.late_reaction import LateReactionAutopilot
from oasis_torchrl.evaluation import EvalReport, Evaluator, side_by_side_for
from oasis_torchrl.train.comparison import best_learned, comparison_rows
from oasis_torchrl.train.demonstrations import record_demonstrations
from oasis_torchrl.train.plan import CloneRound, DaggerRound, EvaluationPlan, Recording, RecordPlan

logger = logging.getLogger(__name__)


def gather_demonstrations(plan: RecordPlan) -> Path:
    """The demonstrations: the given dataset, the recordings imported, or ``plan.recording``'s
    episodes recorded (a complete earlier import or recording is reused). Written whole or not
    at all.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> from oasis_torchrl.train.plan import plan_run
        >>> gather_demonstrations(plan_run(load_config("demo")).record)  # doctest: +SKIP
        PosixPath('outputs/demo/demos')
    """
    root, wanted = plan.dataset, plan.recording.episodes
    if plan.given:
        logger.info("demonstrations: the dataset %s", root)
        return root
    info = root / "meta" / "info.json"
    if info.exists():
        episodes = json.loads(info.read_text())["total_episodes"]
        if episodes >= wanted:
            logger.info("reusing %s (%d episodes)", root, episodes)
            return root
        raise FileExistsError(f"{root} holds {episodes} of {wanted} episodes; delete it")
    with written_whole(root) as partial:  # a stop half way records them again next run
        if plan.recordings is not None:
            from oasis_torchrl.data.importer import import_recordings

            report = import_recordings(plan.recordings, partial, image_size=plan.image_size)
            logger.info("imported %d recordings from %s", len(report.imported), plan.recordings)
        else:
            record_episodes(plan.recording, partial)
    return root


def record_episodes(recording: Recording, root: Path) -> None:
    """Record ``recording``'s episodes into the dataset at ``root``."""
    learner = None
    if recording.late_reaction is not None:
        learner = LateReactionAutopilot(recording.late_reaction, seed=recording.seed)
    elif recording.learner is not None:
        learner = load_driver(recording.learner)
    labeller = recording.labeller
    record_demonstrations(
        recording.env,
        root,
        episodes=recording.episodes,
        seed=recording.seed,
        noise=recording.noise,
        learner=learner,
        labeller=None if labeller == AUTOPILOT else load_driver(labeller),
        progress=recording.progress,
    )


def record_dagger_round(plan: DaggerRound) -> Path:
    """Record a DAgger round's episodes (the previous clone drives, the labeller labels) and
    combine them with the previous round's data; either folder is reused when it exists. The
    round's data folder.

    Each is written whole or not at all: a stop while the round records loses only the round's
    unfinished episodes, which the next run records again from the start, and the
    demonstrations, a person's dataset among them, are only read.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> from oasis_torchrl.train.plan import plan_run
        >>> record_dagger_round(plan_run(load_config("demo")).clone[1].dagger)  # doctest: +SKIP
        PosixPath('outputs/demo/bc/round_1/dataset')
    """
    from oasis_torchrl.data.combine import combine_datasets

    if not plan.episodes.exists():
        with written_whole(plan.episodes) as partial:
            record_episodes(plan.recording, partial)
    if not plan.data.exists():
        combine_datasets([plan.previous, plan.episodes], plan.data)
    return plan.data


def train_clone(rounds: tuple[CloneRound, ...]) -> Path:
    """Behaviour cloning, then the DAgger rounds; the final policy folder (rounds reused).

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> from oasis_torchrl.train.plan import plan_run
        >>> train_clone(plan_run(load_config("demo")).clone)  # doctest: +SKIP
        PosixPath('outputs/demo/bc/round_1/policy')
    """
    from oasis_torchrl.train.bc import PARTIAL_POLICY, TRAINING_STATE, train_bc

    for round_ in rounds:
        if (round_.policy / "model.safetensors").exists():
            logger.info("reusing %s", round_.policy)
            continue
        if round_.dagger is not None:
            record_dagger_round(round_.dagger)
        stopped = (round_.folder / PARTIAL_POLICY / TRAINING_STATE).exists()
        train_bc(round_.config, resume=RESUME_LATEST if stopped else None)
    return rounds[-1].policy


@dataclass
class PPOStage:
    """A finished (or reused) PPO stage: its policy folder, the checkpoint of that policy, the
    env steps it trained for (0: a fine-tuning kept its warm start) and the evaluation history.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> from oasis_torchrl.train.plan import plan_run
        >>> run_ppo(plan_run(load_config("demo")).ppo).history  # doctest: +SKIP
    """

    policy_dir: Path
    checkpoint: Path
    policy_frames: int
    history: list[dict[str, float]]


def run_ppo(config: DictConfig) -> PPOStage:
    """Train a PPO stage, resume it, or reuse it when its policy folder exists.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> from oasis_torchrl.train.plan import ppo_config
        >>> stage = run_ppo(ppo_config(load_config("demo"), None))  # doctest: +SKIP
    """
    from oasis_torchrl.models.checkpoint import BEST, LATEST, load_checkpoint
    from oasis_torchrl.train.ppo import train_ppo

    out = Path(config.output_dir)
    policy, checkpoints = out / "policy", out / "checkpoints"
    if (policy / "model.safetensors").exists():
        logger.info("reusing %s", policy)
        history = load_checkpoint(checkpoints / LATEST)["history"]
    else:
        stopped = (checkpoints / LATEST).exists()
        result = train_ppo(config, resume=RESUME_LATEST if stopped else None)
        policy, history = result.policy_dir or policy, result.history
    # The policy a stage leaves: the selection's choice (best.pt) if it made one, else the last.
    checkpoint = checkpoints / BEST if (checkpoints / BEST).exists() else checkpoints / LATEST
    return PPOStage(policy, checkpoint, load_checkpoint(checkpoint)["frames"], history)


def evaluate_all(
    plan: EvaluationPlan, policies: dict[str, str], *, record: bool
) -> dict[str, dict[str, Any]]:
    """Evaluate each named policy spec on the plan's fixed prompts and seeds: the aggregates
    and every episode (:meth:`~oasis_torchrl.evaluation.EvalReport.to_dict`).

    With ``record``, the last policy's episodes are also recorded (``eval.rerun`` /
    ``eval.lerobot``), side by side with those of the policies in ``eval.compare`` if any. A
    spec named twice is evaluated once: evaluations are deterministic, so a second run would
    repeat the first to the digit.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> plan = EvaluationPlan.of(load_config("demo"))
        >>> evaluate_all(plan, {"autopilot": "autopilot"}, record=False)  # doctest: +SKIP
        {'autopilot': {'mean_distance': ..., 'collision_rate': 0.0, ..., 'per_episode': [...]}}
    """
    settings, unrecorded = plan.settings(record=record), plan.settings(record=False)
    recorded = list(policies.values())[-1] if policies else None
    side_by_side = side_by_side_for(settings, policies)
    reports: dict[str, EvalReport] = {}
    results = {}
    for name, spec in policies.items():
        if spec not in reports:
            driver = load_driver(spec)
            rerun_logger = None
            if side_by_side is not None and name in side_by_side.roots:
                rerun_logger = side_by_side.logger(name)
            with Evaluator.for_driver(
                plan.env,
                settings if spec == recorded else unrecorded,
                driver,
                progress=plan.progress,
                rerun_logger=rerun_logger,
                name=name,
            ) as run:
                reports[spec] = run.evaluate(driver)
        results[name] = reports[spec].to_dict()
        logger.info("%s: %s", name, reports[spec].summary())
    if side_by_side is not None:
        side_by_side.close()  # marks the divergences, then ends the file
    return results


def evaluate_and_record_best(
    plan: EvaluationPlan, policies: dict[str, str], shipped: list[str]
) -> dict[str, dict[str, Any]]:
    """:func:`evaluate_all` of ``policies`` (``shipped``: the shipped ones' names), in their
    order, with one recording (``eval.rerun``, ``eval.lerobot``): the best learned policy's
    episodes, side by side with ``eval.compare``'s.

    Which policy is best is known only once all are evaluated, so the others are evaluated
    unrecorded first; the compared ones and the best then drive the recorded pass (the best's
    figures repeat its first evaluation's: evaluations are deterministic). Recording every
    policy in its first pass would put every policy's frames in the file; this keeps the file to
    the best and the compared ones.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> plan = EvaluationPlan.of(load_config("demo", ["eval.rerun=null"]))  # no recording
        >>> evaluate_and_record_best(plan, {}, [])
        {}
    """
    compared = {str(spec) for spec in plan.recorded.compare} if plan.records else set()
    unrecorded = {n: s for n, s in policies.items() if s not in compared}
    results = evaluate_all(plan, unrecorded, record=False)
    if plan.records:
        recorded = {name: spec for name, spec in policies.items() if spec in compared}
        best = best_learned(comparison_rows(results, shipped))
        if best is not None:
            logger.info("recording %s, the best learned policy", best.name)
            recorded[best.name] = policies[best.name]
        results |= evaluate_all(plan, recorded, record=True)
    return {name: results[name] for name in policies}
