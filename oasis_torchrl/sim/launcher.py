"""Start the embedded A2V server in this process (:class:`LocalServer`) or as a subprocess
(:class:`ServerProcess`), e.g. for tests, examples and offline training; either way with the
worker processes its config asks for.

Both accept a :class:`ServerConfig` plus field overrides. When the config names no API key,
the launcher generates a random one, configures the server with it and exposes it as
``.api_key``, so a launched server is never open to any key by accident.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import grpc
from grpc_health.v1 import health_pb2, health_pb2_grpc

from oasis_torchrl.sim.config import ServerConfig

if TYPE_CHECKING:
    from oasis_torchrl.sim.server import A2VServer

logger = logging.getLogger(__name__)

_POLL_INTERVAL_S = 0.05


def _with_api_key(config: ServerConfig | None, overrides: dict[str, Any]) -> ServerConfig:
    """``config`` with ``overrides`` applied and, if it names no key, a fresh random key."""
    config = dataclasses.replace(config or ServerConfig(), **overrides)
    if not config.api_keys:
        config = dataclasses.replace(config, api_keys=(secrets.token_urlsafe(24),))
    return config


class LocalServer:
    """The embedded A2V server running in this process, on a free loopback port by default
    (with ``config.processes`` worker processes for the sessions' worlds, which stop with it;
    ``processes=0`` keeps everything in this process).

    Args:
        config: Server settings (defaults to :class:`ServerConfig`).
        simulator_factory: Optional world factory handed to
            :class:`~oasis_torchrl.sim.server.A2VServer`.
        **overrides: :class:`ServerConfig` fields replacing those of ``config``.

    Example:
        >>> with LocalServer(width=96, height=64) as server:
        ...     server.endpoint.startswith("http://127.0.0.1:"), len(server.api_key) > 20
        (True, True)
    """

    def __init__(
        self,
        config: ServerConfig | None = None,
        *,
        simulator_factory: Callable[..., Any] | None = None,
        **overrides: Any,
    ) -> None:
        self.config = _with_api_key(config, overrides)
        self._simulator_factory = simulator_factory
        self._server: A2VServer | None = None

    @property
    def api_key(self) -> str:
        """A key the server accepts (the first configured one)."""
        return self.config.api_keys[0]

    @property
    def port(self) -> int:
        """The bound port."""
        if self._server is None:
            raise RuntimeError("LocalServer is not started; call start() first")
        return self._server.port

    @property
    def address(self) -> str:
        """``host:port`` to dial, e.g. ``127.0.0.1:50051``."""
        return self.config.client_address(self.port)

    @property
    def worker_pids(self) -> list[int]:
        """Process ids of the server's worker processes (empty without workers)."""
        if self._server is None:
            raise RuntimeError("LocalServer is not started; call start() first")
        return self._server.worker_pids

    @property
    def endpoint(self) -> str:
        """Endpoint URL for clients, e.g. ``http://127.0.0.1:50051``."""
        return self.config.endpoint(self.port)

    def __getstate__(self) -> dict[str, Any]:
        return dict(self.__dict__, _server=None)  # a running server stays in its process

    def start(self) -> LocalServer:
        """Start serving (idempotent); returns ``self``."""
        from oasis_torchrl.sim.server import A2VServer

        if self._server is None:
            server = A2VServer(self.config, simulator_factory=self._simulator_factory)
            server.start()
            self._server = server
        return self

    def stop(self, grace: float | None = 0.5) -> None:
        """Stop serving and free the port (idempotent)."""
        server, self._server = self._server, None
        if server is not None:
            server.stop(grace)

    def __enter__(self) -> LocalServer:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.stop()


