"""``oasis-torchrl train {ppo,bc}``: train a driving policy from a YAML config.

``oasis-torchrl train ppo`` runs TorchRL PPO in the world model (``configs/ppo.yaml``);
``oasis-torchrl train bc`` runs behaviour cloning on a LeRobot dataset (``configs/bc.yaml``).
Any config value can be overridden as ``key=value`` (dotted keys), e.g.
``oasis-torchrl train ppo env.num_envs=4 collector.total_frames=20000 logger.backend=tensorboard``.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

logger = logging.getLogger(__name__)

NAME = "train"
HELP = "train a driving policy: ppo (TorchRL, in the world model) or bc (LeRobot dataset)"

ALGORITHMS = ("ppo", "bc")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The algorithm, an optional config file and ``key=value`` overrides.

    Example:
        >>> parser = argparse.ArgumentParser()
        >>> add_arguments(parser)
        >>> parser.parse_args(["ppo", "optim.lr=1e-4"]).overrides
        ['optim.lr=1e-4']
    """
    parser.add_argument("algorithm", choices=ALGORITHMS, help="ppo or bc")
    parser.add_argument(
        "--config", type=Path, help="YAML config (default: configs/<algorithm>.yaml)"
    )
    parser.add_argument(
        "overrides", nargs="*", metavar="KEY=VALUE", help="config overrides, e.g. optim.lr=1e-4"
    )


def run(args: argparse.Namespace) -> int:
    """Load the config, train, log where the results are; exit code 2 on bad settings.

    Example:
        >>> run(argparse.Namespace(algorithm="ppo", config=None, overrides=["optim.lrate=1"]))
        2
    """
    from oasis_torchrl.train.config import load_config

    try:
        cfg = load_config(args.config or args.algorithm, args.overrides)
        if args.algorithm == "ppo":
            from oasis_torchrl.train.ppo import train_ppo

            result = train_ppo(cfg)
            logger.info("PPO done: checkpoint %s, policy %s", result.checkpoint, result.policy_dir)
        else:
            from oasis_torchrl.train.bc import train_bc

            result = train_bc(cfg)
            logger.info("behaviour cloning done: policy %s", result.policy_dir)
    except (ValueError, FileNotFoundError, ImportError) as error:
        logger.error("cannot train: %s", error)
        return 2
    except KeyboardInterrupt:
        logger.warning("interrupted (PPO resumes with resume=latest)")
        return 130
    if result.final_eval is not None:
        logger.info("evaluation: %s", result.final_eval.summary())
    return 0
