"""SessionPool: N concurrent A2V sessions stepped as one batch, with retries and recovery.

Concurrency design. One ``grpc.aio`` channel on ONE asyncio event loop in a background thread
carries every session's calls. A batch step is N unary calls in flight at once on one HTTP/2
connection; waiting costs a coroutine per call, not a thread, so latency-bound steps scale with
N at no extra cost and N can grow to hundreds. (A thread pool of blocking stubs would need one
thread per in-flight call and still contend for the GIL on every response.) The blocking API
submits one coroutine per step to the loop and waits for it, so callers stay synchronous.

Decoding never runs on the loop: every (row, stream) chunk of 4 packets is decoded on a thread
pool sized to the cores (PyAV releases the GIL while decoding and converting), in order, by that
stream's own stateful decoder, straight into its slot of the step's preallocated output array.
Raw frames (from a server on this machine) are only copied into their slots, on the loop: a hop
to a thread would cost more than the copy.
A row's next step only starts after its previous step returned, so each decoder sees its
stream's packets in order.

The calls go through :class:`~oasis_torchrl.client.transport.Transport` (retries, timeout);
each row is a :class:`~oasis_torchrl.client.pool_row.PoolRow`, which restarts or loses its
session on a fault without touching the other rows (its module lists the faults). If every
selected row of a step is LOST the server is unreachable: the step raises that error
(within the configured timeout and retry deadline, never a hang). Errors no retry can fix
(bad key, bad request, unsupported SDK or format) raise at once with the row in ``error.row``.
"""

from __future__ import annotations

import asyncio
import logging
import os
import weakref
from collections.abc import Awaitable, Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import grpc
import numpy as np

from oasis_torchrl.client import wire
from oasis_torchrl.client.background import EventLoopThread
from oasis_torchrl.client.channel import TlsSetting, parse_endpoint
from oasis_torchrl.client.decoding import validate_front_crop, validate_resize
from oasis_torchrl.client.errors import DecartRoboticsError, TransportError
from oasis_torchrl.client.pool_row import PoolRow, RowOutcome, RowSlots, assemble, gather
from oasis_torchrl.client.retry import RetryPolicy
from oasis_torchrl.client.session import SessionState
from oasis_torchrl.client.sync_client import DEFAULT_SDK_VERSION
from oasis_torchrl.client.transport import Transport, open_channel
from oasis_torchrl.client.types import PoolStep, ServerHandle, SessionStatus, StreamInfo
from oasis_torchrl.closing import Closing
from oasis_torchrl.protocol import API_KEY_ENV_VAR, CAMERAS, CHUNK, FRONT, with_front_crop

logger = logging.getLogger(__name__)

FRAME_SELECTIONS = {"all": CHUNK, "last": 1}
"""``frames=`` of :class:`SessionPool`: frames kept per chunk (``"last"`` asks the server for
the last frame alone, and otherwise skips the RGB conversion of the first three, which an env
observing only the last frame never reads)."""


class _Runtime:
    """Everything a started pool owns: loop thread, channel, stubs, decode threads, sessions."""

    def __init__(
        self,
        loop: EventLoopThread,
        channel: grpc.aio.Channel,
        rpc: Transport,
        executor: ThreadPoolExecutor,
    ) -> None:
        self.loop = loop
        self.channel = channel
        self.rpc = rpc
        self.executor = executor
        self.sessions: list[PoolRow] = []

    def shutdown(self) -> None:
        """Close the channel, stop the loop and the decode threads (no Finish)."""
        if not self.loop.loop.is_closed():
            self.loop.run(self.channel.close())
        self.loop.stop()
        self.executor.shutdown(wait=True)


