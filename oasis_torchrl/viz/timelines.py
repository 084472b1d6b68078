"""The three timelines every logged value carries: ``frame``, ``step`` and ``sim_time``.

A world frame ``f`` is step ``f // frames_per_step`` (4 frames per env step; a dataset of one row
per step has 1) at ``f / fps`` simulated seconds. One place sets them, for single values and for
columns, so every recording (rollouts, evaluations, replays, side by side) agrees.
"""

from __future__ import annotations

import numpy as np
import rerun as rr

from oasis_torchrl.protocol import CHUNK
from oasis_torchrl.viz.paths import FRAME_TIMELINE, STEP_TIMELINE, TIME_TIMELINE


def set_frame(
    recording: rr.RecordingStream, frame: int, fps: float, frames_per_step: int = CHUNK
) -> None:
    """Log what follows at world frame ``frame`` (its step and simulated time with it).

    Example:
        >>> set_frame(rr.RecordingStream("doc"), 11, fps=20.0)  # step 2, 0.55 s
    """
    recording.set_time(FRAME_TIMELINE, sequence=int(frame))
    recording.set_time(STEP_TIMELINE, sequence=int(frame) // frames_per_step)
    recording.set_time(TIME_TIMELINE, duration=int(frame) / fps)


def time_columns(
    frames: np.ndarray, fps: float, frames_per_step: int = CHUNK
) -> list[rr.TimeColumn]:
    """The three timelines of values at world frames ``frames`` (for ``send_columns``).

    Example:
        >>> [column.timeline_name() for column in time_columns(np.arange(8), fps=20.0)]
        ['frame', 'step', 'sim_time']
    """
    frames = np.asarray(frames, dtype=np.int64).reshape(-1)
    return [
        rr.TimeColumn(FRAME_TIMELINE, sequence=frames),
        rr.TimeColumn(STEP_TIMELINE, sequence=frames // frames_per_step),
        rr.TimeColumn(TIME_TIMELINE, duration=frames / fps),
    ]
