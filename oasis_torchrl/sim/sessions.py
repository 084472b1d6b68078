"""A2V sessions of the embedded server: per-session world state and the registry holding them.

A :class:`Session` owns one simulator and one encoder per camera stream; its lock serialises
that session's calls while different sessions run concurrently. The :class:`SessionRegistry`
creates sessions within the configured limits, resolves ids (checking the owning key and the
``x-session-target`` pin), expires idle sessions and remembers finished ones for a while so
late calls get ``ALREADY_FINISHED`` rather than ``INVALID_SESSION``.
"""

from __future__ import annotations

import hmac
import logging
import secrets
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Iterator
from concurrent.futures import Executor
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import grpc
import numpy as np

from oasis_torchrl.proto import a2v_pb2, common_pb2, sim_pb2
from oasis_torchrl.protocol import CAMERAS
from oasis_torchrl.sim.auth import key_fingerprint
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.encoding import FrameEncoder, make_encoder
from oasis_torchrl.sim.errors import RequestError, StatusError
from oasis_torchrl.sim.simulator import Simulator

logger = logging.getLogger(__name__)

#: Builds a simulator from ``(width, height, fps)``; the real :class:`Simulator` by default.
SimulatorFactory = Callable[..., Any]
# Finished sessions remembered (for ALREADY_FINISHED answers) at most; the oldest go first.
_MAX_FINISHED_REMEMBERED = 4096


@dataclass(frozen=True)
class InferRecord:
    """The outcome of one Infer, kept so a retry of the same call replays identical bytes."""

    sequence_num: int
    actions: np.ndarray
    response: a2v_pb2.InferResponse
    truth: bytes  # serialized sim_pb2.InferTruth


class Session:
    """One A2V session: a simulator, one encoder per stream, and the rollout position.

    Call the methods while holding :attr:`lock` (the registry's :meth:`SessionRegistry.use`
    does). The simulator and encoders are built at the first Prompt.

    Example:
        >>> import numpy as np
        >>> from concurrent.futures import ThreadPoolExecutor
        >>> from oasis_torchrl.proto import common_pb2
        >>> config = ServerConfig(width=64, height=48, api_keys=("k",))
        >>> session = Session("id", b"key", "target", common_pb2.FRAME_FORMAT_JPEG, config)
        >>> session.prompt("a quiet road", seed=3)
        >>> with ThreadPoolExecutor(3) as pool:
        ...     record = session.infer(0, np.zeros((4, 2), np.float32), pool)
        >>> [len(stream.frames) for stream in record.response.streams]
        [4, 4, 4]
    """

    def __init__(
        self,
        session_id: str,
        key_digest: bytes,
        target: str,
        output_format: int,
        config: ServerConfig,
        simulator_factory: SimulatorFactory = Simulator,
    ) -> None:
        self.session_id = session_id
        self.key_digest = key_digest
        self.target = target
        self.output_format = output_format
        self.lock = threading.Lock()
        self.closed = False  # set once finished or expired, under the lock
        self._config = config
        self._simulator_factory = simulator_factory
        self._simulator: Any = None
        self._encoders: dict[str, FrameEncoder] = {}
        self._seed = 0
        self._next_sequence_num = 0
        self._last: InferRecord | None = None

    def prompt(self, prompt: str, seed: int) -> None:
        """Set a new scene: reset the world, restart every stream with a key frame."""
        if self._simulator is None:
            config = self._config
            self._simulator = self._simulator_factory(
                width=config.width, height=config.height, fps=config.fps
            )
            self._encoders = {
                name: make_encoder(
                    self.output_format,
                    config.width,
                    config.height,
                    config.fps,
                    **config.encoder_settings(),
                )
                for name in CAMERAS
            }
        self._simulator.reset(prompt, seed)
        for encoder in self._encoders.values():
            encoder.restart()
        self._seed = seed
        self._next_sequence_num = 0
        self._last = None

    def infer(self, sequence_num: int, actions: np.ndarray, pool: Executor) -> InferRecord:
        """Advance the world by 4 actions and encode the frames, or replay the last call."""
        self._require_prompt()
        last = self._last
        if last is not None and sequence_num == last.sequence_num:
            if not np.array_equal(actions, last.actions):
                raise RequestError(
                    common_pb2.ERROR_CODE_INVALID_REQUEST,
                    f"sequence_num {sequence_num} was already processed with other actions; "
                    f"expected sequence_num {self._next_sequence_num}",
                )
            return last
        if sequence_num != self._next_sequence_num:
            raise RequestError(
                common_pb2.ERROR_CODE_INVALID_REQUEST,
                f"unexpected sequence_num: expected {self._next_sequence_num}, got {sequence_num}"
                " (it restarts at 0 after every Prompt)",
                {"expected": str(self._next_sequence_num), "got": str(sequence_num)},
            )
        result = self._simulator.step(actions)
        streams = list(pool.map(lambda name: self._encode(name, result.rgb[name]), CAMERAS))
        truth = sim_pb2.InferTruth(
            sequence_num=sequence_num,
            seed=self._seed,
            frames=[frame.to_proto() for frame in result.truth],
        )
        self._last = InferRecord(
            sequence_num=sequence_num,
            actions=actions,
            response=a2v_pb2.InferResponse(sequence_num=sequence_num, streams=streams),
            truth=truth.SerializeToString(),
        )
        self._next_sequence_num = sequence_num + 1
        return self._last

    def depth(self) -> sim_pb2.DepthResponse:
        """Metric depth of the last frame of each stream, as little-endian float16."""
        self._require_prompt()
        depths = self._simulator.depth()
        with np.errstate(over="ignore"):  # beyond float16 range (65504 m) is as good as inf
            maps = [
                sim_pb2.DepthMap(
                    name=name,
                    height=depths[name].shape[0],
                    width=depths[name].shape[1],
                    depth_f16=depths[name].astype("<f2").tobytes(),
                )
                for name in CAMERAS
            ]
        last_sequence_num = self._last.sequence_num if self._last is not None else 0
        return sim_pb2.DepthResponse(sequence_num=last_sequence_num, maps=maps)

    def scene(self) -> sim_pb2.SceneResponse:
        """The static world of the current scene."""
        self._require_prompt()
        return self._simulator.scene_proto()

    def release(self) -> None:
        """Mark the session closed and drop its simulator (its threads stopped) and encoders."""
        self.closed = True
        if self._simulator is not None:
            self._simulator.close()
        self._simulator = None
        self._encoders = {}
        self._last = None

    def _require_prompt(self) -> None:
        if self._simulator is None:
            raise RequestError(
                common_pb2.ERROR_CODE_PROMPT_SET,
                "no scene yet: call Prompt before Infer (and before depth or scene queries)",
            )

    def _encode(self, name: str, frames: np.ndarray) -> a2v_pb2.OutputStream:
        encoder = self._encoders[name]
        return a2v_pb2.OutputStream(name=name, frames=[encoder.encode(frame) for frame in frames])


