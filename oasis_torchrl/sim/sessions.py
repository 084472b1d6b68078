"""A2V sessions of the embedded server and the registry holding them.

A :class:`Session` is one session's identity, lock and world handle (the world itself, see
:mod:`~oasis_torchrl.sim.session_world`, runs in this process or a worker's). The
:class:`SessionRegistry` creates sessions within the configured limits, resolves ids (checking
the owning key and the ``x-session-target`` pin), expires idle sessions, and remembers finished
and lost ones for a while, so late calls get ``ALREADY_FINISHED`` or an ``INVALID_SESSION``
naming why the session was lost.
"""

from __future__ import annotations

import hmac
import logging
import secrets
import threading
import time
from collections import OrderedDict
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import Any

import grpc

from oasis_torchrl.proto import common_pb2
from oasis_torchrl.sim.auth import key_fingerprint
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.errors import RequestError, StatusError
from oasis_torchrl.sim.session_world import WorldHandle, WorldHost

logger = logging.getLogger(__name__)

# Finished and lost sessions remembered (for clear answers to late calls) at most; the oldest go.
_MAX_ENDED_REMEMBERED = 4096


class Session:
    """One A2V session as the server tracks it: id, owning key, pinning target, lock, and its
    world (in this process or a worker's).

    Hold :attr:`lock` while using :attr:`world` (the registry's :meth:`SessionRegistry.use`
    does): it serialises the session's calls while different sessions run concurrently.

    Example:
        >>> from oasis_torchrl.sim.session_world import LocalWorlds
        >>> worlds = LocalWorlds(ServerConfig(width=64, height=48, api_keys=("k",)))
        >>> session = Session("id", b"key", "target", worlds.open("id", 1))
        >>> session.release(); session.closed
        True
        >>> worlds.close()
    """

    def __init__(self, session_id: str, key_digest: bytes, target: str, world: WorldHandle) -> None:
        self.session_id = session_id
        self.key_digest = key_digest
        self.target = target
        self.world = world
        self.lock = threading.Lock()
        self.closed = False  # set once finished, expired or lost

    def release(self) -> None:
        """Mark the session closed and release its world."""
        self.closed = True
        self.world.release()


