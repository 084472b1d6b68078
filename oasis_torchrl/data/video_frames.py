"""Frames of a dataset's video at given timestamps, decoded in one forward pass with PyAV.

LeRobot's decoders answer one query at a time: each opens the file, seeks to the keyframe before
the query and decodes forward. Reading a whole dataset that way opens every video file once per
episode and camera. :func:`frames_at` opens a file once and decodes it in order, which is what
loading every row of a dataset (behaviour cloning's in-memory cache) and replaying episodes
(:mod:`oasis_torchrl.viz.lerobot_replay`) need. Its frames are PyAV's ``rgb24`` conversion, as
LeRobot's ``pyav`` backend gives them.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import av
import numpy as np

if TYPE_CHECKING:
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata


class MissingFrameError(ValueError):
    """A video has no frame within the tolerance of a requested timestamp."""


def frames_at(
    path: str | Path, timestamps: Sequence[float] | np.ndarray, tolerance_s: float
) -> Iterator[np.ndarray]:
    """The uint8 RGB ``[H, W, 3]`` frame of the video at ``path`` at each of ``timestamps``
    (seconds into the file, ascending), decoded in one pass from the keyframe before the first.

    A frame matches a timestamp within ``tolerance_s``; two timestamps may match the same frame
    (it is yielded for each). Frames between the requested ones are decoded and skipped.

    Raises:
        ValueError: ``timestamps`` are not ascending.
        MissingFrameError: no frame lies within ``tolerance_s`` of a timestamp (naming the file
            and the timestamp); the frames before it have been yielded.

    Example:
        >>> import tempfile
        >>> from oasis_torchrl.video import StripVideoWriter
        >>> path = Path(tempfile.mkdtemp()) / "clip.mp4"
        >>> with StripVideoWriter(path, ["front"], fps=20) as video:
        ...     video.write({"front": [np.full((64, 96, 3), k * 60, np.uint8) for k in range(4)]})
        >>> [int(frame.mean()) for frame in frames_at(path, [0.05, 0.15], tolerance_s=1e-4)]
        [60, 180]
        >>> list(frames_at(path, [0.12], tolerance_s=1e-4))  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        oasis_torchrl...MissingFrameError: ... has no frame within 0.0001 s of 0.12 s
    """
    wanted = np.asarray(timestamps, dtype=np.float64)
    if wanted.size == 0:
        return
    if np.any(np.diff(wanted) < 0):
        raise ValueError(f"timestamps must be ascending to decode {path} in one pass")
    index = 0
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        first = max(int(wanted[0] / stream.time_base) - 1, 0)
        container.seek(first, backward=True, any_frame=False, stream=stream)
        for frame in container.decode(stream):
            time = frame.time
            if time is None:
                continue
            if wanted[index] < time - tolerance_s:  # decoded past it without a match
                break
            if time < wanted[index] - tolerance_s:  # a frame before the next requested one
                continue
            image = frame.to_ndarray(format="rgb24")
            while index < wanted.size and abs(time - wanted[index]) <= tolerance_s:
                yield image
                index += 1
            if index == wanted.size:
                return
    raise MissingFrameError(f"{path} has no frame within {tolerance_s:g} s of {wanted[index]:g} s")


def episode_frames(
    meta: LeRobotDatasetMetadata, episode: int, key: str, count: int | None = None
) -> Iterator[np.ndarray]:
    """The frames of one episode in the video of feature ``key`` (the first ``count``; None:
    the episode's length), decoded in one pass with :func:`frames_at`.

    Example (``meta`` a ``LeRobotDatasetMetadata``):
        >>> frames = episode_frames(meta, 0, "observation.images.front")  # doctest: +SKIP
    """
    row = meta.episodes[episode]
    start = float(row[f"videos/{key}/from_timestamp"])
    count = int(row["length"]) if count is None else count
    path = Path(meta.root) / meta.get_video_file_path(episode, key)
    times = start + np.arange(count) / meta.fps
    yield from frames_at(path, times, tolerance_s=0.5 / meta.fps)
