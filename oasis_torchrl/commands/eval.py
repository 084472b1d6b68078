"""``oasis-torchrl eval``: evaluate a policy on fixed prompts and seeds; JSON out.

The policy is ``autopilot``, ``constant:throttle=1.0,steering=0.0`` (any scripted driver spec),
a PPO checkpoint or a LeRobot ``oasis`` policy folder. Settings come from ``configs/eval.yaml``,
overridable as ``key=value``:
``oasis-torchrl eval policy=outputs/bc/policy seeds=[0,1] episodes=8 output=eval.json``.
The report (mean distance before collision, collision rate, mean return, and every episode) is
written to stdout as JSON, and to ``output`` when set.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

logger = logging.getLogger(__name__)

NAME = "eval"
HELP = "evaluate a policy (distance before collision, collision rate, return) as JSON"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """An optional config file and ``key=value`` overrides.

    Example:
        >>> parser = argparse.ArgumentParser()
        >>> add_arguments(parser)
        >>> parser.parse_args(["policy=autopilot"]).overrides
        ['policy=autopilot']
    """
    parser.add_argument("--config", type=Path, help="YAML config (default: configs/eval.yaml)")
    parser.add_argument(
        "overrides", nargs="*", metavar="KEY=VALUE", help="config overrides, e.g. policy=PATH"
    )


def run(args: argparse.Namespace) -> int:
    """Evaluate and print the JSON report; exit code 2 on bad settings.

    Example:
        >>> run(argparse.Namespace(config=None, overrides=["policy=missing.pt"]))
        2
    """
    from oasis_torchrl.train.config import load_config
    from oasis_torchrl.train.evaluate import Evaluator
    from oasis_torchrl.train.policy_source import load_policy

    try:
        cfg = load_config(args.config or "eval", args.overrides)
        source = load_policy(cfg.policy)
        with Evaluator(cfg.env, cfg, image_size=source.image_size) as evaluator:
            report = evaluator.evaluate(source.policy)
    except (ValueError, FileNotFoundError, ImportError, KeyError) as error:
        logger.error("cannot evaluate: %s", error)
        return 2
    if cfg.output:
        logger.info("wrote %s", report.write_json(cfg.output, policy=str(cfg.policy)))
    sys.stdout.write(json.dumps(report.to_dict(policy=str(cfg.policy)), indent=2) + "\n")
    return 0
