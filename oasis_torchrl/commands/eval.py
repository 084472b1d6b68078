"""``oasis-torchrl eval``: evaluate a policy on fixed prompts and seeds; JSON out.

The policy is ``autopilot``, ``constant:throttle=1.0,steering=0.0`` (any scripted driver spec),
a PPO checkpoint, a LeRobot policy folder of any type (``oasis``, ``act``, ``diffusion``, plugins)
or a policy server (``grpc://host:port``, the key in ``OASIS_POLICY_API_KEY``). Settings:
:class:`~oasis_torchrl.config.EvalConfig`, each a flag or a ``key=value`` override:
``oasis-torchrl eval policy=outputs/bc/policy seeds=[0,1] episodes=8 output=eval.json``.
The report (mean distance before collision, collision rate, mean return, and every episode) is
written to stdout as JSON, and to ``output`` when set. With ``baseline=<an earlier report>`` it
also holds ``vs_baseline``: the mean and standard error of the per-episode distance differences
over the episodes both ran (same prompt and episode seed), the comparison that says whether one
policy beats another beyond the noise of the scenes:
``oasis-torchrl eval policy=outputs/ppo/policy seeds=[1000] episodes=32
baseline=constant.json``.

On an endpoint that sends frames only (the hosted service) the report holds what frames give
(return under the frames-only motion reward, episode length, likely-collision
terminations, the metres seen in the frames; ``ground_truth: false``), and ``vs_baseline`` is
the unpaired (Welch) difference in mean return: such an endpoint ignores seeds.

With ``compare=[autopilot]`` and ``rerun=pair.rrd`` the other policies
drive the same seeds too, recorded side by side with the policy (their aggregates under
``compared``): ``oasis-torchrl eval policy=outputs/bc/policy compare=[autopilot]
rerun=pair.rrd``.
"""

from __future__ import annotations

import json
import logging
import math
import sys
from typing import Any

from omegaconf import DictConfig

from oasis_torchrl.config.evaluation import EvalConfig

logger = logging.getLogger(__name__)

NAME = "eval"
HELP = "evaluate a policy (distance before collision, collision rate, return) as JSON"
CONFIG = EvalConfig


def run(cfg: DictConfig) -> int:
    """Evaluate and print the JSON report; exit code 2 on bad settings, or on a baseline that
    shares fewer than 2 episodes with the evaluation (the report is still written).

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> run(load_config("eval", ["policy=missing.pt"]))
        2
    """
    from oasis_torchrl.drivers import load_driver
    from oasis_torchrl.evaluation import Evaluator, evaluate_side_by_side, load_report
    from oasis_torchrl.remote import RemotePolicyError

    compared: dict[str, Any] = {}
    try:
        baseline = load_report(cfg.baseline) if cfg.baseline else None
        if cfg.compare:
            if not cfg.rerun:
                raise ValueError("compare records policies side by side: set rerun=<file>.rrd")
            drivers = {str(spec): load_driver(spec) for spec in [cfg.policy, *cfg.compare]}
            reports = evaluate_side_by_side(cfg.env, cfg, drivers, progress=cfg.progress)
            report = reports.pop(str(cfg.policy))
            compared = {spec: other.summary() for spec, other in reports.items()}
        else:
            driver = load_driver(cfg.policy)
            with Evaluator.for_driver(
                cfg.env, cfg, driver, progress=cfg.progress, name=str(cfg.policy)
            ) as evaluator:
                report = evaluator.evaluate(driver)
    except (ValueError, FileNotFoundError, ImportError, KeyError, RemotePolicyError) as error:
        logger.error("cannot evaluate: %s", error)
        return 2
    extra: dict[str, Any] = {"policy": str(cfg.policy)}
    if compared:
        extra["compared"] = compared
    code = 0
    if baseline is not None:
        try:
            extra["vs_baseline"] = _versus(report.to_dict(), baseline, cfg.baseline)
        except ValueError as error:
            logger.error(
                "cannot compare with the baseline %s: %s (evaluate with its prompts, seeds and "
                "episodes)",
                cfg.baseline,
                error,
            )
            code = 2
    if cfg.output:
        logger.info("wrote %s", report.write_json(cfg.output, **extra))
    sys.stdout.write(json.dumps(report.to_dict(**extra), indent=2) + "\n")
    return code


def _versus(result: dict[str, Any], baseline: dict[str, Any], name: str) -> dict[str, Any]:
    """The paired difference against ``baseline``, logged for a person."""
    from oasis_torchrl.evaluation import difference as compare

    difference = compare(result, baseline)
    logger.info(
        "vs %s: %+.2f ± %.2f %s per episode over %d %s episodes (%.1f standard errors)",
        name,
        difference["mean"],
        difference["stderr"],
        "m" if difference["paired"] else "of return",
        difference["episodes"],
        "shared" if difference["paired"] else "unpaired",
        _standard_errors(difference["mean"], difference["stderr"]),
    )
    return {"baseline": name, **difference}


def _standard_errors(mean: float, stderr: float) -> float:
    """``mean`` in standard errors (0 for no difference at all, infinite for a constant one)."""
    if stderr:
        return mean / stderr
    return math.copysign(math.inf, mean) if mean else 0.0
