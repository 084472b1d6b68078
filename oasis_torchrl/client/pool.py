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

Faults, per row (other rows are unaffected):

- transient gRPC failures are retried by the :class:`RetryPolicy` (Infer replays idempotently);
- a sequence mismatch or an undecodable packet (desync): the row is re-prompted with its stored
  prompt and seed and one all-zero chunk is sent; status RESTARTED;
- the session is gone (INVALID_SESSION, ALREADY_FINISHED, server restart): re-Initialize,
  re-prompt, zero chunk; status RESTARTED;
- the recovery (or the call itself) still fails after retries: status LOST, frames zero; the row
  is re-Initialized at its next step (RESTARTED) or by :meth:`SessionPool.recover`.

If every selected row of a step is LOST the server is unreachable: the step raises that error
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
from dataclasses import dataclass
from types import TracebackType
from typing import Any

import grpc
import numpy as np
from grpc_health.v1 import health_pb2_grpc

from oasis_torchrl.client import health, wire
from oasis_torchrl.client.background import EventLoopThread
from oasis_torchrl.client.channel import TlsSetting, create_aio_channel, parse_endpoint
from oasis_torchrl.client.decoding import (
    FrontCrop,
    decode_chunk,
    validate_front_crop,
    validate_resize,
)
from oasis_torchrl.client.errors import (
    DecartRoboticsError,
    DecodeError,
    SequenceError,
    SessionLostError,
    TransportError,
)
from oasis_torchrl.client.ground_truth import (
    TRUTH_FIELDS,
    depth_maps,
    expert_chunk,
    raise_sim_error,
    truth_array,
)
from oasis_torchrl.client.retry import RetryPolicy, acall_with_retry
from oasis_torchrl.client.session import Call, SessionState
from oasis_torchrl.client.sync_client import DEFAULT_SDK_VERSION
from oasis_torchrl.client.types import (
    PoolStep,
    ServerHandle,
    SessionStatus,
    StreamInfo,
)
from oasis_torchrl.proto import a2v_pb2_grpc, sim_pb2_grpc
from oasis_torchrl.protocol import (
    ACTION_DIM,
    API_KEY_ENV_VAR,
    CAMERAS,
    CHUNK,
    FRONT,
    FRONT_CROP,
    with_front_crop,
)

logger = logging.getLogger(__name__)

# Finish at close is best effort: a hung server must not hold close() for the full call timeout.
FINISH_TIMEOUT_S = 5.0
ZERO_CHUNK = np.zeros((CHUNK, 2), np.float32)
FRAME_SELECTIONS = {"all": CHUNK, "last": 1}
"""``frames=`` of :class:`SessionPool`: frames kept per chunk (``"last"`` asks the server for
the last frame alone, and otherwise skips the RGB conversion of the first three, which an env
observing only the last frame never reads)."""
RECOVERABLE_STEP_ERRORS = (TransportError, SessionLostError, SequenceError, DecodeError)

RowSlots = dict[str, np.ndarray]


@dataclass
class _Outcome:
    """What one row's step produced."""

    status: SessionStatus
    error: Exception | None = None
    sequence_num: int = -1
    truth: np.ndarray | None = None
    expert: np.ndarray | None = None


class _Rpc:
    """The pool's stubs on one aio channel, with retries, timeout and masked API key."""

    def __init__(
        self,
        channel: grpc.aio.Channel,
        policy: RetryPolicy,
        timeout: float | None,
        target: str,
        secret: str | None,
    ) -> None:
        self.a2v = a2v_pb2_grpc.A2VServiceStub(channel)
        self.sim = sim_pb2_grpc.SimServiceStub(channel)
        self.health = health_pb2_grpc.HealthStub(channel)
        self.policy = policy
        self.timeout = timeout
        self.target = target
        self.secret = secret

    async def call(
        self,
        method: Callable[..., Any],
        name: str,
        request: object,
        metadata: wire.Metadata,
        *,
        policy: RetryPolicy | None = None,
        timeout: float | None = None,
    ) -> tuple[Any, grpc.aio.Call]:
        """One unary call with retries; returns the response and its finished call."""

        async def attempt(attempt_timeout: float | None) -> tuple[Any, grpc.aio.Call]:
            call = method(request, timeout=attempt_timeout, metadata=metadata)
            return await call, call

        return await acall_with_retry(
            attempt,
            policy=policy or self.policy,
            method=name,
            timeout=self.timeout if timeout is None else timeout,
            secret=self.secret,
            target=self.target,
        )


