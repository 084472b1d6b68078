"""``oasis-torchrl demo``: the main job (what ``make demo`` runs), on the embedded server.

Records autopilot demonstrations as a LeRobot dataset, behaviour-clones a policy on them,
fine-tunes it with TorchRL PPO in the world model, evaluates the references, the clone and the
fine-tuned policy on fixed seeds, and prints their comparison as a table and where everything
is (settings: :class:`~oasis_torchrl.config.DemoConfig`;
:func:`oasis_torchrl.train.pipeline.run_pipeline`).
Any setting can be given as ``key=value``, e.g. ``oasis-torchrl demo output_dir=outputs/demo2
ppo.collector.total_frames=8192``. Finished stages are reused, so running the same command
again after an interruption continues where it stopped.
"""

from __future__ import annotations

import logging
import sys

from omegaconf import DictConfig

from oasis_torchrl.config.pipeline import DemoConfig

logger = logging.getLogger(__name__)

NAME = "demo"
HELP = "the main job: record demonstrations, behaviour cloning, PPO fine-tuning, evaluation"
CONFIG = DemoConfig


def run(cfg: DictConfig) -> int:
    """Run the pipeline and print its comparison table (the summary with paths, evaluations and
    timings is its ``summary.json``); exit code 2 on bad settings, 130 when interrupted.

    Example:
        >>> import tempfile
        >>> from oasis_torchrl.config import load_config
        >>> fresh = f"output_dir={tempfile.mkdtemp()}"  # a finished run's stages would be reused
        >>> run(load_config("demo", ["record.episodes=0", fresh]))
        2
    """
    import torch

    from oasis_torchrl.train.pipeline import run_pipeline

    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    try:
        result = run_pipeline(cfg)
    except (ValueError, FileNotFoundError, ImportError) as error:
        logger.error("cannot run the demo: %s", error)
        return 2
    except KeyboardInterrupt:
        logger.warning("interrupted: run the same command again to continue where it stopped")
        return 130
    sys.stdout.write(result.table() + "\n")
    return 0
