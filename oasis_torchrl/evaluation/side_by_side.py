"""Policies side by side: several evaluated on the same prompts and seeds into one rerun
recording (``eval.rerun``, ``eval.compare``), where their actions part is an event."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

from omegaconf import DictConfig, OmegaConf

from oasis_torchrl.drivers.base import Driver
from oasis_torchrl.evaluation.evaluator import Evaluator
from oasis_torchrl.evaluation.reports import EvalReport

if TYPE_CHECKING:
    from oasis_torchrl.viz.side_by_side import SideBySide


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
    unrecorded = OmegaConf.merge(eval_cfg, {"rerun": None, "lerobot": None})
    recording = SideBySide(eval_cfg.rerun, list(drivers), threshold=eval_cfg.divergence)
    reports = {}
    try:
        for index, (name, driver) in enumerate(drivers.items()):
            with Evaluator.for_driver(
                env_cfg,
                unrecorded if index else eval_cfg,
                driver,
                progress=progress,
                rerun_logger=recording.logger(name),
            ) as evaluator:
                reports[name] = evaluator.evaluate(driver)
    finally:
        recording.close()
    return reports