class SessionRegistry:
    """All sessions of one server: creation within limits, lookup, finish and idle expiry.

    Another key's session is reported exactly like an unknown one (``INVALID_SESSION``), so a
    key cannot probe which session ids exist. Session limits are reported as the gRPC status
    RESOURCE_EXHAUSTED (a transport-level, retryable condition).

    Example:
        >>> from oasis_torchrl.proto import common_pb2
        >>> registry = SessionRegistry(ServerConfig(api_keys=("k",)))
        >>> session = registry.open(b"digest", common_pb2.FRAME_FORMAT_VP9)
        >>> with registry.use(session.session_id, b"digest", session.target) as same:
        ...     same is session
        True
        >>> registry.close()
    """

    def __init__(
        self,
        config: ServerConfig,
        simulator_factory: SimulatorFactory = Simulator,
    ) -> None:
        self._config = config
        self._simulator_factory = simulator_factory
        self._lock = threading.Lock()
        self._open: dict[str, Session] = {}
        self._last_used: dict[str, float] = {}
        self._finished: OrderedDict[str, bytes] = OrderedDict()  # id -> key digest
        self._node = secrets.token_hex(4)
        self._stop_reaper = threading.Event()
        self._reaper: threading.Thread | None = None

    def open(self, key_digest: bytes, output_format: int) -> Session:
        """Create a session for a key, or raise RESOURCE_EXHAUSTED at the session limits."""
        session = Session(
            session_id=secrets.token_urlsafe(24),
            key_digest=key_digest,
            target=f"oasis-sim-{self._node}-{secrets.token_hex(4)}",
            output_format=output_format,
            config=self._config,
            simulator_factory=self._simulator_factory,
        )
        with self._lock:
            self._check_limits(key_digest)
            self._open[session.session_id] = session
            self._last_used[session.session_id] = time.monotonic()
        logger.debug(
            "session %s opened for key %s", session.session_id[:6], key_fingerprint(key_digest)
        )
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
            self._finished[session.session_id] = session.key_digest
            while len(self._finished) > _MAX_FINISHED_REMEMBERED:
                self._finished.popitem(last=False)
        session.release()
        logger.debug("session %s finished", session.session_id[:6])

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
