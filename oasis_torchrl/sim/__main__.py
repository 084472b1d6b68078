"""``python -m oasis_torchrl.sim``: the embedded A2V server as a child process.

Reads its :class:`~oasis_torchrl.sim.config.ServerConfig` as JSON on stdin (so API keys never
appear on a command line), writes the bound port to ``--port-file`` once serving, and serves
until SIGTERM or SIGINT. :class:`~oasis_torchrl.sim.launcher.ServerProcess` starts it; people
use ``oasis-torchrl serve``.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

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
        config = ServerConfig.from_json(sys.stdin.read())
    except ValueError as error:
        logger.error("bad server config on stdin: %s", error)
        return 2
    return serve(config, port_file=args.port_file, grace=args.grace)


if __name__ == "__main__":
    sys.exit(main())
