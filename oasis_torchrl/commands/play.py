"""``oasis-torchrl play``: a person drives the world model in a browser page and records what
they drive as a LeRobot dataset (settings: :class:`~oasis_torchrl.config.web.PlayConfig`).

A command of its own rather than a flag of ``film`` (the autopilot filmed on a route): the page
is a server that runs until stopped, with its own settings (address, token, dataset, policy).
Open the logged URL; over SSH forward the port (``ssh -L 8080:127.0.0.1:8080 host``). Stop with
Ctrl-C or SIGTERM: every saved episode is kept, a running one is dropped.
"""

from __future__ import annotations

import logging

from omegaconf import DictConfig

from oasis_torchrl.commands._signals import sigterm_as_interrupt
from oasis_torchrl.config import to_object
from oasis_torchrl.config.web import PlayConfig

logger = logging.getLogger(__name__)

NAME = "play"
HELP = "drive the world model in a browser page (keyboard, gamepad) and record LeRobot episodes"
CONFIG = PlayConfig


def run(settings: DictConfig) -> int:
    """Serve the page until interrupted; exit code 0, 2 on bad settings or a world that does not
    open, 130 when interrupted.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> run(load_config("play", ["policy=nowhere.pt"]))
        2
    """
    from oasis_torchrl.data.quiet import quiet_dataset_libraries
    from oasis_torchrl.web import RunningPage

    cfg: PlayConfig = to_object(settings)
    quiet_dataset_libraries()
    try:
        with sigterm_as_interrupt() as stop, RunningPage(cfg):
            stop.wait()  # RunningPage logs the page's URL
    except (ValueError, FileExistsError, FileNotFoundError, OSError) as error:
        logger.error("cannot serve the page: %s", error)
        return 2
    except KeyboardInterrupt:
        logger.info("stopped; every saved episode is kept")
        return 130
    return 0
