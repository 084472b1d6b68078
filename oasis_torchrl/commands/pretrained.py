"""``oasis-torchrl pretrained {list,path,ship}``: the policies the package ships.

``list`` prints their names, ``path NAME`` the folder of one (a LeRobot policy folder:
``lerobot-eval --policy.path=$(oasis-torchrl pretrained path ppo-scratch)``), and
``ship POLICY NAME`` adds a trained policy with its card
(:func:`~oasis_torchrl.train.cards.ship_policy`). Everywhere a policy is named,
``pretrained:NAME`` loads one: ``oasis-torchrl eval policy=pretrained:ppo-scratch``.
"""

from __future__ import annotations

import logging
import sys

from omegaconf import DictConfig

from oasis_torchrl.config.pretrained import (
    PretrainedListConfig,
    PretrainedPathConfig,
    ShipConfig,
)

logger = logging.getLogger(__name__)

NAME = "pretrained"
HELP = "the shipped policies: list them, print one's folder, or ship a trained one with its card"
CONFIG = {"list": PretrainedListConfig, "path": PretrainedPathConfig, "ship": ShipConfig}


def run(cfg: DictConfig, action: str) -> int:
    """Run ``action``; exit code 2 on an unknown name, a run lacking a file the card needs or
    a policy already shipped under that name.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> run(load_config(PretrainedPathConfig, ["name=nothing-by-that-name"]), "path")
        2
    """
    from oasis_torchrl.drivers.pretrained import pretrained_path, shipped_policies

    if action == "list":
        names = shipped_policies()
        if not names:  # stdout stays empty for scripts; the person reading is told why
            logger.warning("no policy is shipped yet (docs/guides/training.md: Shipped policies)")
        sys.stdout.writelines(f"{name}\n" for name in names)
        return 0
    try:
        if action == "path":
            sys.stdout.write(f"{pretrained_path(cfg.name)}\n")
            return 0
        from oasis_torchrl.train.cards import ship_policy

        ship_policy(cfg)
    except (ValueError, FileNotFoundError, FileExistsError) as error:
        logger.error("pretrained %s: %s", action, error)
        return 2
    return 0
