"""Scalar time series sent as columns: one ``send_columns`` per entity instead of one ``log`` per
value, which is most of the logging cost of a fast env (dozens of values per row and step). Each
entity is styled once with its fixed name and colour (:mod:`~oasis_torchrl.viz.palette`).

:class:`SeriesBuffer` holds values for at most ``max_delay_s`` seconds (so a live plot lags at
most that much) and at most ``max_values`` values (so memory stays bounded), then sends them.
Each send is a chunk per entity, schema included: a file, which nobody watches while it is
written, takes them in fewer, larger ones (:data:`FILE_DELAY_S`).
"""

from __future__ import annotations

import time
from collections import defaultdict
from collections.abc import Callable

import numpy as np
import rerun as rr

from oasis_torchrl.protocol import CHUNK
from oasis_torchrl.viz.palette import series_style
from oasis_torchrl.viz.timelines import time_columns

LIVE_DELAY_S, LIVE_MAX_VALUES = 1.0, 4096
"""How long and how many values a live viewer's series wait to be sent."""
FILE_DELAY_S, FILE_MAX_VALUES = 30.0, 1 << 16
"""The same for a file (512 KiB of values at most)."""

Styler = Callable[[str], rr.AsComponents]
"""The static style (``SeriesLines`` or ``SeriesPoints``) of the series at an entity path."""


def send_series(
    recording: rr.RecordingStream,
    path: str,
    frames: np.ndarray,
    values: np.ndarray,
    fps: float,
    *,
    style: Styler | None = series_style,
    frames_per_step: int = CHUNK,
) -> None:
    """Send a scalar time series (one value per frame) in one call; non-finite values become NaN.
    With a ``style``, the signal's fixed name and colour (:mod:`~oasis_torchrl.viz.palette`)
    are logged with it (static).

    Example:
        >>> recording = rr.RecordingStream("doc")
        >>> send_series(recording, "env/0/reward/total", np.arange(3), np.ones(3), fps=20.0)
    """
    if style is not None:
        recording.log(path, style(path), static=True)
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    recording.send_columns(
        path,
        indexes=time_columns(frames, fps, frames_per_step),
        columns=rr.Scalars.columns(scalars=np.where(np.isfinite(values), values, np.nan)),
    )


class SeriesBuffer:
    """Buffers scalar values per entity and sends them as columns.

    Args:
        recording: where to send.
        fps: frame rate (``sim_time = frame / fps``).
        style: the static style of each entity, logged once (default: its palette signal).
        max_delay_s: send once the oldest buffered value is this old (wall clock).
        max_values: send once this many values are buffered.

    Example:
        >>> series = SeriesBuffer(rr.RecordingStream("doc"), fps=20.0)
        >>> series.add("env/0/action/throttle", np.arange(4), np.full(4, 0.5))
        >>> series.pending
        4
        >>> series.flush()
        >>> series.pending
        0
    """

    def __init__(
        self,
        recording: rr.RecordingStream,
        fps: float,
        style: Styler = series_style,
        max_delay_s: float = LIVE_DELAY_S,
        max_values: int = LIVE_MAX_VALUES,
    ) -> None:
        self.recording = recording
        self.fps = fps
        self.style = style
        self.max_delay_s = max_delay_s
        self.max_values = max_values
        self._frames: defaultdict[str, list[np.ndarray]] = defaultdict(list)
        self._values: defaultdict[str, list[np.ndarray]] = defaultdict(list)
        self._oldest: float | None = None
        self._styled: set[str] = set()
        self.pending = 0

    def add(self, path: str, frames: np.ndarray, values: np.ndarray) -> None:
        """Buffer ``values`` of ``path`` at ``frames``; send everything if a limit is reached."""
        self._frames[path].append(np.asarray(frames, dtype=np.int64).reshape(-1))
        self._values[path].append(np.asarray(values, dtype=np.float64).reshape(-1))
        self.pending += len(self._frames[path][-1])
        now = time.monotonic()
        self._oldest = now if self._oldest is None else self._oldest
        if self.pending >= self.max_values or now - self._oldest >= self.max_delay_s:
            self.flush()

    def flush(self) -> None:
        """Send every buffered value."""
        for path, frames in self._frames.items():
            values = np.concatenate(self._values[path])
            style = None if path in self._styled else self.style
            self._styled.add(path)
            send_series(self.recording, path, np.concatenate(frames), values, self.fps, style=style)
        self._frames.clear()
        self._values.clear()
        self._oldest = None
        self.pending = 0