class ServerProcess:
    """The embedded A2V server as a subprocess (``python -m oasis_torchrl.sim``).

    The child reads the config as JSON on its stdin, so API keys never appear on its command
    line, and serves while that pipe stays open: if this process exits or dies without
    stopping it, the child stops too. Readiness: the child writes its bound port to a file
    once serving; the launcher then waits for the gRPC health service to answer SERVING
    (plain-text servers) within ``startup_timeout``. The child's output goes to
    :attr:`log_path`.

    Args:
        config: Server settings (defaults to :class:`ServerConfig`); picklable.
        startup_timeout: Seconds to wait for readiness before failing.
        python: Interpreter to run (defaults to this one).
        **overrides: :class:`ServerConfig` fields replacing those of ``config``.

    Example:
        >>> with ServerProcess(width=96, height=64) as server:
        ...     server.is_running()
        True
    """

    def __init__(
        self,
        config: ServerConfig | None = None,
        *,
        startup_timeout: float = 60.0,
        python: str | None = None,
        **overrides: Any,
    ) -> None:
        self.config = _with_api_key(config, overrides)
        self.startup_timeout = startup_timeout
        self.python = python or sys.executable
        self.port: int | None = None
        self._process: subprocess.Popen[bytes] | None = None
        self._workdir: Path | None = None

    def __getstate__(self) -> dict[str, Any]:
        # A running child stays with the process that started it.
        return dict(self.__dict__, _process=None, port=None, _workdir=None)

    @property
    def api_key(self) -> str:
        """A key the server accepts (the first configured one)."""
        return self.config.api_keys[0]

    @property
    def address(self) -> str:
        """``host:port`` to dial."""
        if self.port is None:
            raise RuntimeError("ServerProcess is not started; call start() first")
        return self.config.client_address(self.port)

    @property
    def endpoint(self) -> str:
        """Endpoint URL for clients, e.g. ``http://127.0.0.1:50051``."""
        return self.config.endpoint(self.port)

    @property
    def pid(self) -> int | None:
        """The child's process id (None before start)."""
        return None if self._process is None else self._process.pid

    @property
    def log_path(self) -> Path | None:
        """File holding the child's stdout and stderr (None before start)."""
        return None if self._workdir is None else self._workdir / "server.log"

    def is_running(self) -> bool:
        """Whether the child process is alive."""
        return self._process is not None and self._process.poll() is None

    def start(self) -> ServerProcess:
        """Spawn the server and wait until it serves; raises RuntimeError if it does not."""
        if self._process is not None:
            return self
        self._workdir = Path(tempfile.mkdtemp(prefix="oasis-server-"))
        port_file = self._workdir / "port"
        command = [self.python, "-m", "oasis_torchrl.sim", "--port-file", str(port_file)]
        with open(self.log_path, "wb") as log:
            self._process = subprocess.Popen(
                command, stdin=subprocess.PIPE, stdout=log, stderr=subprocess.STDOUT
            )
        try:
            self._send_config()
            self._wait_until_ready(port_file, time.monotonic() + self.startup_timeout)
        except BaseException:
            self.kill()
            raise
        logger.info("server process %d serving %s", self._process.pid, self.endpoint)
        return self

    def stop(self, timeout: float = 10.0) -> int | None:
        """SIGTERM (clean shutdown), SIGKILL after ``timeout``; returns the exit code."""
        return self._end(signal.SIGTERM, timeout)

    def kill(self) -> int | None:
        """SIGKILL at once (to test clients against a dead server); returns the exit code."""
        return self._end(signal.SIGKILL, 10.0)

    def log_text(self) -> str:
        """What the child printed so far (empty before start)."""
        path = self.log_path
        return path.read_text(errors="replace") if path is not None and path.exists() else ""

    def __enter__(self) -> ServerProcess:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    def _end(self, signum: signal.Signals, timeout: float) -> int | None:
        process, self._process = self._process, None
        if process is None:
            return None
        if process.poll() is None:
            process.send_signal(signum)
            try:
                process.wait(timeout)
            except subprocess.TimeoutExpired:
                logger.warning("server process %d ignored %s; killing it", process.pid, signum)
                process.kill()
                process.wait()
        if process.stdin is not None:
            with contextlib.suppress(BrokenPipeError):
                process.stdin.close()
        if self._workdir is not None:
            shutil.rmtree(self._workdir, ignore_errors=True)
            self._workdir = None
        return process.returncode

    def _send_config(self) -> None:
        """Hand the config (API keys included) to the child on its stdin, as one line."""
        assert self._process is not None and self._process.stdin is not None
        # A child that died at once breaks the pipe; waiting for readiness reports its output.
        # The pipe stays open: the child serves until it closes (see _end), or this process dies.
        with contextlib.suppress(BrokenPipeError):
            self._process.stdin.write(self.config.to_json().encode() + b"\n")
            self._process.stdin.flush()

    def _wait_until_ready(self, port_file: Path, deadline: float) -> None:
        while not port_file.exists():
            self._check_alive_before(deadline, "write its port file")
            time.sleep(_POLL_INTERVAL_S)
        self.port = int(port_file.read_text())
        if self.config.tls_enabled:
            return  # the port file is written once serving; TLS health would need the CA here
        with grpc.insecure_channel(self.address) as channel:
            health = health_pb2_grpc.HealthStub(channel)
            while not self._reports_serving(health):
                self._check_alive_before(deadline, "report SERVING")
                time.sleep(_POLL_INTERVAL_S)

    @staticmethod
    def _reports_serving(health: health_pb2_grpc.HealthStub) -> bool:
        try:
            reply = health.Check(health_pb2.HealthCheckRequest(service=""), timeout=1.0)
        except grpc.RpcError:
            return False
        return reply.status == health_pb2.HealthCheckResponse.SERVING

    def _check_alive_before(self, deadline: float, step: str) -> None:
        if self._process is not None and self._process.poll() is not None:
            raise RuntimeError(
                f"server process exited with code {self._process.returncode} before it could "
                f"{step}; its output:\n{self.log_text()[-4000:]}"
            )
        if time.monotonic() > deadline:
            raise RuntimeError(
                f"server process did not {step} within {self.startup_timeout} s; its output:\n"
                f"{self.log_text()[-4000:]}"
            )