class SessionRegistry:
    """All sessions of one server: creation within limits, lookup, finish and idle expiry.

    Another key's session is reported exactly like an unknown one (``INVALID_SESSION``), so a
    key cannot probe which session ids exist. Session limits are reported as the gRPC status
    RESOURCE_EXHAUSTED (a transport-level, retryable condition).

    Example:
        >>> from oasis_torchrl.sim.session_world import LocalWorlds
        >>> config = ServerConfig(api_keys=("k",))
        >>> worlds = LocalWorlds(config)
        >>> registry = SessionRegistry(config, worlds)
        >>> session = registry.open(b"digest", common_pb2.FRAME_FORMAT_VP9)
        >>> with registry.use(session.session_id, b"digest", session.target) as same:
        ...     same is session
        True
        >>> registry.close(); worlds.close()
    """

    def __init__(self, config: ServerConfig, worlds: WorldHost) -> None:
        self._config = config
        self._worlds = worlds
        self._lock = threading.Lock()
        self._open: dict[str, Session] = {}
        self._last_used: dict[str, float] = {}
        self._finished: OrderedDict[str, bytes] = OrderedDict()  # id -> key digest
        self._lost: OrderedDict[str, tuple[bytes, str]] = OrderedDict()  # id -> digest, cause
        self._node = secrets.token_hex(4)
        self._stop_reaper = threading.Event()
        self._reaper: threading.Thread | None = None

    def open(self, key_digest: bytes, output_format: int) -> Session:
        """Create a session for a key, or raise RESOURCE_EXHAUSTED at the session limits."""
        session_id = secrets.token_urlsafe(24)
        with self._lock:
            self._check_limits(key_digest)
            session = Session(
                session_id,
                key_digest,
                f"oasis-sim-{self._node}-{secrets.token_hex(4)}",
                self._worlds.open(session_id, output_format),
            )
            self._open[session_id] = session
            self._last_used[session_id] = time.monotonic()
        logger.debug("session %s opened for key %s", session_id[:6], key_fingerprint(key_digest))
        return session

    @contextmanager
    def use(self, session_id: str, key_digest: bytes, target: str | None) -> Iterator[Session]:
        """Resolve a session of ``key_digest`` pinned to ``target`` and hold its lock."""
        session = self._lookup(session_id, key_digest)
        if target is None:
            raise RequestError(
                common_pb2.ERROR_CODE_INVALID_SESSION,
                "missing x-session-target metadata: send the value Initialize returned in its "
                "initial metadata on every call of the session",
            )
        if not hmac.compare_digest(target.encode(), session.target.encode()):
            raise RequestError(
                common_pb2.ERROR_CODE_INVALID_SESSION,
                "x-session-target does not match this session; send the value its Initialize "
                "returned",
            )
        with session.lock:
            if session.closed:  # finished or expired while this call waited for the lock
                raise self._closed_error(session_id, key_digest)
            self._touch(session_id)
            try:
                yield session
            finally:
                self._touch(session_id)

    def finish(self, session: Session) -> None:
        """End a session (call while holding its lock): later calls get ALREADY_FINISHED."""
        with self._lock:
            self._forget(session.session_id)
            _remember(self._finished, session.session_id, session.key_digest)
        session.release()
        logger.debug("session %s finished", session.session_id[:6])

    def lose(self, session_ids: Iterable[str], cause: str) -> None:
        """Drop sessions whose worlds are gone (their worker process died): later calls get
        INVALID_SESSION naming ``cause``."""
        with self._lock:
            lost = [self._open[i] for i in session_ids if i in self._open]
            for session in lost:
                self._forget(session.session_id)
                _remember(self._lost, session.session_id, (session.key_digest, cause))
        for session in lost:
            session.closed = True

    def expire_idle(self) -> int:
        """Drop sessions idle for longer than ``idle_timeout_s``; returns how many."""
        with self._lock:
            sessions = list(self._open.values())
        return sum(self._expire_if_idle(session) for session in sessions)

    def start_reaper(self) -> None:
        """Expire idle sessions in a background thread until :meth:`close`."""
        interval = min(max(self._config.idle_timeout_s / 4, 0.01), 5.0)
        self._reaper = threading.Thread(
            target=self._reap_until_stopped, args=(interval,), name="oasis-session-reaper"
        )
        self._reaper.daemon = True
        self._reaper.start()

    def close(self) -> None:
        """Stop the reaper and release every session."""
        self._stop_reaper.set()
        if self._reaper is not None:
            self._reaper.join()
        with self._lock:
            sessions = list(self._open.values())
            self._open.clear()
            self._last_used.clear()
        for session in sessions:
            with session.lock:
                session.release()

    def _reap_until_stopped(self, interval: float) -> None:
        while not self._stop_reaper.wait(interval):
            self.expire_idle()

    def _lookup(self, session_id: str, key_digest: bytes) -> Session:
        with self._lock:
            session = self._open.get(session_id)
        if session is None or not hmac.compare_digest(session.key_digest, key_digest):
            raise self._closed_error(session_id, key_digest)
        if self._expire_if_idle(session):
            raise self._closed_error(session_id, key_digest)
        return session

    def _closed_error(self, session_id: str, key_digest: bytes) -> RequestError:
        with self._lock:
            finished_by = self._finished.get(session_id)
            lost_by, cause = self._lost.get(session_id, (None, ""))
        if lost_by is not None and hmac.compare_digest(lost_by, key_digest):
            return RequestError(
                common_pb2.ERROR_CODE_INVALID_SESSION,
                f"session lost: {cause}; Initialize a new session",
            )
        if finished_by is not None and hmac.compare_digest(finished_by, key_digest):
            return RequestError(
                common_pb2.ERROR_CODE_ALREADY_FINISHED,
                "session already finished; Initialize a new session",
            )
        return RequestError(
            common_pb2.ERROR_CODE_INVALID_SESSION,
            "unknown or expired session id for this API key; Initialize a new session",
        )

    def _check_limits(self, key_digest: bytes) -> None:
        limit = self._config.max_sessions
        if len(self._open) >= limit:
            raise StatusError(
                grpc.StatusCode.RESOURCE_EXHAUSTED,
                f"the server holds its limit of {limit} sessions; Finish unused sessions or "
                "retry later",
            )
        per_key = self._config.max_sessions_per_key
        if sum(s.key_digest == key_digest for s in self._open.values()) >= per_key:
            raise StatusError(
                grpc.StatusCode.RESOURCE_EXHAUSTED,
                f"this API key holds its limit of {per_key} sessions; Finish unused sessions "
                "or retry later",
            )

    def _expire_if_idle(self, session: Session) -> bool:
        """Drop ``session`` if it idled past the timeout; a session in a call is never idle."""
        if not session.lock.acquire(blocking=False):
            return False
        try:
            deadline = time.monotonic() - self._config.idle_timeout_s
            with self._lock:
                idle = self._last_used.get(session.session_id, deadline) < deadline
                if idle:
                    self._forget(session.session_id)
            if idle:
                session.release()
                logger.info("session %s expired after idling", session.session_id[:6])
            return idle
        finally:
            session.lock.release()

    def _forget(self, session_id: str) -> None:
        self._open.pop(session_id, None)
        self._last_used.pop(session_id, None)

    def _touch(self, session_id: str) -> None:
        with self._lock:
            if session_id in self._last_used:
                self._last_used[session_id] = time.monotonic()


def _remember(ended: OrderedDict[str, Any], session_id: str, value: Any) -> None:
    """Remember an ended session, forgetting the oldest beyond the limit."""
    ended[session_id] = value
    while len(ended) > _MAX_ENDED_REMEMBERED:
        ended.popitem(last=False)
