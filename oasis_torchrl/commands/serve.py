"""``oasis-torchrl serve``: run the embedded A2V server until SIGTERM or SIGINT (settings:
:class:`~oasis_torchrl.config.serving.ServeConfig`). API keys are better passed in
``OASIS_SERVER_API_KEYS`` than with ``--api-key``: command lines are visible to every user of
the machine.
"""

from __future__ import annotations

import logging
from pathlib import Path

from omegaconf import DictConfig

from oasis_torchrl.config import to_object
from oasis_torchrl.config.serving import ServeConfig

logger = logging.getLogger(__name__)

NAME = "serve"
HELP = "run the embedded A2V server (procedural driving simulator) until SIGTERM/SIGINT"
CONFIG = ServeConfig


def run(settings: DictConfig) -> int:
    """Start the server, write ``port_file``, serve until a signal, then stop cleanly.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> run(load_config("serve", ["tls_cert=/no/cert.pem", "tls_key=/no/key.pem"]))
        2
    """
    from oasis_torchrl.sim.serving import serve

    cfg: ServeConfig = to_object(settings)
    port_file = None if cfg.port_file is None else Path(cfg.port_file)
    return serve(cfg.server_config(), port_file=port_file, grace=cfg.grace)