class SessionPool(Closing):
    """N concurrent A2V sessions, prompted and stepped as one batch.

    Constructing a pool opens nothing (it pickles, so a worker process can open it);
    :meth:`start` (or the first call that needs it, or ``with``) connects and Initializes all
    sessions. ``frames="last"`` returns only the last frame of each chunk (``[n, 1, H, W, 3]``):
    the pool asks the server for it alone (``x-oasis-frames``, granted by the embedded server for
    raw frames, so the others are never drawn nor sent); from other servers the other three are
    still decoded, so the streams stay in sync, but never converted to RGB. ``expert=True``
    asks every Prompt for the embedded server's expert, whose next chunk each step returns
    (``PoolStep.expert``, NaN without it). ``front_crop`` (a fraction) adds a derived camera,
    ``"front_crop"``: the centre of each ``front`` frame decoded at the stream's full size, at
    the other cameras' size (:class:`~oasis_torchrl.client.decoding.FrontCrop`).

    ``endpoint`` is an A2V endpoint URL, or a :class:`ServerHandle` (such as the embedded
    server's launcher): the pool starts that server when it starts, takes its endpoint and key,
    and stops it when it closes. A pickled pool arrives unstarted (sessions, channels and a
    started server never cross processes): the receiving process opens its own.

    >>> pool = SessionPool("http://127.0.0.1:1", num_sessions=4, api_key="secret")
    >>> import pickle
    >>> pickle.loads(pickle.dumps(pool)).num_sessions
    4
    >>> "secret" in repr(pool)
    False
    """

    def __init__(
        self,
        endpoint: str | ServerHandle,
        num_sessions: int,
        *,
        api_key: str | None = None,
        tls: TlsSetting = None,
        timeout: float | None = 120.0,
        retry: RetryPolicy | None = None,
        accepted_formats: Sequence[int] | None = None,
        resize: tuple[int, int] | None = None,
        required_streams: Sequence[str] = CAMERAS,
        decode_threads: int | None = None,
        client_sdk_version: str = DEFAULT_SDK_VERSION,
        frames: str = "all",
        expert: bool = False,
        front_crop: float | None = None,
    ) -> None:
        if frames not in FRAME_SELECTIONS:
            raise ValueError(f"frames must be one of {sorted(FRAME_SELECTIONS)}, got {frames!r}")
        if isinstance(num_sessions, bool) or not isinstance(num_sessions, int) or num_sessions < 1:
            raise ValueError(f"num_sessions must be a positive int, got {num_sessions!r}")
        if decode_threads is not None and decode_threads < 1:
            raise ValueError(
                f"decode_threads must be a positive int or None, got {decode_threads!r}"
            )
        self.server = None if isinstance(endpoint, str) else endpoint
        self.endpoint = endpoint if isinstance(endpoint, str) else None
        self.api_key = api_key if api_key is not None else os.getenv(API_KEY_ENV_VAR)
        self.tls = tls
        self.timeout = timeout
        self.retry = RetryPolicy() if retry is None else retry
        self.accepted_formats = wire.accepted_format_list(accepted_formats, self.endpoint)
        self.resize = validate_resize(resize)
        self.required_streams = tuple(required_streams)
        self.front_crop = validate_front_crop(front_crop)
        cut = self.front_crop is not None and self.required_streams
        if cut and FRONT not in self.required_streams:
            raise ValueError(
                f"front_crop cuts the '{FRONT}' stream: add it to required_streams "
                f"{list(self.required_streams)}"
            )
        self.decode_threads = decode_threads
        self.client_sdk_version = client_sdk_version
        self.frames = frames
        self.expert = expert
        self._num_sessions = num_sessions
        self._target = None if self.endpoint is None else parse_endpoint(self.endpoint, tls).address
        self._streams: tuple[StreamInfo, ...] = ()
        self._runtime: _Runtime | None = None
        self._finalizer: weakref.finalize | None = None

    # ----------------------------------------------------------------- properties

    @property
    def num_sessions(self) -> int:
        """Number of rows (sessions)."""
        return self._num_sessions

    @property
    def streams(self) -> tuple[StreamInfo, ...]:
        """The selected streams as the server advertised them (empty before start)."""
        return self._streams

    @property
    def stream_names(self) -> tuple[str, ...]:
        """Names of the streams each step returns, in order (empty before start)."""
        return tuple(stream.name for stream in self._streams)

    @property
    def camera_names(self) -> tuple[str, ...]:
        """Names of the cameras each step returns: the streams, then ``"front_crop"`` with a
        crop (empty before start)."""
        if not self._streams:
            return ()
        return with_front_crop(self.stream_names, self.front_crop)

    @property
    def frame_size(self) -> tuple[int, int]:
        """``(height, width)`` of returned frames: ``resize`` or the streams' native size."""
        if self.resize is not None:
            return self.resize
        sizes = {(stream.height, stream.width) for stream in self._require_streams()}
        if len(sizes) != 1:
            raise DecartRoboticsError(f"streams have different sizes {sorted(sizes)}; pass resize")
        return sizes.pop()

    @property
    def session_ids(self) -> tuple[str | None, ...]:
        """Each row's current session id (None if not open)."""
        if self._runtime is None:
            return (None,) * self._num_sessions
        return tuple(s.state.session_id for s in self._runtime.sessions)

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(endpoint={self.endpoint!r}, num_sessions={self._num_sessions}, "
            f"api_key={'***' if self.api_key else None!r}, started={self._runtime is not None})"
        )

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__, _runtime=None, _finalizer=None, _streams=())
        if self.server is not None:  # the receiving process starts a server of its own
            state.update(endpoint=None, _target=None)
        return state

    def __enter__(self) -> SessionPool:
        try:
            self.start()
        except BaseException:
            self.close()
            raise
        return self

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> tuple[StreamInfo, ...]:
        """Connect and Initialize all sessions concurrently; idempotent. Returns the streams."""
        if self._streams:
            return self._streams
        try:
            runtime = self._ensure_runtime()
            infos = runtime.loop.run(self._start(runtime))
        except BaseException:
            self.close()
            raise
        self._streams = self._selected_streams(infos[0].streams)
        logger.info(
            "pool of %d sessions on %s: streams %s, frames %s",
            self._num_sessions,
            self.endpoint,
            self.stream_names,
            self.frame_size,
        )
        return self._streams

    def close(self) -> None:
        """Finish all sessions (best effort, concurrently), close the channel, stop threads."""
        runtime, self._runtime = self._runtime, None
        self._streams = ()
        try:
            if runtime is not None:
                if self._finalizer is not None:
                    self._finalizer.detach()
                try:
                    runtime.loop.run(self._finish_all(runtime.sessions))
                finally:
                    runtime.shutdown()
        finally:
            if self.server is not None and self.endpoint is not None:
                self.server.stop()
                self.endpoint = self._target = None

    def ping(self) -> bool:
        """Whether the server's gRPC health service reports SERVING (False if unreachable)."""
        runtime = self._ensure_runtime()
        return runtime.loop.run(runtime.rpc.ping())

    # ---------------------------------------------------------------- batch calls

    def prompt(
        self,
        prompts: Sequence[str],
        seeds: Sequence[int | None] | None = None,
        indices: Sequence[int] | None = None,
    ) -> None:
        """Prompt the selected rows concurrently (re-Initializing lost sessions first).

        Resets those rows' sequence numbers and decoders, and remembers prompt and seed for
        recovery. Raises the first failing row's error (``error.row``) after all rows finished.
        """
        runtime = self._require_started()
        rows = self._select(indices)
        prompts, seeds = self._prompt_args(prompts, seeds, rows)
        sessions = [runtime.sessions[row] for row in rows]
        coroutines = [s.set_scene(p, sd) for s, p, sd in zip(sessions, prompts, seeds, strict=True)]
        self._raise_first(rows, runtime.loop.run(gather(coroutines)))

    def infer(self, actions: np.ndarray, indices: Sequence[int] | None = None) -> PoolStep:
        """Send one action chunk per selected row (float32 ``[n, 4, 2]``), all concurrently."""
        runtime = self._require_started()
        rows = self._select(indices)
        chunk = wire.validate_action_batch(actions, rows)
        unprompted = [row for row in rows if runtime.sessions[row].state.prompt_text is None]
        if unprompted:
            raise ValueError(
                f"rows {unprompted} have no prompt yet; call prompt() or reset() first"
            )
        return self._run_step(runtime, rows, lambda s, j, slots: s.step(chunk[j], slots))

    def reset(
        self,
        indices: Sequence[int] | None,
        prompts: Sequence[str],
        seeds: Sequence[int | None] | None = None,
        actions: np.ndarray | None = None,
    ) -> PoolStep:
        """Prompt the selected rows and send one chunk (all-zero by default), concurrently."""
        runtime = self._require_started()
        rows = self._select(indices)
        prompts, seeds = self._prompt_args(prompts, seeds, rows)
        chunk = (
            np.zeros((len(rows), CHUNK, 2), np.float32)
            if actions is None
            else wire.validate_action_batch(actions, rows)
        )
        return self._run_step(
            runtime,
            rows,
            lambda s, j, slots: s.reset(prompts[j], seeds[j], chunk[j], slots),
        )

    def recover(self, indices: Sequence[int]) -> None:
        """Re-Initialize the selected rows and re-prompt them with their stored prompt and seed."""
        runtime = self._require_started()
        rows = self._select(indices)
        sessions = [runtime.sessions[row] for row in rows]
        self._raise_first(rows, runtime.loop.run(gather([s.recover() for s in sessions])))

    def depth(self, indices: Sequence[int] | None = None) -> dict[str, np.ndarray]:
        """Metric depth of each selected row's last frame: stream -> float32 ``[n, H, W]``."""
        runtime = self._require_started()
        rows = self._select(indices)
        sessions = [runtime.sessions[row] for row in rows]
        results = runtime.loop.run(gather([s.depth() for s in sessions]))
        self._raise_first(rows, results)
        return {name: np.stack([maps[name] for maps in results]) for name in self.stream_names}

    async def _start(self, runtime: _Runtime) -> list[wire.SessionInfo]:
        await self._wait_ready(runtime.channel)
        results = await gather([s.open() for s in runtime.sessions])
        self._raise_first(range(self._num_sessions), results)
        return results

    async def _wait_ready(self, channel: grpc.aio.Channel) -> None:
        try:
            await asyncio.wait_for(channel.channel_ready(), self.timeout)
        except TimeoutError:
            raise TransportError(
                grpc.StatusCode.UNAVAILABLE,
                f"no connection within the {self.timeout} s timeout",
                method="connect",
                target=self._target,
            ) from None

    @staticmethod
    async def _finish_all(sessions: list[PoolRow]) -> None:
        await asyncio.gather(*(s.finish_quietly() for s in sessions))

    # -------------------------------------------------------------------- helpers

    def _run_step(
        self,
        runtime: _Runtime,
        rows: list[int],
        row_step: Callable[[PoolRow, int, RowSlots], Awaitable[RowOutcome]],
    ) -> PoolStep:
        """Run ``row_step`` for every selected row concurrently into fresh output arrays."""
        height, width = self.frame_size
        per_chunk = FRAME_SELECTIONS[self.frames]
        frames = {
            name: np.empty((len(rows), per_chunk, height, width, 3), np.uint8)
            for name in self.camera_names
        }
        coroutines = [
            row_step(runtime.sessions[row], j, {name: out[j] for name, out in frames.items()})
            for j, row in enumerate(rows)
        ]
        outcomes = runtime.loop.run(gather(coroutines))
        self._raise_first(rows, outcomes)
        if all(o.status == SessionStatus.LOST for o in outcomes):
            # No row could be served: the server is unreachable, which a caller must not miss.
            self._raise_first(rows, [o.error for o in outcomes])
        return assemble(frames, outcomes)

    def _ensure_runtime(self) -> _Runtime:
        if self._runtime is None:
            self._connect_server()
            if not self.api_key:
                raise wire.missing_api_key_error()
            loop = EventLoopThread(f"oasis-pool-{self._target}")
            channel = loop.run(open_channel(self.endpoint, self.tls))
            rpc = Transport(channel, self.retry, self.timeout, self._target, self.api_key)
            executor = ThreadPoolExecutor(
                self.decode_threads or os.cpu_count() or 1, thread_name_prefix="oasis-decode"
            )
            runtime = _Runtime(loop, channel, rpc, executor)
            runtime.sessions = [
                PoolRow(row, rpc, self._session_state(), executor)
                for row in range(self._num_sessions)
            ]
            self._runtime = runtime
            self._finalizer = weakref.finalize(self, runtime.shutdown)
        return self._runtime

    def _connect_server(self) -> None:
        """Start the pool's own server, if it has one, and take its endpoint and key."""
        if self.server is None or self.endpoint is not None:
            return
        self.server.start()
        self.endpoint, self.api_key = self.server.endpoint, self.server.api_key
        self._target = parse_endpoint(self.endpoint, self.tls).address

    def _session_state(self) -> SessionState:
        return SessionState(
            self.api_key,
            sdk_version=self.client_sdk_version,
            accepted_formats=self.accepted_formats,
            required_streams=self.required_streams,
            decoder_threads=1,  # the pool decodes many streams in parallel
            last_frame_only=self.frames == "last",
            expert=self.expert,
            front_crop=self.front_crop,
        )

    def _require_started(self) -> _Runtime:
        self.start()
        assert self._runtime is not None
        return self._runtime

    def _require_streams(self) -> tuple[StreamInfo, ...]:
        if not self._streams:
            raise DecartRoboticsError("the pool is not started; call start() first")
        return self._streams

    def _selected_streams(self, advertised: tuple[StreamInfo, ...]) -> tuple[StreamInfo, ...]:
        if not self.required_streams:
            return advertised
        by_name = {stream.name: stream for stream in advertised}
        return tuple(by_name[name] for name in self.required_streams)

    def _select(self, indices: Sequence[int] | None) -> list[int]:
        if indices is None:
            return list(range(self._num_sessions))
        rows = [int(i) for i in np.asarray(indices, dtype=np.int64).reshape(-1)]
        if len(set(rows)) != len(rows) or any(not 0 <= r < self._num_sessions for r in rows):
            raise ValueError(
                f"indices must be distinct ints in [0, {self._num_sessions}), got {list(indices)}"
            )
        return rows

    @staticmethod
    def _prompt_args(
        prompts: Sequence[str], seeds: Sequence[int | None] | None, rows: list[int]
    ) -> tuple[list[str], list[int | None]]:
        prompts = [prompts] if isinstance(prompts, str) else list(prompts)
        seeds = [None] * len(rows) if seeds is None else list(seeds)
        if len(prompts) != len(rows) or len(seeds) != len(rows):
            raise ValueError(
                f"need one prompt and one seed per selected row ({len(rows)}), got "
                f"{len(prompts)} prompts and {len(seeds)} seeds"
            )
        for row, prompt in zip(rows, prompts, strict=True):
            if not isinstance(prompt, str):
                raise TypeError(f"prompt for row {row} must be a str, got {type(prompt).__name__}")
        return prompts, [None if s is None else wire.validate_seed(s) for s in seeds]

    @staticmethod
    def _raise_first(rows: Sequence[int], results: Sequence[object]) -> None:
        """Raise the first row's exception (tagged with its row) if any row raised."""
        for row, result in zip(rows, results, strict=True):
            if isinstance(result, BaseException):
                if isinstance(result, DecartRoboticsError):
                    result.row = row
                raise result
