"""``python -m oasis_torchrl.sim``: the embedded A2V server as a child process.

Reads its :class:`~oasis_torchrl.sim.config.ServerConfig` as one line of JSON on stdin (so API
keys never appear on a command line), writes the bound port to ``--port-file`` once serving,
and serves until SIGTERM, SIGINT or the end of stdin: the launcher holds the pipe open while it
wants the server, so a launcher that exits or dies without stopping it leaves no server behind.
:class:`~oasis_torchrl.sim.launcher.ServerProcess` starts it; people use ``oasis-torchrl serve``.
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import TextIO

from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.serving import serve

logger = logging.getLogger("oasis_torchrl.sim")


def main(argv: Sequence[str] | None = None) -> int:
    """Parse the flags, read the config from stdin and serve; returns the exit code."""
    parser = argparse.ArgumentParser(prog="python -m oasis_torchrl.sim", description=__doc__)
    parser.add_argument("--port-file", type=Path, help="write the bound port here once serving")
    parser.add_argument("--grace", type=float, default=2.0, help="seconds for in-flight calls")
    parser.add_argument("--log-level", default="INFO", help="logging threshold (default INFO)")
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=args.log_level, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    try:
        config = ServerConfig.from_json(sys.stdin.readline())
    except ValueError as error:
        logger.error("bad server config on stdin: %s", error)
        return 2
    stop = threading.Event()
    threading.Thread(
        target=_stop_at_end_of, args=(sys.stdin, stop), name="oasis-launcher-watch", daemon=True
    ).start()
    return serve(config, port_file=args.port_file, grace=args.grace, stop=stop)


def _stop_at_end_of(stream: TextIO, stop: threading.Event) -> None:
    """Set ``stop`` once ``stream`` ends: the launching process closed it, or is gone."""
    stream.read()
    logger.info("the launching process let go of the server (stdin closed); stopping")
    stop.set()


if __name__ == "__main__":
    sys.exit(main())
