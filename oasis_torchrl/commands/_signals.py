"""Signal handling of the dataset-writing commands (``record``, ``import-recordings``): a
stopped command still finalizes its dataset."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[threading.Event]:
    """Let SIGTERM stop a writing command the way Ctrl-C does, so the dataset is finalized.

    Both signals raise ``KeyboardInterrupt`` and set the yielded event: a loop that checks it
    stops even when the exception landed in library code that swallowed it.

    Example:
        >>> with sigterm_as_interrupt() as stop:
        ...     stop.is_set()
        False
    """
    requested = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield requested
        return

    def interrupt(signum: int, frame: object) -> None:
        requested.set()
        raise KeyboardInterrupt

    previous = {sig: signal.signal(sig, interrupt) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield requested
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
