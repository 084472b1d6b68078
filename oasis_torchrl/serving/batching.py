"""Dynamic batching: concurrent requests from many sessions share one forward pass.

One thread runs the policy. Requests queue up while it runs; when it is free it takes the
waiting ones (and those arriving within ``max_wait`` of the first) up to ``max_rows`` rows,
concatenates them, makes one call and hands each request its rows of the answer. N clients
then cost about one batched call, not N. A request is never split; one with more rows than
``max_rows`` runs alone. The first request waits for others only when the previous call
merged several: a lone client pays no wait.

When a merged call raises, each of its requests runs again alone, so only a request the
policy cannot answer fails (with :class:`PolicyRaised`) and the others get their actions.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass, field

import torch
from tensordict import TensorDictBase

logger = logging.getLogger(__name__)

BatchedCall = Callable[[TensorDictBase], torch.Tensor]


class PolicyRaised(RuntimeError):
    """The policy raised while answering a request (the server keeps serving).

    Example:
        >>> str(PolicyRaised(ValueError("bad frame")))
        'the policy raised ValueError: bad frame'
    """

    def __init__(self, cause: BaseException) -> None:
        super().__init__(f"the policy raised {type(cause).__name__}: {cause}")


@dataclass
class _Request:
    observation: TensorDictBase
    answer: Future[torch.Tensor] = field(default_factory=Future)

    @property
    def rows(self) -> int:
        return self.observation.batch_size[0]


@dataclass
class BatchStats:
    """Counters of a :class:`Batcher`: requests answered and calls made."""

    requests: int = 0
    calls: int = 0
    rows: int = 0


class Batcher:
    """Runs ``call`` on batches merged from concurrent requests, in one thread.

    Args:
        call: ``observation [rows] -> answer [rows, ...]``.
        max_rows: rows of one merged call at most (1: every request runs alone).
        max_wait: seconds the first request of a batch waits for others at most.

    Example:
        >>> from tensordict import TensorDict
        >>> batcher = Batcher(lambda td: td["x"] * 2, max_rows=64, max_wait=0.001)
        >>> batcher(TensorDict(x=torch.ones(3), batch_size=[3]))
        tensor([2., 2., 2.])
        >>> batcher.close()
    """

    def __init__(self, call: BatchedCall, *, max_rows: int, max_wait: float) -> None:
        if max_rows < 1 or max_wait < 0:
            raise ValueError(f"need max_rows >= 1 and max_wait >= 0, got {max_rows}, {max_wait}")
        self._call = call
        self.max_rows = max_rows
        self.max_wait = max_wait
        self.stats = BatchStats()
        self._queue: queue.SimpleQueue[_Request | None] = queue.SimpleQueue()
        self._held: _Request | None = None  # taken from the queue, too big for the last batch
        self._company = False  # the last call merged several requests: others may follow
        self._thread = threading.Thread(target=self._serve, name="policy-batcher", daemon=True)
        self._thread.start()

    def submit(self, observation: TensorDictBase) -> Future[torch.Tensor]:
        """Queue ``observation``; the future resolves to its rows of the answer."""
        if not self._thread.is_alive():
            raise RuntimeError("the batcher is closed")
        request = _Request(observation)
        self._queue.put(request)
        return request.answer

    def __call__(self, observation: TensorDictBase) -> torch.Tensor:
        """The answer for ``observation`` (blocking); raises :class:`PolicyRaised`."""
        return self.submit(observation).result()

    def close(self) -> None:
        """Answer what is queued, then stop the thread."""
        self._queue.put(None)
        self._thread.join()

    def _serve(self) -> None:
        while True:
            batch, closing = self._next_batch()
            if batch:
                self._run(batch)
            if closing:
                return

    def _next_batch(self) -> tuple[list[_Request], bool]:
        """The next requests to run together, and whether the batcher is closing."""
        first = self._held or self._queue.get()
        self._held = None
        if first is None:
            return [], True
        batch, rows = [first], first.rows
        deadline = time.monotonic() + (self.max_wait if self._company else 0.0)
        while rows < self.max_rows:
            try:
                wait = deadline - time.monotonic()
                request = self._queue.get(timeout=wait) if wait > 0 else self._queue.get_nowait()
            except queue.Empty:
                break
            if request is None:
                return batch, True
            if rows + request.rows > self.max_rows:
                self._held = request
                break
            batch.append(request)
            rows += request.rows
        return batch, False

    def _run(self, batch: list[_Request]) -> None:
        self._company = len(batch) > 1
        self.stats.requests += len(batch)
        if len(batch) > 1:
            merged = torch.cat([request.observation for request in batch])
            try:
                answers = self._checked_call(merged).split([r.rows for r in batch])
            except Exception:
                logger.warning(
                    "a merged call of %d requests raised; running each alone", len(batch)
                )
            else:
                for request, answer in zip(batch, answers, strict=True):
                    request.answer.set_result(answer)
                return
        for request in batch:
            try:
                request.answer.set_result(self._checked_call(request.observation))
            except Exception as error:
                logger.warning("the policy raised on a request: %r", error)
                request.answer.set_exception(PolicyRaised(error))

    def _checked_call(self, observation: TensorDictBase) -> torch.Tensor:
        self.stats.calls += 1
        self.stats.rows += observation.batch_size[0]
        answer = self._call(observation)
        if answer.shape[:1] != observation.batch_size:
            raise ValueError(
                f"the policy answered {list(answer.shape)} for {observation.batch_size[0]} rows"
            )
        return answer
