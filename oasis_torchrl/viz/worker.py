"""One background thread that runs jobs in order, with a bound on how many may wait.

The bound is the back-pressure that keeps memory flat: when the writer falls behind, the caller
waits instead of queueing frames without limit. A failed job is re-raised to the caller at the
next ``submit`` or ``drain``.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any


class BoundedWorker:
    """Run jobs in submission order on one thread; ``submit`` blocks while ``max_pending`` wait.

    Example:
        >>> done = []
        >>> worker = BoundedWorker(max_pending=2)
        >>> for i in range(5):
        ...     worker.submit(done.append, i)
        >>> worker.drain()
        >>> done
        [0, 1, 2, 3, 4]
        >>> worker.close()
    """

    def __init__(self, max_pending: int, name: str = "oasis-rerun") -> None:
        if max_pending < 1:
            raise ValueError(f"max_pending must be >= 1, got {max_pending}")
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix=name)
        self._slots = threading.BoundedSemaphore(max_pending)
        self._futures: deque[Future] = deque()

    def submit(self, job: Callable[..., Any], *args: Any) -> None:
        """Queue ``job(*args)``; waits for a free slot; raises a previous job's error first."""
        self._collect(wait=False)
        self._slots.acquire()
        try:
            future = self._executor.submit(job, *args)
        except BaseException:
            self._slots.release()
            raise
        future.add_done_callback(lambda _: self._slots.release())
        self._futures.append(future)

    def drain(self) -> None:
        """Wait for every queued job; raise the first error among them."""
        self._collect(wait=True)

    def close(self) -> None:
        """Finish the queued jobs and stop the thread (errors are raised after stopping)."""
        try:
            self.drain()
        finally:
            self._executor.shutdown(wait=True)

    def _collect(self, wait: bool) -> None:
        while self._futures and (wait or self._futures[0].done()):
            error = self._futures.popleft().exception()
            if error is not None:
                self._futures.clear()
                raise RuntimeError("rerun logging failed in the background writer") from error