@dataclass
class _PoolSession:
    """One row: its session's state, its transport, and why it was lost (if it was)."""

    row: int
    rpc: _Rpc
    state: SessionState
    executor: ThreadPoolExecutor
    lost_error: Exception | None = None

    @property
    def lost(self) -> bool:
        """Whether the row must be re-Initialized before use."""
        return self.lost_error is not None

    async def open(self) -> wire.SessionInfo:
        """Initialize a new session (finishing any previous one, best effort)."""
        await self.finish_quietly()
        response, call = await self._send(self.state.initialize())
        try:
            info = self.state.on_initialize(response, await call.initial_metadata())
        except DecartRoboticsError:
            await self.finish_quietly()
            raise
        self.lost_error = None
        logger.debug("row %d: session %s opened", self.row, info.session_id[:6])
        return info

    async def prompt(self, prompt: str, seed: int | None) -> None:
        """Set the scene; restarts the rollout (sequence 0, fresh decoders)."""
        response, _ = await self._send(self.state.prompt(prompt, seed))
        self.state.on_prompt(response)

    async def reprompt(self) -> None:
        """Prompt again with the stored prompt and seed (a new clip of the same world)."""
        response, _ = await self._send(self.state.replay_prompt())
        self.state.on_prompt(response)

    async def infer_into(self, actions: np.ndarray, slots: RowSlots) -> _Outcome:
        """One Infer; decodes every selected stream into ``slots`` concurrently, off the loop."""
        response, call = await self._send(self.state.infer(actions))
        reply = self.state.on_infer(response, await call.trailing_metadata())
        await self._decode(reply.packets, slots)
        return _Outcome(
            SessionStatus.OK,
            sequence_num=reply.sequence_num,
            truth=None if reply.truth is None else truth_array(reply.truth),
            expert=expert_chunk(reply.truth),
        )

    async def _decode(self, packets: dict[str, Sequence[bytes]], slots: RowSlots) -> None:
        """Decode every selected stream into its slot: on the decode threads, concurrently,
        or right here when decoding is a mere copy (raw frames)."""
        decoders, chunk = self.state.decoders, self.state.info.frames_per_chunk
        jobs = [
            (decoders[name], packets.get(name, ()), out, chunk, self._crop_of(name, slots))
            for name, out in slots.items()
            if name != FRONT_CROP
        ]
        if not any(decoder.threaded for decoder, *_ in jobs):
            for job in jobs:
                decode_chunk(*job)
            return
        loop = asyncio.get_running_loop()
        # Wait for every stream's decode even if one fails: a recovery must not reset a decoder
        # or rewrite a slot that a still-running decode job is using.
        _raise_any(
            await _gather([loop.run_in_executor(self.executor, decode_chunk, *job) for job in jobs])
        )

    def _crop_of(self, stream: str, slots: RowSlots) -> tuple[FrontCrop, np.ndarray] | None:
        """The crop the ``stream`` decode also writes: ``front``'s, where the pool has one."""
        front_crop = self.state.front_crop
        if stream != FRONT or front_crop is None:
            return None
        return front_crop, slots[FRONT_CROP]

    async def depth(self) -> dict[str, np.ndarray]:
        """Depth maps of the last frame of each stream (SimService)."""
        try:
            response, _ = await self._send(self.state.depth())
        except TransportError as error:
            raise_sim_error(error, "depth")
        return depth_maps(response)

    async def finish_quietly(self) -> None:
        """Finish the current session if any, ignoring failures (short timeout per attempt)."""
        call = self.state.finish()
        if call is None:
            return
        try:
            await self._send(
                call, timeout=min(self.rpc.timeout or FINISH_TIMEOUT_S, FINISH_TIMEOUT_S)
            )
        except (DecartRoboticsError, grpc.RpcError) as error:
            logger.debug("row %d: Finish failed (ignored): %s", self.row, error)

    async def _send(self, call: Call, *, timeout: float | None = None) -> tuple[Any, grpc.aio.Call]:
        stub = self.rpc.sim if call.on_sim_service else self.rpc.a2v
        method = getattr(stub, call.method)
        return await self.rpc.call(
            method, call.method, call.request, call.metadata, timeout=timeout
        )


