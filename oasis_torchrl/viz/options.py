"""What a :class:`~oasis_torchrl.viz.RolloutLogger` logs, and how."""

from __future__ import annotations

from dataclasses import dataclass

from oasis_torchrl.protocol import FPS
from oasis_torchrl.viz.images import DEFAULT_JPEG_QUALITY
from oasis_torchrl.viz.topdown import DEFAULT_WINDOW, Window

DEFAULT_TRUTH_SERIES = ("speed", "lateral_offset", "obstacle_distance")
"""Plotted ground truth (a collision is an event and turns the top-down car red, not a plot)."""


@dataclass(frozen=True)
class LogOptions:
    """Logging options (defaults keep files small and the viewer readable).

    Args:
        rows: env rows to log (default: all). Each logged row gets its own tab.
        cameras: cameras to log (default: every ``("pixels", camera)`` but the front crop, a
            part of the front camera's frame; name it here to log it).
        jpeg_quality: JPEG quality 1-100 of logged frames (at the env's size: the viewer
            scales them to its panels); None logs raw images (large).
        all_frames: when the env returns all 4 frames of a chunk, log every one (four times the
            size); by default the last, the frame a policy acts on.
        depth: log ``("depth", camera)`` maps when the env provides them.
        topdown: draw the top-down view when the env provides ground-truth poses (the road
            and obstacles when the logger has a scene source, else the car and its path).
        truth_series: ground-truth fields plotted as time series.
        fps: world frame rate; ``sim_time = frame / fps``.
        topdown_window: what the top-down view shows around the car (20 m behind to 60 m
            ahead, 15 m to each side by default).
        trail_frames: positions kept for the path (a fixed-size buffer per row).
        background: encode and log on a background thread (the env does not wait for JPEG).
        max_pending: steps that may wait for the background thread before the caller blocks.

    Example:
        >>> LogOptions(rows=(0, 5), jpeg_quality=70).rows
        (0, 5)
        >>> LogOptions(jpeg_quality=0)
        Traceback (most recent call last):
        ...
        ValueError: jpeg_quality must be within 1-100 or None, got 0
    """

    rows: tuple[int, ...] | None = None
    cameras: tuple[str, ...] | None = None
    jpeg_quality: int | None = DEFAULT_JPEG_QUALITY
    all_frames: bool = False
    depth: bool = True
    topdown: bool = True
    truth_series: tuple[str, ...] = DEFAULT_TRUTH_SERIES
    fps: float = FPS
    topdown_window: Window = DEFAULT_WINDOW
    trail_frames: int = 200
    background: bool = True
    max_pending: int = 2

    def __post_init__(self) -> None:
        if self.jpeg_quality is not None and not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be within 1-100 or None, got {self.jpeg_quality}")
        if self.rows is not None and (not self.rows or min(self.rows) < 0):
            raise ValueError(f"rows must be non-empty and non-negative, got {self.rows}")
        if not self.fps > 0:
            raise ValueError(f"fps must be positive, got {self.fps}")
        if self.trail_frames < 2:
            raise ValueError(f"trail_frames must be >= 2, got {self.trail_frames}")
        if self.max_pending < 1:
            raise ValueError(f"max_pending must be >= 1, got {self.max_pending}")
