"""Flags shared by the dataset-writing commands (``record``, ``import-recordings``)."""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import re
import signal
import threading
import warnings
from collections.abc import Iterator
from pathlib import Path

_SIZE = re.compile(r"^(\d+)x(\d+)$")


def parse_size(text: str) -> tuple[int, int]:
    """``"HEIGHTxWIDTH"`` -> ``(height, width)``.

    Example:
        >>> parse_size("128x192")
        (128, 192)
    """
    match = _SIZE.match(text.strip().lower())
    if match is None:
        raise argparse.ArgumentTypeError(f"expected HEIGHTxWIDTH such as 128x192, got {text!r}")
    return int(match[1]), int(match[2])


def add_dataset_arguments(parser: argparse.ArgumentParser) -> None:
    """Output flags: dataset folder, repo id, stored size, codec, append.

    Example:
        >>> parser = argparse.ArgumentParser()
        >>> add_dataset_arguments(parser)
        >>> parser.parse_args(["--root", "out", "--image-size", "128x192"]).image_size
        (128, 192)
    """
    parser.add_argument("--root", type=Path, required=True, help="dataset folder to write")
    parser.add_argument("--repo-id", help="LeRobot repo id (default local/<folder name>)")
    parser.add_argument(
        "--image-size",
        type=parse_size,
        metavar="HxW",
        help="stored frame size, e.g. 128x192 (even; default: full resolution)",
    )
    parser.add_argument(
        "--vcodec",
        default="h264",
        help="video codec: h264 (default, fast), libsvtav1 (LeRobot's default, slow), hevc",
    )
    parser.add_argument("--append", action="store_true", help="add episodes to the dataset")


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


def _not_lerobot_chatter(record: logging.LogRecord) -> bool:
    # LeRobot logs through the root logger, so its INFO lines can only be told by their file.
    return record.levelno >= logging.WARNING or f"{os.sep}lerobot{os.sep}" not in record.pathname


def quiet_dataset_libraries() -> None:
    """Keep LeRobot's and ``datasets``' per-episode chatter and bars out of our progress bar.

    Example:
        >>> quiet_dataset_libraries()
    """
    import datasets

    datasets.disable_progress_bars()
    for handler in logging.getLogger().handlers:
        handler.addFilter(_not_lerobot_chatter)
    warnings.filterwarnings("ignore", message="Converting input from bool", category=RuntimeWarning)
