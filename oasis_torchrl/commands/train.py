"""``oasis-torchrl train {ppo,bc,motion,depth}``: train a driving policy, or a frames-only reward's
network.

``train ppo`` runs TorchRL PPO in the world model (:class:`~oasis_torchrl.config.PPOConfig`);
``train bc`` runs behaviour cloning on a LeRobot dataset (:class:`~oasis_torchrl.config.BCConfig`);
``train motion`` fits the frames-only reward's motion network to the embedded world's ground truth
(or, with ``dataset=DIR``, its crash heads to the crash marks of a LeRobot dataset)
(:class:`~oasis_torchrl.config.reward_networks.MotionTrainConfig`); ``train depth`` the reference
reward's small depth network to its depth
(:class:`~oasis_torchrl.config.reward_networks.DepthTrainConfig`).
Any setting can be given as ``key=value``, e.g.
``oasis-torchrl train ppo env.num_envs=4 collector.total_frames=20000 logger.backend=tensorboard``.
"""

from __future__ import annotations

import logging
import sys

from omegaconf import DictConfig

from oasis_torchrl.config.reward_networks import DepthTrainConfig, MotionTrainConfig
from oasis_torchrl.config.training import BCConfig, PPOConfig

logger = logging.getLogger(__name__)

NAME = "train"
HELP = (
    "train a driving policy: ppo (TorchRL, in the world model) or bc (LeRobot dataset); or "
    "motion (the frames-only reward's network) or depth (the reference reward's depth network)"
)
CONFIG = {"ppo": PPOConfig, "bc": BCConfig, "motion": MotionTrainConfig, "depth": DepthTrainConfig}


def lost_worker(error: BaseException) -> bool:
    """Whether ``error`` is a Ray collector worker's death
    (:class:`~oasis_torchrl.distributed.WorkerLostError`; Ray, an extra, is loaded if so).

    Example:
        >>> lost_worker(RuntimeError("anything else"))
        False
    """
    collection = sys.modules.get("oasis_torchrl.distributed.ray_collection")
    return collection is not None and isinstance(error, collection.WorkerLostError)


def run(cfg: DictConfig, algorithm: str) -> int:
    """Train, then log where the results are; exit code 2 on bad settings, 1 when a Ray
    collector worker died (one line: what died and how to go on), 130 when interrupted.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> run(load_config("bc"), "bc")  # no dataset.root
        2
    """
    try:
        if algorithm == "ppo":
            from oasis_torchrl.train.ppo import train_ppo

            result = train_ppo(cfg)
            logger.info("PPO done: checkpoint %s, policy %s", result.checkpoint, result.policy_dir)
        elif algorithm == "motion":
            from oasis_torchrl.train.motion import train_motion

            logger.info("motion network done: %s", train_motion(cfg).path)
            return 0
        elif algorithm == "depth":
            from oasis_torchrl.train.depth import train_depth

            logger.info("depth network done: %s", train_depth(cfg).path)
            return 0
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
    except RuntimeError as error:
        if not lost_worker(error):
            raise
        logger.error(
            "cannot train: %s; resume=latest continues from the last checkpoint, "
            "ray.on_failure=continue carries on without a lost worker",
            error,
        )
        return 1
    if result.final_eval is not None:
        logger.info("evaluation: %s", result.final_eval.summary())
    return 0
