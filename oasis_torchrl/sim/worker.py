"""A worker process of the embedded server: it runs the worlds of the sessions it is given.

The server process (:mod:`oasis_torchrl.sim.worker_pool`) talks to each worker over one pipe:
requests ``(request_id, operation, session_id, arguments)``, answers ``(request_id, kind,
payload)`` with kind ``"ok"`` (the result), ``"request_error"`` (``(code, message, details)``,
reported in-band to the client) or ``"internal"`` (an unexpected fault, logged here). The worker
announces itself with ``("ready", pid)``, serves requests one at a time, and exits on ``None``
(the server stops) or when the pipe breaks (the server died). It ignores SIGINT: a Ctrl-C on
the server's terminal stops the server, which then closes its workers.
"""

from __future__ import annotations

import logging
import os
import signal
import sys
from multiprocessing.connection import Connection
from typing import Any

from oasis_torchrl.proto import common_pb2
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.errors import RequestError
from oasis_torchrl.sim.session_world import LocalWorlds, SessionWorld, SimulatorFactory

logger = logging.getLogger(__name__)

READY = "ready"


class _Worlds:
    """The worlds of this worker's sessions, by session id; built at a session's first Prompt."""

    def __init__(self, config: ServerConfig, simulator_factory: SimulatorFactory) -> None:
        self._host = LocalWorlds(config, simulator_factory)
        self._worlds: dict[str, SessionWorld] = {}

    def run(self, operation: str, session_id: str, arguments: tuple[Any, ...]) -> Any:
        """Run one request on a session's world."""
        if operation == "prompt":
            output_format, prompt, seed = arguments
            world = self._worlds.get(session_id)
            if world is None:
                world = self._worlds[session_id] = self._host.open(session_id, output_format)
            return world.prompt(prompt, seed)
        if operation == "release":
            world = self._worlds.pop(session_id, None)
            return None if world is None else world.release()
        world = self._worlds.get(session_id)
        if world is None:
            raise RequestError(
                common_pb2.ERROR_CODE_PROMPT_SET,
                "no scene yet: call Prompt before Infer (and before depth or scene queries)",
            )
        return getattr(world, operation)(*arguments)

    def close(self) -> None:
        for world in self._worlds.values():
            world.release()
        self._host.close()


def serve_worlds(
    connection: Connection,
    config: ServerConfig,
    simulator_factory: SimulatorFactory,
    log_level: int,
) -> None:
    """The worker's main loop (the target of its process)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.basicConfig(
        level=log_level, format="%(asctime)s %(levelname)s %(name)s[worker]: %(message)s"
    )
    worlds = _Worlds(config, simulator_factory)
    connection.send((READY, os.getpid()))
    try:
        while True:
            try:
                request = connection.recv()
            except (EOFError, OSError):
                return  # the server died
            if request is None:
                return  # the server stops
            request_id, operation, session_id, arguments = request
            connection.send((request_id, *_answer(worlds, operation, session_id, arguments)))
    finally:
        worlds.close()


def _answer(
    worlds: _Worlds, operation: str, session_id: str, arguments: tuple[Any, ...]
) -> tuple[str, Any]:
    try:
        return "ok", worlds.run(operation, session_id, arguments)
    except RequestError as error:
        return "request_error", (error.code, error.message, error.details)
    except Exception:
        logger.exception("internal error in %s of session %s", operation, session_id[:6])
        return "internal", operation


def main() -> None:
    """``python -m oasis_torchrl.sim.worker FD``: serve on the socket with descriptor ``FD``,
    after receiving the server's import path, then its settings."""
    connection = Connection(int(sys.argv[1]))
    sys.path[:] = connection.recv()
    config, simulator_factory, log_level = connection.recv()
    serve_worlds(connection, config, simulator_factory, log_level)


if __name__ == "__main__":
    main()
