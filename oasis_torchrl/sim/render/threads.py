"""Threads for the per-pixel work of large images, and per-thread scratch arrays.

NumPy releases the GIL inside its loops, so large independent parts of an image (a view, half
an image) run on separate cores; small images are faster in one thread. Per-pixel work writes
into scratch arrays that each thread keeps and grows as needed, so it allocates no frame-sized
temporaries (those cost page faults).
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

import numpy as np

from oasis_torchrl.closing import Closing

T = TypeVar("T")

#: Part of a drawing step's per-pixel work: the views and the image rows it covers.
Part = tuple[slice, slice]

#: Most threads a renderer spreads per-pixel work over.
MAX_WORKERS = 4


class RenderThreads(Closing):
    """Runs the parts of one drawing step, on a thread pool this object owns, or in the
    calling thread when ``parallel`` is false or there is a single core.

    Close it (or use it as a context manager) to shut the pool down.

    Example:
        >>> done = []
        >>> with RenderThreads(parallel=True) as threads:
        ...     threads.run(done.append, [1, 2, 3])
        >>> sorted(done)
        [1, 2, 3]
    """

    def __init__(self, parallel: bool) -> None:
        count = min(os.cpu_count() or 1, MAX_WORKERS) if parallel else 1
        self._pool = (
            ThreadPoolExecutor(count, thread_name_prefix="oasis-render") if count > 1 else None
        )

    @property
    def parallel(self) -> bool:
        """Whether parts run on several threads."""
        return self._pool is not None

    def run(self, function: Callable[[T], None], items: Sequence[T]) -> None:
        """Call ``function`` on every item; returns once all are done."""
        if self._pool is None or len(items) < 2:
            for item in items:
                function(item)
            return
        for _ in self._pool.map(function, items):
            pass

    def close(self) -> None:
        """Shut the pool down (idempotent); later calls run in the calling thread."""
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True)


_scratch = threading.local()


def thread_array(name: str, shape: tuple[int, ...], dtype: type) -> np.ndarray:
    """This thread's work array ``name`` of ``shape`` (a view of a buffer grown as needed).

    Example:
        >>> thread_array("example", (2, 3), np.float32).shape
        (2, 3)
    """
    size = math.prod(shape)
    buffer = getattr(_scratch, name, None)
    if buffer is None or buffer.size < size:
        buffer = np.empty(size, dtype=dtype)
        setattr(_scratch, name, buffer)
    return buffer[:size].reshape(shape)