class _Runtime:
    """Everything a started pool owns: loop thread, channel, stubs, decode threads, sessions."""

    def __init__(
        self,
        loop: EventLoopThread,
        channel: grpc.aio.Channel,
        rpc: _Rpc,
        executor: ThreadPoolExecutor,
    ) -> None:
        self.loop = loop
        self.channel = channel
        self.rpc = rpc
        self.executor = executor
        self.sessions: list[_PoolSession] = []

    def shutdown(self) -> None:
        """Close the channel, stop the loop and the decode threads (no Finish)."""
        if not self.loop.loop.is_closed():
            self.loop.run(self.channel.close())
        self.loop.stop()
        self.executor.shutdown(wait=True)


class SessionPool:
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

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

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
        return runtime.loop.run(self._ping(runtime.rpc))

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
        coroutines = [
            self._prompt_session(s, p, sd)
            for s, p, sd in zip(sessions, prompts, seeds, strict=True)
        ]
        self._raise_first(rows, runtime.loop.run(_gather(coroutines)))

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
        return self._run_step(runtime, rows, lambda s, j, slots: self._step(s, chunk[j], slots))

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
            lambda s, j, slots: self._reset_session(s, prompts[j], seeds[j], chunk[j], slots),
        )

    def recover(self, indices: Sequence[int]) -> None:
        """Re-Initialize the selected rows and re-prompt them with their stored prompt and seed."""
        runtime = self._require_started()
        rows = self._select(indices)
        sessions = [runtime.sessions[row] for row in rows]
        self._raise_first(rows, runtime.loop.run(_gather([self._recover(s) for s in sessions])))

    def depth(self, indices: Sequence[int] | None = None) -> dict[str, np.ndarray]:
        """Metric depth of each selected row's last frame: stream -> float32 ``[n, H, W]``."""
        runtime = self._require_started()
        rows = self._select(indices)
        sessions = [runtime.sessions[row] for row in rows]
        results = runtime.loop.run(_gather([s.depth() for s in sessions]))
        self._raise_first(rows, results)
        return {name: np.stack([maps[name] for maps in results]) for name in self.stream_names}

    # ------------------------------------------------------------- row coroutines

    async def _step(self, session: _PoolSession, actions: np.ndarray, slots: RowSlots) -> _Outcome:
        if session.lost:
            return await self._restart(session, slots, session.lost_error, reopen=True)
        try:
            return await session.infer_into(actions, slots)
        except (SequenceError, DecodeError) as error:
            return await self._restart(session, slots, error, reopen=False)
        except SessionLostError as error:
            return await self._restart(session, slots, error, reopen=True)
        except TransportError as error:
            return _lose(session, error)

    async def _restart(
        self, session: _PoolSession, slots: RowSlots, cause: Exception | None, *, reopen: bool
    ) -> _Outcome:
        logger.info("row %d: restarting its rollout after: %s", session.row, cause)
        try:
            if reopen:
                await session.open()
            await session.reprompt()
            outcome = await session.infer_into(ZERO_CHUNK, slots)
        except RECOVERABLE_STEP_ERRORS as error:
            return _lose(session, error)
        outcome.status, outcome.error = SessionStatus.RESTARTED, cause
        return outcome

    async def _reset_session(
        self,
        session: _PoolSession,
        prompt: str,
        seed: int | None,
        actions: np.ndarray,
        slots: RowSlots,
    ) -> _Outcome:
        try:
            await self._prompt_session(session, prompt, seed)
        except RECOVERABLE_STEP_ERRORS as error:
            return _lose(session, error)
        return await self._step(session, actions, slots)

    async def _prompt_session(self, session: _PoolSession, prompt: str, seed: int | None) -> None:
        """Prompt a row, re-Initializing it first if its session is lost or gone."""
        try:
            if session.lost or session.state.info is None:
                await session.open()
            try:
                await session.prompt(prompt, seed)
            except SessionLostError:
                await session.open()
                await session.prompt(prompt, seed)
        except TransportError as error:
            # The server may or may not have applied the call: start this row over next time.
            session.lost_error = error
            raise

    async def _recover(self, session: _PoolSession) -> None:
        await session.open()
        if session.state.prompt_text is not None:
            await session.reprompt()

    async def _start(self, runtime: _Runtime) -> list[wire.SessionInfo]:
        await self._wait_ready(runtime.channel)
        results = await _gather([s.open() for s in runtime.sessions])
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
    async def _finish_all(sessions: list[_PoolSession]) -> None:
        await asyncio.gather(*(s.finish_quietly() for s in sessions))

    @staticmethod
    async def _ping(rpc: _Rpc) -> bool:
        try:
            response, _ = await rpc.call(
                rpc.health.Check, "Check", health.health_request(), (), policy=RetryPolicy.never()
            )
        except TransportError as error:
            return health.ping_outcome(error)
        return health.is_serving(response)

    # -------------------------------------------------------------------- helpers

    def _run_step(
        self,
        runtime: _Runtime,
        rows: list[int],
        row_step: Callable[[_PoolSession, int, RowSlots], Awaitable[_Outcome]],
    ) -> PoolStep:
        """Run ``row_step`` for every selected row concurrently into fresh output arrays."""
        height, width = self.frame_size
        kept = FRAME_SELECTIONS[self.frames]
        frames = {
            name: np.empty((len(rows), kept, height, width, 3), np.uint8)
            for name in self.camera_names
        }
        coroutines = [
            row_step(runtime.sessions[row], j, {name: out[j] for name, out in frames.items()})
            for j, row in enumerate(rows)
        ]
        outcomes = runtime.loop.run(_gather(coroutines))
        self._raise_first(rows, outcomes)
        if all(o.status == SessionStatus.LOST for o in outcomes):
            # No row could be served: the server is unreachable, which a caller must not miss.
            self._raise_first(rows, [o.error for o in outcomes])
        return _assemble(frames, outcomes)

    def _ensure_runtime(self) -> _Runtime:
        if self._runtime is None:
            self._connect_server()
            if not self.api_key:
                raise wire.missing_api_key_error()
            loop = EventLoopThread(f"oasis-pool-{self._target}")
            channel = loop.run(_open_channel(self.endpoint, self.tls))
            rpc = _Rpc(channel, self.retry, self.timeout, self._target, self.api_key)
            executor = ThreadPoolExecutor(
                self.decode_threads or os.cpu_count() or 1, thread_name_prefix="oasis-decode"
            )
            runtime = _Runtime(loop, channel, rpc, executor)
            runtime.sessions = [
                _PoolSession(row, rpc, self._session_state(), executor)
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


async def _open_channel(endpoint: str, tls: TlsSetting) -> grpc.aio.Channel:
    return create_aio_channel(endpoint, tls)


async def _gather(coroutines: Sequence[Awaitable[Any]]) -> list[Any]:
    """Run all coroutines to completion; exceptions are returned in place of results."""
    return await asyncio.gather(*coroutines, return_exceptions=True)


def _lose(session: _PoolSession, error: Exception) -> _Outcome:
    logger.warning("row %d: session lost: %s", session.row, error)
    session.lost_error = error
    return _Outcome(SessionStatus.LOST, error)


def _raise_any(results: Sequence[object]) -> None:
    for result in results:
        if isinstance(result, BaseException):
            raise result


def _assemble(frames: dict[str, np.ndarray], outcomes: list[_Outcome]) -> PoolStep:
    """Build the PoolStep; LOST rows get zero frames."""
    status = np.array([o.status for o in outcomes], np.int8)
    lost = status == SessionStatus.LOST
    for out in frames.values():
        out[lost] = 0
    truths = [o.truth for o in outcomes]
    truth = None
    if any(t is not None for t in truths):
        truth = np.full((len(outcomes), CHUNK, len(TRUTH_FIELDS)), np.nan)
        for j, row_truth in enumerate(truths):
            if row_truth is not None:
                truth[j, : len(row_truth)] = row_truth[:CHUNK]
    expert = np.full((len(outcomes), CHUNK, ACTION_DIM), np.nan, np.float32)
    for j, outcome in enumerate(outcomes):
        if outcome.expert is not None:
            expert[j] = outcome.expert
    return PoolStep(
        frames=frames,
        truth=truth,
        status=status,
        errors=[o.error for o in outcomes],
        sequence_nums=np.array([o.sequence_num for o in outcomes], np.int64),
        expert=expert,
    )
