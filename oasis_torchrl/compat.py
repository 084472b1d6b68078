"""Every use of another library's private internals, each checked against the installed version.

Nothing else in the project touches a private attribute of LeRobot, TorchRL or Ray. Each helper
first checks that the installed release is one whose internals it was written against, and
otherwise fails with an error naming the installed and the supported versions (rather than
misbehaving on a layout it does not know). What is used, and why no public API does the job:

- LeRobot's streaming video encoder (:func:`wait_for_encoder_room`,
  :func:`dropped_video_frames`): it was built for live cameras and drops a frame when a camera's
  queue stays full for 0.1 s. Frames replayed from a rollout must all land, so the writer waits
  for queue room before each frame and refuses to save an episode that lost one anyway.
- TorchRL's ``RayCollector`` (:func:`drop_ray_collectors`): it can add remote collectors but not
  remove one, so after a worker died the survivors are kept by rewriting its actor list and
  those of its weight senders.
- LeRobot's episode announcements (:func:`on_lerobot_episode_start`): a robot has no hook for
  the start of an episode, but ``lerobot-record`` and ``lerobot-rollout``'s episodic strategy
  announce each one with ``log_say("Recording episode N")`` (a root-logger INFO record); the oasis
  robot listens for it to re-prompt its world for that episode.

Example:
    >>> SUPPORTED["lerobot"]
    ((0, 6), (0, 7))
    >>> require("lerobot")
"""

from __future__ import annotations

import functools
import importlib.metadata
import logging
import re
import time
from collections.abc import Callable, Sequence
from typing import Any

SUPPORTED: dict[str, tuple[tuple[int, int], tuple[int, int]]] = {
    "lerobot": ((0, 6), (0, 7)),
    "torchrl": ((0, 14), (0, 15)),
}
"""Distribution -> ``(lowest, first unsupported)`` ``(major, minor)`` whose internals are used."""


class UnsupportedVersionError(RuntimeError):
    """An installed library's release is not one this module's private accesses were written for."""


def _release(version: str) -> tuple[int, int]:
    """``(major, minor)`` of a version string.

    Example:
        >>> _release("0.14.1"), _release("0.6.1.dev0")
        ((0, 14), (0, 6))
    """
    numbers = re.findall(r"\d+", version)[:2]
    return int(numbers[0]), int(numbers[1]) if len(numbers) > 1 else 0


def _range_text(package: str) -> str:
    (low_major, low_minor), (high_major, high_minor) = SUPPORTED[package]
    return f">={low_major}.{low_minor},<{high_major}.{high_minor}"


@functools.cache
def _installed(package: str) -> str:
    # Looked up once per process: a lookup scans the installed distributions (about 4 ms), and
    # the dataset writer checks before every frame it streams.
    return importlib.metadata.version(package)


def require(package: str) -> None:
    """Check that the installed ``package`` is a release :data:`SUPPORTED` lists.

    Raises:
        UnsupportedVersionError: naming the installed and the supported versions.

    Example:
        >>> require("torchrl")
    """
    installed = _installed(package)
    low, high = SUPPORTED[package]
    if not low <= _release(installed) < high:
        raise UnsupportedVersionError(
            f"oasis_torchrl.compat supports {package}{_range_text(package)}, "
            f"found {package} {installed}; install a supported release "
            f"(pip install '{package}{_range_text(package)}')"
        )


# -- LeRobot: the streaming video encoder ------------------------------------------------------


def _streaming_encoder(dataset: Any) -> Any | None:
    require("lerobot")
    writer = dataset.writer
    return None if writer is None else writer._streaming_encoder


def wait_for_encoder_room(dataset: Any) -> None:
    """Block until every camera's streaming-encoder queue of ``dataset`` can take a frame.

    Returns at once when the dataset encodes without streaming, or a camera's encoder thread
    has stopped (LeRobot then raises its error at the next frame).
    """
    encoder = _streaming_encoder(dataset)
    if encoder is None:
        return
    for key, frames in encoder._frame_queues.items():
        thread = encoder._threads[key]
        while frames.full() and thread.is_alive():
            time.sleep(0.001)


def dropped_video_frames(dataset: Any) -> dict[str, int]:
    """Frames the streaming encoder dropped in the current episode, per camera (none: empty)."""
    encoder = _streaming_encoder(dataset)
    counts = {} if encoder is None else encoder._dropped_frames
    return {key: count for key, count in counts.items() if count}


# -- TorchRL: removing remote collectors from a RayCollector ------------------------------------


def drop_ray_collectors(collector: Any, keep: Sequence[int]) -> None:
    """Keep only the remote collectors at indices ``keep`` of a TorchRL ``RayCollector``.

    The collector and its weight-sync schemes then address the kept actors only (TorchRL has no
    public way to shrink a ``RayCollector``).
    """
    require("torchrl")
    actors = [collector.remote_collectors[index] for index in keep]
    collector._remote_collectors = actors
    collector.num_collectors = len(actors)
    collector._batches_since_weight_update = [0] * len(actors)
    for scheme in (collector._weight_sync_schemes or {}).values():
        scheme._remote_collectors = list(actors)
        scheme._num_workers = len(actors)


# -- LeRobot: the episode announcements of its recording loops -----------------------------------

_EPISODE_ANNOUNCEMENT = re.compile(r"Recording episode (\d+)")


class _EpisodeStarts(logging.Handler):
    """Calls back with ``N`` for every ``"Recording episode N"`` record it sees."""

    def __init__(self, callback: Callable[[int], None]) -> None:
        super().__init__(logging.INFO)
        self.callback = callback

    def emit(self, record: logging.LogRecord) -> None:
        match = _EPISODE_ANNOUNCEMENT.fullmatch(str(record.msg))
        if match is not None and record.name == "root":
            self.callback(int(match[1]))


def on_lerobot_episode_start(callback: Callable[[int], None]) -> Callable[[], None]:
    """Call ``callback(index)`` whenever a LeRobot recording loop starts dataset episode
    ``index`` (``lerobot-record``, ``lerobot-rollout --strategy.type=episodic``; a re-recorded
    episode is announced again with the same index). Returns a function that stops listening.

    LeRobot's tools log at INFO from the root logger (``init_logging``), where the announcement
    arrives; a program running LeRobot's loops with the root logger above INFO is not told.

    Example:
        >>> from lerobot.utils.utils import log_say
        >>> root, starts = logging.getLogger(), []
        >>> level = root.level
        >>> root.setLevel(logging.INFO)  # as LeRobot's tools log
        >>> stop = on_lerobot_episode_start(starts.append)
        >>> log_say("Recording episode 3", play_sounds=False)
        >>> stop()
        >>> log_say("Recording episode 4", play_sounds=False)
        >>> root.setLevel(level)
        >>> starts
        [3]
    """
    require("lerobot")
    handler = _EpisodeStarts(callback)
    root = logging.getLogger()
    root.addHandler(handler)
    return lambda: root.removeHandler(handler)
