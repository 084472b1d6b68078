"""The main job's evaluation stage: every policy (the reference drivers, the shipped policies,
the clone and the fine-tuned one) on the same fixed prompts and seeds, the best learned policy's
episodes recorded, and the evaluations as comparison rows."""

from __future__ import annotations

import logging
from typing import Any

from omegaconf import DictConfig, OmegaConf

from oasis_torchrl.drivers import (
    AUTOPILOT,
    SCRIPTED,
    load_driver,
    pretrained_path,
    shipped_policies,
)
from oasis_torchrl.drivers.pretrained import PREFIX as PRETRAINED
from oasis_torchrl.evaluation import EvalReport, Evaluator, side_by_side_for
from oasis_torchrl.train.comparison import PolicyRow, best_learned, comparison

logger = logging.getLogger(__name__)


def evaluate_all(cfg: DictConfig, policies: dict[str, str]) -> dict[str, dict[str, Any]]:
    """Evaluate each named policy spec on the config's fixed prompts and seeds: the aggregates
    and every episode (:meth:`~oasis_torchrl.evaluation.EvalReport.to_dict`).

    The last policy's episodes are also recorded (``eval.rerun`` / ``eval.lerobot``), side by
    side with those of the policies in ``eval.compare`` if any. A spec
    named twice is evaluated once: evaluations are deterministic, so a second run would repeat
    the first to the digit.

    Example:
        >>> evaluate_all(load_config("demo"), {"autopilot": "autopilot"})  # doctest: +SKIP
        {'autopilot': {'mean_distance': ..., 'collision_rate': 0.0, ..., 'per_episode': [...]}}
    """
    plain = OmegaConf.merge(cfg.eval, {"rerun": None, "lerobot": None})
    recorded = list(policies.values())[-1] if policies else None
    side_by_side = side_by_side_for(cfg.eval, policies)
    reports: dict[str, EvalReport] = {}
    results = {}
    for name, spec in policies.items():
        if spec not in reports:
            driver = load_driver(spec)
            eval_cfg = cfg.eval if spec == recorded else plain
            rerun_logger = None
            if side_by_side is not None and name in side_by_side.roots:
                rerun_logger = side_by_side.logger(name)
            with Evaluator.for_driver(
                cfg.env, eval_cfg, driver, progress=cfg.progress, rerun_logger=rerun_logger
            ) as run:
                reports[spec] = run.evaluate(driver)
        results[name] = reports[spec].to_dict()
        logger.info("%s: %s", name, reports[spec].summary())
    if side_by_side is not None:
        side_by_side.close()  # marks the divergences, then ends the file
    return results


def shipped_specs(names: list[str] | None) -> dict[str, str]:
    """The shipped policies the comparison lists, as row names and driver specs
    (``pretrained:NAME``): those ``names`` (null: every shipped one).

    Raises:
        ValueError: a name that is not shipped (with those that are).

    Example:
        >>> shipped_specs([])
        {}
    """
    names = list(shipped_policies()) if names is None else [str(name) for name in names]
    specs = [f"{PRETRAINED}{name.removeprefix(PRETRAINED)}" for name in names]
    for spec in specs:
        pretrained_path(spec)  # an unknown name fails here, before any stage
    return {spec: spec for spec in specs}


def evaluate_and_record_best(
    cfg: DictConfig, policies: dict[str, str], shipped: list[str]
) -> dict[str, dict[str, Any]]:
    """:func:`evaluate_all` of ``policies`` (``shipped``: the shipped ones' names), in their
    order, with one recording (``eval.rerun``, ``eval.lerobot``): the best learned policy's
    episodes, side by side with ``eval.compare``'s.

    Which policy is best is known only once all are evaluated, so the others are evaluated
    unrecorded first; the compared ones and the best then drive the recorded pass (the best's
    figures repeat its first evaluation's: evaluations are deterministic). Recording costs
    several times an unrecorded evaluation, so this records each episode once.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> cfg = load_config("demo", ["eval.rerun=null"])  # nothing to record
        >>> evaluate_and_record_best(cfg, {}, [])
        {}
    """
    recording = bool(cfg.eval.rerun or cfg.eval.lerobot)
    compared = {str(spec) for spec in cfg.eval.compare} if recording else set()
    plain = OmegaConf.merge(cfg, {"eval": {"rerun": None, "lerobot": None}})
    results = evaluate_all(plain, {n: s for n, s in policies.items() if s not in compared})
    if recording:
        recorded = {name: spec for name, spec in policies.items() if spec in compared}
        best = best_learned(comparison_rows(results, shipped))
        if best is not None:
            logger.info("recording %s, the best learned policy", best.name)
            recorded[best.name] = policies[best.name]
        results |= evaluate_all(cfg, recorded)
    return {name: results[name] for name in policies}


def comparison_rows(evaluations: dict[str, dict[str, Any]], shipped: list[str]) -> list[PolicyRow]:
    """The main job's evaluations as comparison rows: the autopilot, the scripted constants
    (``constant:...``) and the ``shipped`` policies named as such, the rest learned.

    Example:
        >>> evaluations = {"bc": {"mean_distance": 240.0, "collision_rate": 0.25, "episodes": 4}}
        >>> [(row.name, row.kind) for row in comparison_rows(evaluations, [])]
        [('bc', 'learned')]
    """
    constants = [name for name in evaluations if name.startswith(SCRIPTED)]
    return comparison(evaluations, autopilot=AUTOPILOT, constants=constants, shipped=shipped)
