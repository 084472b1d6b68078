"""The server's worker processes: each runs the worlds of its sessions on its own core.

The server process keeps the gRPC front (authentication, limits, idle expiry, injected faults
and latency, session pinning); every session's world lives in one worker for the session's
life, chosen at Initialize (the worker with the fewest sessions). A :class:`RemoteWorld` forwards
the server's calls over the worker's pipe (see :mod:`oasis_torchrl.sim.worker` for the
messages) and waits for the answer, already serialised.

A worker that dies loses only its own sessions: their pending and later calls get
``INVALID_SESSION`` naming the worker and how it ended, the server is told which sessions are
gone, the log says which worker died and why, and a fresh worker takes its place for new
sessions.
"""

from __future__ import annotations

import atexit
import contextlib
import itertools
import logging
import signal
import socket
import subprocess
import sys
import threading
import weakref
from collections.abc import Callable
from concurrent.futures import Future
from multiprocessing.connection import Connection
from typing import Any

import grpc
import numpy as np

from oasis_torchrl.proto import common_pb2
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.errors import RequestError, StatusError
from oasis_torchrl.sim.session_world import InferRecord, SimulatorFactory
from oasis_torchrl.sim.simulator import Simulator
from oasis_torchrl.sim.worker import READY

logger = logging.getLogger(__name__)

#: Seconds a starting worker has to announce itself.
STARTUP_TIMEOUT_S = 60.0
#: Seconds a closing worker has to exit before it is killed.
EXIT_TIMEOUT_S = 5.0

#: Called with the ids of sessions whose worker died and a description of the cause.
LossListener = Callable[[list[str], str], None]


def describe_exit(exit_code: int | None) -> str:
    """How a process ended, from its exit code.

    Example:
        >>> describe_exit(-9), describe_exit(1)
        ('killed by signal SIGKILL', 'exited with code 1')
    """
    if exit_code is None:
        return "closed its pipe"
    if exit_code < 0:
        try:
            return f"killed by signal {signal.Signals(-exit_code).name}"
        except ValueError:
            return f"killed by signal {-exit_code}"
    return f"exited with code {exit_code}"


