"""``oasis-torchrl film``: the autopilot drives one route on the embedded server, filmed by the
three cameras (settings: :class:`~oasis_torchrl.config.viewing.FilmConfig`).

Named for what it makes, a film of a drive: "drive" is what a policy or a person does through an
env (the drive loop, the drivers, the drive page); this command was ``oasis-torchrl drive``."""

from __future__ import annotations

import json
import sys

from omegaconf import DictConfig

from oasis_torchrl.config.viewing import FilmConfig

NAME = "film"
HELP = "film the autopilot driving one route on the embedded server: the cameras to an MP4"
CONFIG = FilmConfig


def run(cfg: DictConfig) -> int:
    """Film the drive, write ``film.mp4`` and ``summary.json``, print the summary as JSON.

    Example:
        >>> import tempfile
        >>> from oasis_torchrl.config import load_config
        >>> settings = [f"output={tempfile.mkdtemp()}", "steps=2", "width=96", "height=64"]
        >>> run(load_config("film", settings))  # doctest: +ELLIPSIS
        {...
        0
    """
    from oasis_torchrl.film import film_route

    summary = film_route(
        cfg.output,
        prompt=cfg.prompt,
        seed=cfg.seed,
        steps=cfg.steps,
        width=cfg.width,
        height=cfg.height,
    )
    sys.stdout.write(json.dumps(summary.__dict__, indent=2) + "\n")
    return 0
