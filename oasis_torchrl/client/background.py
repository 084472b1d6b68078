"""An asyncio event loop running in a daemon thread, driven from blocking code.

The session pool keeps its gRPC channel and all in-flight calls on this one loop; its blocking
methods submit a coroutine and wait for the result.
"""

from __future__ import annotations

import asyncio
import inspect
import threading
from collections.abc import Coroutine
from typing import Any, TypeVar

T = TypeVar("T")


class EventLoopThread:
    """Own an event loop in a background thread; :meth:`run` executes coroutines on it.

    >>> async def add(a, b):
    ...     return a + b
    >>> loop = EventLoopThread("example")
    >>> loop.run(add(1, 2))
    3
    >>> loop.stop()
    """

    def __init__(self, name: str) -> None:
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._serve, name=name, daemon=True)
        self._thread.start()

    @property
    def loop(self) -> asyncio.AbstractEventLoop:
        """The event loop (for scheduling from inside coroutines)."""
        return self._loop

    def run(self, coroutine: Coroutine[Any, Any, T]) -> T:
        """Run ``coroutine`` on the loop and block until it finishes; cancel it if interrupted."""
        if threading.current_thread() is self._thread:
            coroutine.close()
            raise RuntimeError("a blocking call was made from the pool's own event loop thread")
        try:
            future = asyncio.run_coroutine_threadsafe(coroutine, self._loop)
        except RuntimeError:  # the loop is closed: the coroutine will never run
            coroutine.close()
            raise
        try:
            return future.result()
        except BaseException:
            if future.cancel() and inspect.getcoroutinestate(coroutine) == inspect.CORO_CREATED:
                coroutine.close()  # cancelled before the loop started it: it never will
            raise

    def stop(self) -> None:
        """Stop the loop, join the thread and close the loop (idempotent)."""
        if self._loop.is_closed():
            return
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join()
        self._loop.close()

    def _serve(self) -> None:
        asyncio.set_event_loop(self._loop)
        self._loop.run_forever()
