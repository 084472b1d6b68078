"""One-pass decoding of a video at requested timestamps, on a real H.264 file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from oasis_torchrl.data.video_frames import MissingFrameError, frames_at
from oasis_torchrl.video import StripVideoWriter

FPS = 20
TOLERANCE = 1e-4


@pytest.fixture(scope="module")
def clip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """40 frames at 20 fps, frame k a flat grey of level 6 k."""
    path = tmp_path_factory.mktemp("video") / "clip.mp4"
    with StripVideoWriter(path, ["front"], fps=FPS) as video:
        video.write({"front": [np.full((64, 96, 3), 6 * k, np.uint8) for k in range(40)]})
    return path


def _levels(frames) -> list[int]:
    return [round(float(frame.mean()) / 6) for frame in frames]


def test_frames_come_at_the_timestamps_with_gaps_and_repeats(clip: Path) -> None:
    times = np.array([2, 2, 10, 11, 39]) / FPS  # a frame twice; frames skipped between
    frames = list(frames_at(clip, times, TOLERANCE))
    assert _levels(frames) == [2, 2, 10, 11, 39]
    assert all(frame.shape == (64, 96, 3) and frame.dtype == np.uint8 for frame in frames)
    assert _levels(frames_at(clip, [30 / FPS], TOLERANCE)) == [30]  # from a seek
    assert list(frames_at(clip, [], TOLERANCE)) == []


def test_a_timestamp_without_a_frame_is_named_after_the_frames_before_it(clip: Path) -> None:
    decoded = []
    with pytest.raises(MissingFrameError, match=r"clip\.mp4 has no frame within 0\.0001 s of 2 s"):
        for frame in frames_at(clip, [1 / FPS, 3 / FPS, 2.0], TOLERANCE):  # past the end
            decoded.append(frame)
    assert _levels(decoded) == [1, 3]  # nothing before the missing one is lost
    with pytest.raises(MissingFrameError, match=r"of 0\.125 s"):  # between two frames
        list(frames_at(clip, [0.125], TOLERANCE))
    assert _levels(frames_at(clip, [0.12], tolerance_s=0.5 / FPS)) == [2]  # the nearer one


def test_timestamps_must_be_ascending(clip: Path) -> None:
    with pytest.raises(ValueError, match=r"timestamps must be ascending to decode .*clip\.mp4"):
        list(frames_at(clip, [0.5, 0.1], TOLERANCE))
