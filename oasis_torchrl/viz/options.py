"""What a :class:`~oasis_torchrl.viz.RolloutLogger` logs, and how."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from oasis_torchrl.proto import sim_pb2
from oasis_torchrl.protocol import FPS
from oasis_torchrl.viz.images import DEFAULT_JPEG_QUALITY
from oasis_torchrl.viz.topdown import local_scene

SceneSource = Callable[[str, int], "sim_pb2.SceneResponse | None"]
"""``source(prompt, seed)``: the static world of an episode, or None when unknown."""

DEFAULT_TRUTH_SERIES = ("speed", "lateral_offset", "obstacle_distance", "collided", "off_road")


@dataclass(frozen=True)
class LogOptions:
    """Logging options (defaults keep files small and the viewer readable).

    Args:
        rows: env rows to log (default: all). Each logged row gets its own tab.
        cameras: cameras to log (default: every ``("pixels", camera)``).
        jpeg_quality: JPEG quality 1-100 of logged frames; None logs raw images (large).
        all_frames: when the env returns all 4 frames of a chunk, log every one (else the last).
        depth: log ``("depth", camera)`` maps when the env provides them.
        topdown: draw the top-down map when the env provides ground-truth poses.
        truth_series: ground-truth fields plotted as time series.
        fps: world frame rate; ``sim_time = frame / fps``.
        scene_source: ``source(prompt, seed) -> SceneResponse | None`` for the top-down road
            and obstacles; default: rebuilt locally (the embedded server's worlds are
            deterministic). None draws only the car and its path.
        topdown_radius: metres around the car drawn on the top-down map.
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
    all_frames: bool = True
    depth: bool = True
    topdown: bool = True
    truth_series: tuple[str, ...] = DEFAULT_TRUTH_SERIES
    fps: float = FPS
    scene_source: SceneSource | None = local_scene
    topdown_radius: float = 60.0
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
        if not self.topdown_radius > 0:
            raise ValueError(f"topdown_radius must be positive, got {self.topdown_radius}")
        if self.trail_frames < 2:
            raise ValueError(f"trail_frames must be >= 2, got {self.trail_frames}")
        if self.max_pending < 1:
            raise ValueError(f"max_pending must be >= 1, got {self.max_pending}")
