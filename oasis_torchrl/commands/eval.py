"""``oasis-torchrl eval``: evaluate a policy on fixed prompts and seeds; JSON out.

The policy is ``autopilot``, ``constant:throttle=1.0,steering=0.0`` (any scripted driver spec),
a PPO checkpoint, a LeRobot policy folder of any type (``oasis``, ``act``, ``diffusion``, plugins)
or a policy server (``grpc://host:port``, the key in ``OASIS_POLICY_API_KEY``). Settings:
:class:`~oasis_torchrl.config.EvalConfig`, each a flag or a ``key=value`` override:
``oasis-torchrl eval policy=outputs/bc/policy seeds=[0,1] episodes=8 output=eval.json``.
The report (mean distance before collision, collision rate, mean return, and every episode) is
written to stdout as JSON, and to ``output`` when set.
"""

from __future__ import annotations

import json
import logging
import sys

from omegaconf import DictConfig

from oasis_torchrl.config.evaluation import EvalConfig

logger = logging.getLogger(__name__)

NAME = "eval"
HELP = "evaluate a policy (distance before collision, collision rate, return) as JSON"
CONFIG = EvalConfig


def run(cfg: DictConfig) -> int:
    """Evaluate and print the JSON report; exit code 2 on bad settings.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> run(load_config("eval", ["policy=missing.pt"]))
        2
    """
    from oasis_torchrl.drivers import load_driver
    from oasis_torchrl.remote import RemotePolicyError
    from oasis_torchrl.train.evaluate import Evaluator

    try:
        driver = load_driver(cfg.policy)
        with Evaluator.for_driver(cfg.env, cfg, driver) as evaluator:
            report = evaluator.evaluate(driver)
    except (ValueError, FileNotFoundError, ImportError, KeyError, RemotePolicyError) as error:
        logger.error("cannot evaluate: %s", error)
        return 2
    if cfg.output:
        logger.info("wrote %s", report.write_json(cfg.output, policy=str(cfg.policy)))
    sys.stdout.write(json.dumps(report.to_dict(policy=str(cfg.policy)), indent=2) + "\n")
    return 0
