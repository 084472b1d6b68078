"""``oasis-torchrl demo``: the main job (what ``make demo`` runs), on the embedded server.

Records autopilot demonstrations as a LeRobot dataset, behaviour-clones a policy on them,
fine-tunes it with TorchRL PPO in the world model, evaluates the references, the clone and the
fine-tuned policy on fixed seeds, and prints their comparison as a table and where everything
is (config: ``configs/demo.yaml``; :func:`oasis_torchrl.train.pipeline.run_pipeline`). Any
config value can be overridden as ``key=value``, e.g. ``oasis-torchrl demo
output_dir=outputs/demo2 ppo.collector.total_frames=8192``. Finished stages are reused, so
running the same command again after an interruption continues where it stopped.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

logger = logging.getLogger(__name__)

NAME = "demo"
HELP = "the main job: record demonstrations, behaviour cloning, PPO fine-tuning, evaluation"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """An optional config file and ``key=value`` overrides.

    Example:
        >>> add_arguments(parser := argparse.ArgumentParser())
        >>> parser.parse_args(["output_dir=/tmp/demo"]).overrides
        ['output_dir=/tmp/demo']
    """
    parser.add_argument("--config", type=Path, help="YAML config (default: configs/demo.yaml)")
    parser.add_argument(
        "overrides", nargs="*", metavar="KEY=VALUE", help="config overrides, e.g. seed=1"
    )


def run(args: argparse.Namespace) -> int:
    """Run the pipeline and print its comparison table (the summary with paths, evaluations and
    timings is its ``summary.json``); exit code 2 on bad settings, 130 when interrupted.

    Example:
        >>> run(argparse.Namespace(config=None, overrides=["record.episode=3"]))
        2
    """
    from oasis_torchrl.train.config import load_config
    from oasis_torchrl.train.pipeline import run_pipeline

    try:
        result = run_pipeline(load_config(args.config or "demo", args.overrides))
    except (ValueError, FileNotFoundError, ImportError) as error:
        logger.error("cannot run the demo: %s", error)
        return 2
    except KeyboardInterrupt:
        logger.warning("interrupted: run the same command again to continue where it stopped")
        return 130
    sys.stdout.write(result.table() + "\n")
    return 0
