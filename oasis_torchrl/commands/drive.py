"""``oasis-torchrl drive``: the autopilot drives one route on the embedded server, filmed by the
three cameras (settings: :class:`~oasis_torchrl.config.viewing.DriveConfig`)."""

from __future__ import annotations

import json
import sys

from omegaconf import DictConfig

from oasis_torchrl.config.viewing import DriveConfig

NAME = "drive"
HELP = "the autopilot drives one route on the embedded server; the cameras go to an MP4"
CONFIG = DriveConfig


def run(cfg: DictConfig) -> int:
    """Drive, write ``drive.mp4`` and ``summary.json``, print the summary as JSON.

    Example:
        >>> import tempfile
        >>> from oasis_torchrl.config import load_config
        >>> settings = [f"output={tempfile.mkdtemp()}", "steps=2", "width=96", "height=64"]
        >>> run(load_config("drive", settings))  # doctest: +ELLIPSIS
        {...
        0
    """
    from oasis_torchrl.drive import drive_route

    summary = drive_route(
        cfg.output,
        prompt=cfg.prompt,
        seed=cfg.seed,
        steps=cfg.steps,
        width=cfg.width,
        height=cfg.height,
    )
    sys.stdout.write(json.dumps(summary.__dict__, indent=2) + "\n")
    return 0
