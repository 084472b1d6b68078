"""One row of a :class:`~oasis_torchrl.client.pool.SessionPool`: its session's state machine
over the pool's transport, and the step's outcome of every row assembled into a
:class:`~oasis_torchrl.client.types.PoolStep`.

Faults, per row (other rows are unaffected):

- transient gRPC failures are retried by the :class:`~oasis_torchrl.client.retry.RetryPolicy`
  (Infer replays idempotently);
- a sequence mismatch or an undecodable packet (desync): the row is re-prompted with its stored
  prompt and seed and one all-zero chunk is sent; status RESTARTED;
- the session is gone (INVALID_SESSION, ALREADY_FINISHED, server restart): re-Initialize,
  re-prompt, zero chunk; status RESTARTED;
- the recovery (or the call itself) still fails after retries: status LOST, frames zero; the row
  is re-Initialized at its next step (RESTARTED) or by :meth:`PoolRow.recover`.

Decoding never runs on the loop: every (row, stream) chunk of 4 packets is decoded on the pool's
decode threads, in order, by that stream's own stateful decoder, straight into its slot of the
step's preallocated output array; raw frames are only copied into their slots, on the loop.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import grpc
import numpy as np

from oasis_torchrl.client import wire
from oasis_torchrl.client.decoding import FrontCrop, decode_chunk
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
from oasis_torchrl.client.session import Call, SessionState
from oasis_torchrl.client.transport import Transport
from oasis_torchrl.client.types import PoolStep, SessionStatus
from oasis_torchrl.protocol import ACTION_DIM, CHUNK, FRONT, FRONT_CROP

logger = logging.getLogger(__name__)

# Finish at close is best effort: a hung server must not hold close() for the full call timeout.
FINISH_TIMEOUT_S = 5.0
ZERO_CHUNK = np.zeros((CHUNK, 2), np.float32)

RECOVERABLE_STEP_ERRORS = (TransportError, SessionLostError, SequenceError, DecodeError)

RowSlots = dict[str, np.ndarray]


@dataclass
class RowOutcome:
    """What one row's step produced."""

    status: SessionStatus
    error: Exception | None = None
    sequence_num: int = -1
    truth: np.ndarray | None = None
    expert: np.ndarray | None = None


@dataclass
class PoolRow:
    """One row: its session's state, its transport, and why it was lost (if it was)."""

    row: int
    rpc: Transport
    state: SessionState
    executor: ThreadPoolExecutor
    lost_error: Exception | None = None

    @property
    def lost(self) -> bool:
        """Whether the row must be re-Initialized before use."""
        return self.lost_error is not None

    async def step(self, actions: np.ndarray, slots: RowSlots) -> RowOutcome:
        """Send one chunk and decode it into ``slots``, restarting the row after a desync or a
        gone session (RESTARTED), or losing it (LOST); a lost row is re-Initialized first."""
        if self.lost:
            return await self._restart(slots, self.lost_error, reopen=True)
        try:
            return await self.infer_into(actions, slots)
        except (SequenceError, DecodeError) as error:
            return await self._restart(slots, error, reopen=False)
        except SessionLostError as error:
            return await self._restart(slots, error, reopen=True)
        except TransportError as error:
            return self._lose(error)

    async def reset(
        self, prompt: str, seed: int | None, actions: np.ndarray, slots: RowSlots
    ) -> RowOutcome:
        """Prompt the row (:meth:`set_scene`) and :meth:`step` it; a failed prompt loses it."""
        try:
            await self.set_scene(prompt, seed)
        except RECOVERABLE_STEP_ERRORS as error:
            return self._lose(error)
        return await self.step(actions, slots)

    async def set_scene(self, prompt: str, seed: int | None) -> None:
        """Prompt the row, re-Initializing it first if its session is lost or gone."""
        try:
            if self.lost or self.state.info is None:
                await self.open()
            try:
                await self.prompt(prompt, seed)
            except SessionLostError:
                await self.open()
                await self.prompt(prompt, seed)
        except TransportError as error:
            # The server may or may not have applied the call: start this row over next time.
            self.lost_error = error
            raise

    async def recover(self) -> None:
        """Re-Initialize the row and re-prompt it with its stored prompt and seed."""
        await self.open()
        if self.state.prompt_text is not None:
            await self.reprompt()

    async def _restart(
        self, slots: RowSlots, cause: Exception | None, *, reopen: bool
    ) -> RowOutcome:
        logger.info("row %d: restarting its rollout after: %s", self.row, cause)
        try:
            if reopen:
                await self.open()
            await self.reprompt()
            outcome = await self.infer_into(ZERO_CHUNK, slots)
        except RECOVERABLE_STEP_ERRORS as error:
            return self._lose(error)
        outcome.status, outcome.error = SessionStatus.RESTARTED, cause
        return outcome

    def _lose(self, error: Exception) -> RowOutcome:
        logger.warning("row %d: session lost: %s", self.row, error)
        self.lost_error = error
        return RowOutcome(SessionStatus.LOST, error)

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

    async def infer_into(self, actions: np.ndarray, slots: RowSlots) -> RowOutcome:
        """One Infer; decodes every selected stream into ``slots`` concurrently, off the loop."""
        response, call = await self._send(self.state.infer(actions))
        reply = self.state.on_infer(response, await call.trailing_metadata())
        await self._decode(reply.packets, slots)
        return RowOutcome(
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
            await gather([loop.run_in_executor(self.executor, decode_chunk, *job) for job in jobs])
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


async def gather(coroutines: Sequence[Awaitable[Any]]) -> list[Any]:
    """Run all coroutines to completion; exceptions are returned in place of results.

    >>> async def two():
    ...     return 2
    >>> async def refused():
    ...     raise ValueError("refused")
    >>> asyncio.run(gather([two(), refused()]))
    [2, ValueError('refused')]
    """
    return await asyncio.gather(*coroutines, return_exceptions=True)


def _raise_any(results: Sequence[object]) -> None:
    for result in results:
        if isinstance(result, BaseException):
            raise result


def assemble(frames: dict[str, np.ndarray], outcomes: list[RowOutcome]) -> PoolStep:
    """Build the PoolStep; LOST rows get zero frames.

    >>> frames = {"front": np.ones((2, 1, 2, 2, 3), np.uint8)}
    >>> outcomes = [RowOutcome(SessionStatus.OK, sequence_num=3), RowOutcome(SessionStatus.LOST)]
    >>> step = assemble(frames, outcomes)
    >>> int(step.frames["front"][1].max()), step.sequence_nums.tolist(), step.truth is None
    (0, [3, -1], True)
    """
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
