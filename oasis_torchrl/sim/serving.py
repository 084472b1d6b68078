"""Run the embedded A2V server in the foreground until SIGTERM or SIGINT.

What ``oasis-torchrl serve`` and a launched server process (``python -m oasis_torchrl.sim``)
both do: start the server, announce its port through a file once it serves, wait for a
signal, then stop cleanly, letting in-flight calls finish within a grace period.
"""

from __future__ import annotations

import logging
import signal
import threading
from pathlib import Path

from oasis_torchrl.atomic import written_whole
from oasis_torchrl.sim.config import ServerConfig

logger = logging.getLogger(__name__)


def write_port_file(path: Path, port: int) -> None:
    """Write ``port`` to ``path`` atomically, so a reader never sees a partial file.

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "port"
        >>> write_port_file(path, 50051)
        >>> path.read_text()
        '50051\\n'
    """
    with written_whole(path) as partial:
        partial.write_text(f"{port}\n")


def wait_for_signal(stop: threading.Event) -> None:
    """Block until SIGTERM, SIGINT or ``stop`` (signal handlers can only be set from the main
    thread)."""
    if threading.current_thread() is threading.main_thread():
        for signum in (signal.SIGTERM, signal.SIGINT):
            signal.signal(signum, lambda received, frame: stop.set())
    # Short waits keep the main thread responsive to signals on every platform.
    while not stop.wait(0.5):
        pass


def serve(
    config: ServerConfig,
    *,
    port_file: Path | None = None,
    grace: float = 2.0,
    stop: threading.Event | None = None,
) -> int:
    """Serve ``config`` until a signal (or ``stop`` is set); returns the exit code (2: the
    server could not start).

    ``port_file`` receives the bound port once the server serves; in-flight calls get
    ``grace`` seconds at shutdown.
    """
    from oasis_torchrl.sim.server import A2VServer

    try:
        server = A2VServer(config)
        logger.info("starting with %s", config.redacted())
        server.start()
    except (ValueError, OSError, RuntimeError) as error:
        logger.error("cannot start the server: %s", error)
        return 2
    if port_file is not None:
        write_port_file(port_file, server.port)
    logger.info("serving %s; stop with SIGTERM or Ctrl-C", server.endpoint)
    try:
        wait_for_signal(stop or threading.Event())
    finally:
        logger.info("shutting down")
        server.stop(grace)
    return 0
