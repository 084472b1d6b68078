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

Example:
    >>> SUPPORTED["lerobot"]
    ((0, 6), (0, 7))
    >>> require("lerobot")
"""

from __future__ import annotations

import importlib.metadata
import re
import time
from collections.abc import Sequence
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


def require(package: str) -> None:
    """Check that the installed ``package`` is a release :data:`SUPPORTED` lists.

    Raises:
        UnsupportedVersionError: naming the installed and the supported versions.

    Example:
        >>> require("torchrl")
    """
    installed = importlib.metadata.version(package)
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