class _Worker:
    """One worker process, its pipe, and the server-side bookkeeping of its calls."""

    def __init__(
        self,
        index: int,
        config: ServerConfig,
        simulator_factory: SimulatorFactory,
        on_death: Callable[[_Worker, str], None],
    ) -> None:
        self.index = index
        self.sessions: set[str] = set()
        self._on_death = on_death
        self._lock = threading.Lock()
        self._pending: dict[int, Future[Any]] = {}
        self._ids = itertools.count()
        self._alive = True
        self._death = ""
        self._death_known = threading.Event()
        self.process, self._connection = _launch(
            (config, simulator_factory, logging.getLogger().getEffectiveLevel())
        )
        self._ready = threading.Event()
        self._reader = threading.Thread(
            target=self._read, name=f"oasis-worker-{index}-reader", daemon=True
        )
        self._reader.start()

    @property
    def alive(self) -> bool:
        """Whether the process is running (as far as its pipe tells)."""
        return self._alive

    def wait_ready(self, timeout: float) -> None:
        """Wait for the worker's announcement; raise RuntimeError if it dies or is late."""
        if not self._ready.wait(timeout):
            raise RuntimeError(f"server worker {self.index} did not start within {timeout} s")
        if not self._alive:
            raise RuntimeError(f"server worker {self.index} {self._death} while starting")

    def call(self, operation: str, session_id: str, *arguments: Any) -> Any:
        """Run ``operation`` on a session's world in the worker; its answer, or its error."""
        future: Future[Any] = Future()
        with self._lock:
            alive = self._alive
            if alive:
                request_id = next(self._ids)
                self._pending[request_id] = future
                with contextlib.suppress(OSError):
                    # A send to a dead worker leaves the call pending: the reader sees the pipe
                    # close, learns how the worker ended, and fails the call with that cause.
                    self._connection.send((request_id, operation, session_id, arguments))
        if not alive:
            raise self.lost_error()
        return future.result()

    def lost_error(self) -> RequestError:
        """What a call of a session on this (dead) worker gets, once the cause is known."""
        self._death_known.wait(EXIT_TIMEOUT_S)
        return RequestError(common_pb2.ERROR_CODE_INVALID_SESSION, self.death_message())

    def death_message(self) -> str:
        """Which worker died, and how."""
        return f"server worker process {self.index} (pid {self.process.pid}) {self._death}"

    def ask_to_exit(self) -> None:
        """Tell the worker to exit (idempotent); :meth:`close` waits for it."""
        with self._lock:
            was_alive, self._alive = self._alive, False
            if was_alive:
                self._death = "was stopped with the server"
                self._death_known.set()
                with contextlib.suppress(OSError):  # already gone
                    self._connection.send(None)

    def close(self) -> None:
        """Ask the worker to exit, reap it (killing it if it lingers), close the pipe."""
        self.ask_to_exit()
        try:
            self.process.wait(EXIT_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self._reader.join()  # the worker's exit ends its reads
        self._connection.close()

    def _read(self) -> None:
        while True:
            try:
                message = self._connection.recv()
            except (EOFError, OSError):
                break
            if message[0] == READY:
                self._ready.set()
                continue
            request_id, kind, payload = message
            with self._lock:
                future = self._pending.pop(request_id)
            if kind == "ok":
                future.set_result(payload)
            else:
                future.set_exception(_error(kind, payload))
        self._died()

    def _died(self) -> None:
        with self._lock:
            stopping = not self._alive
            self._alive = False
            pending, self._pending = self._pending, {}
        if not stopping:
            try:
                self._death = describe_exit(self.process.wait(EXIT_TIMEOUT_S))
            except subprocess.TimeoutExpired:
                self._death = describe_exit(None)
            self._death_known.set()
        error = self.lost_error()
        for future in pending.values():
            future.set_exception(error)
        self._ready.set()
        if not stopping:
            self._on_death(self, self.death_message())


def _launch(settings: tuple[Any, ...]) -> tuple[subprocess.Popen[bytes], Connection]:
    """Start a worker (``python -m oasis_torchrl.sim.worker``) on one end of a socket pair and
    hand it this process's import path, then ``settings``; returns it and our end.

    A fresh interpreter, not ``multiprocessing``: that would re-import the caller's main module
    in the worker (unguarded scripts would start servers recursively).
    """
    ours, theirs = socket.socketpair()
    with theirs:
        process = subprocess.Popen(
            [sys.executable, "-m", "oasis_torchrl.sim.worker", str(theirs.fileno())],
            stdin=subprocess.DEVNULL,
            pass_fds=(theirs.fileno(),),
        )
    connection = Connection(ours.detach())
    connection.send(sys.path)  # so the worker can unpickle a simulator factory defined here
    connection.send(settings)
    return process, connection


def _error(kind: str, payload: Any) -> Exception:
    """The server-side exception of a worker's failure answer."""
    if kind == "request_error":
        return RequestError(*payload)
    return StatusError(grpc.StatusCode.INTERNAL, "internal server error")


class RemoteWorld:
    """A session's world in a worker process (see :class:`~.session_world.WorldHandle`)."""

    def __init__(
        self, worker: _Worker, session_id: str, output_format: int, last_frame_only: bool
    ) -> None:
        self._worker = worker
        self._session_id = session_id
        self._delivery = (output_format, last_frame_only)

    def prompt(self, prompt: str, seed: int, *, expert: bool = False) -> None:
        """Set a new scene (the worker builds the world at the first Prompt)."""
        self._worker.call("prompt", self._session_id, self._delivery, prompt, seed, expert)

    def infer(self, sequence_num: int, actions: np.ndarray) -> InferRecord:
        """Advance the world by 4 actions."""
        return self._worker.call("infer", self._session_id, sequence_num, actions)

    def depth(self) -> bytes:
        """The serialised depth answer."""
        return self._worker.call("depth", self._session_id)

    def scene(self) -> bytes:
        """The serialised scene answer."""
        return self._worker.call("scene", self._session_id)

    def release(self) -> None:
        """Drop the world in the worker (nothing to do if the worker is gone)."""
        self._worker.sessions.discard(self._session_id)
        if self._worker.alive:
            with contextlib.suppress(RequestError):  # it died meanwhile: the world is gone too
                self._worker.call("release", self._session_id)


class WorkerPool:
    """``processes`` worker processes running the sessions' worlds.

    Args:
        config: The server's settings (each worker builds its worlds from them).
        processes: Worker processes to run.
        on_lost: Told the sessions a dead worker took with it, and why.
        simulator_factory: Builds each session's simulator (it must pickle: it is sent to the
            workers).

    Example:
        >>> pool = WorkerPool(ServerConfig(width=64, height=48, api_keys=("k",)), 1,
        ...                   on_lost=lambda ids, cause: None)
        >>> pool.start()
        >>> world = pool.open("id", common_pb2.FRAME_FORMAT_JPEG)
        >>> world.prompt("rural", 1)
        >>> len(world.infer(0, np.zeros((4, 2), np.float32)).truth) > 0
        True
        >>> pool.close()
    """

    def __init__(
        self,
        config: ServerConfig,
        processes: int,
        *,
        on_lost: LossListener,
        simulator_factory: SimulatorFactory = Simulator,
    ) -> None:
        self._config = config
        self._processes = processes
        self._on_lost = on_lost
        self._simulator_factory = simulator_factory
        self._lock = threading.Lock()
        self._workers: list[_Worker] = []
        self._closing = False

    @property
    def pids(self) -> list[int]:
        """The process ids of the current workers, by worker index."""
        return [worker.process.pid for worker in self._workers]

    def start(self) -> None:
        """Start the workers and wait until every one is ready."""
        _RUNNING.add(self)
        self._workers = [self._spawn(index) for index in range(self._processes)]
        try:
            for worker in self._workers:
                worker.wait_ready(STARTUP_TIMEOUT_S)
        except BaseException:
            self.close()
            raise
        logger.info("%d server worker processes ready: pids %s", self._processes, self.pids)

    def open(
        self, session_id: str, output_format: int, *, last_frame_only: bool = False
    ) -> RemoteWorld:
        """Pin a new session to the live worker with the fewest sessions."""
        with self._lock:
            live = [worker for worker in self._workers if worker.alive]
            if not live:
                raise StatusError(
                    grpc.StatusCode.UNAVAILABLE, "no server worker process runs; retry later"
                )
            worker = min(live, key=lambda candidate: len(candidate.sessions))
            worker.sessions.add(session_id)
        return RemoteWorld(worker, session_id, output_format, last_frame_only)

    def close(self) -> None:
        """Stop every worker."""
        with self._lock:
            self._closing = True
            workers = list(self._workers)
        # All at once: each worker's interpreter takes a while to exit.
        for worker in workers:
            worker.ask_to_exit()
        for worker in workers:
            worker.close()
        _RUNNING.discard(self)

    def _spawn(self, index: int) -> _Worker:
        return _Worker(index, self._config, self._simulator_factory, self._replace)

    def _replace(self, dead: _Worker, cause: str) -> None:
        """A worker died: report it and its sessions, and start a fresh one in its place."""
        lost = sorted(dead.sessions)
        logger.error("%s; its %d session(s) are lost", cause, len(lost))
        self._on_lost(lost, cause)
        with self._lock:
            if self._closing:
                return
            try:
                fresh = self._spawn(dead.index)
            except (OSError, RuntimeError):
                logger.exception("server worker process %d could not be restarted", dead.index)
                return
            self._workers[dead.index] = fresh
        logger.info("server worker process %d restarted: pid %d", dead.index, fresh.process.pid)


#: Pools with running workers: stopped at interpreter exit before multiprocessing terminates
#: their processes (which would look like deaths).
_RUNNING: weakref.WeakSet[WorkerPool] = weakref.WeakSet()


@atexit.register
def _close_running_pools() -> None:
    for pool in list(_RUNNING):
        pool.close()
