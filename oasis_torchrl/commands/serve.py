"""``oasis-torchrl serve``: run the embedded A2V server until SIGTERM or SIGINT (settings:
:class:`~oasis_torchrl.config.serving.ServeConfig`). API keys are better passed in
``OASIS_SERVER_API_KEYS`` than with ``--api-key``: command lines are visible to every user of
the machine.
"""

from __future__ import annotations

import logging
import os
import signal
import threading
from pathlib import Path

from omegaconf import DictConfig

from oasis_torchrl.config import to_object
from oasis_torchrl.config.serving import ServeConfig

logger = logging.getLogger(__name__)

NAME = "serve"
HELP = "run the embedded A2V server (procedural driving simulator) until SIGTERM/SIGINT"
CONFIG = ServeConfig


def _write_port_file(path: Path, port: int) -> None:
    """Write the port atomically, so a reader never sees a partial file."""
    partial = path.with_name(path.name + ".partial")
    partial.write_text(f"{port}\n")
    os.replace(partial, path)


def _wait_for_signal() -> None:
    """Block until SIGTERM or SIGINT (handlers can only be set from the main thread)."""
    stop = threading.Event()
    if threading.current_thread() is threading.main_thread():
        for signum in (signal.SIGTERM, signal.SIGINT):
            signal.signal(signum, lambda received, frame: stop.set())
    # Short waits keep the main thread responsive to signals on every platform.
    while not stop.wait(0.5):
        pass


def run(settings: DictConfig) -> int:
    """Start the server, write ``port_file``, serve until a signal, then stop cleanly.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> run(load_config("serve", ["tls_cert=/no/cert.pem", "tls_key=/no/key.pem"]))
        2
    """
    from oasis_torchrl.sim.server import A2VServer

    try:
        cfg: ServeConfig = to_object(settings)
        config = cfg.server_config()
        server = A2VServer(config)
        logger.info("starting with %s", config.redacted())
        server.start()
    except (ValueError, OSError, RuntimeError) as error:
        logger.error("cannot start the server: %s", error)
        return 2
    if cfg.port_file is not None:
        _write_port_file(Path(cfg.port_file), server.port)
    logger.info("serving %s; stop with SIGTERM or Ctrl-C", server.endpoint)
    try:
        _wait_for_signal()
    finally:
        logger.info("shutting down")
        server.stop(cfg.grace)
    return 0
