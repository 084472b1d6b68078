"""LeRobot datasets to rerun: chosen episodes, each under ``episode/<index>`` with the same layout
as live rollouts (cameras, actions, state, reward, events; no ground truth, so no top-down map).

Tabular columns are read with LeRobot's own reader and sent as whole columns; videos are decoded
sequentially with PyAV (:func:`~oasis_torchrl.data.video_frames.frames_at`) and logged frame by
frame, so memory stays flat however long an episode is.
Timelines: ``frame`` = the dataset's ``frame_index``, ``step`` = the env step it belongs to (4
frames a step in a dataset of one row per frame, 1 in one of a row per step), ``sim_time`` =
``frame_index / fps``. Each episode's tab is named after it (``episode 3``), every panel after the
dataset (its folder's name, or the repo id given).
Needs the ``lerobot`` extra.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from oasis_torchrl.data.features import IMAGE_PREFIX
from oasis_torchrl.data.loading import default_repo_id, is_dataset_root
from oasis_torchrl.data.video_frames import episode_frames
from oasis_torchrl.protocol import CHUNK, FPS
from oasis_torchrl.viz.blueprint import default_blueprint
from oasis_torchrl.viz.images import DEFAULT_JPEG_QUALITY, check_frame, image_archetype
from oasis_torchrl.viz.paths import EPISODE_ROOT, RowPaths
from oasis_torchrl.viz.series import send_series
from oasis_torchrl.viz.timelines import set_frame

logger = logging.getLogger(__name__)

STATE, ACTION, REWARD, DONE, SEED = (
    "observation.state",
    "action",
    "next.reward",
    "next.done",
    "episode_seed",
)


def _names(feature: dict[str, Any], width: int) -> list[str]:
    names = feature.get("names")
    if isinstance(names, dict):  # LeRobot also allows {"motors": [...]}
        names = next(iter(names.values()), None)
    if isinstance(names, list) and len(names) == width:
        return [str(name) for name in names]
    return [str(k) for k in range(width)]


class DatasetReplay:
    """Replays episodes of a LeRobot dataset into a recording.

    Args:
        root: the dataset folder.
        recording: where to log (see :func:`~oasis_torchrl.viz.recording.open_recording`).
        jpeg_quality: JPEG quality of logged frames (None: raw images).
        repo_id: LeRobot repo id (default ``local/<folder name>``).

    :attr:`name` (the repo id given, else the folder's name) titles every panel.

    Example:
        >>> replay = DatasetReplay("drives", rr.RecordingStream("doc"))  # doctest: +SKIP
        >>> replay.log([0, 3])  # doctest: +SKIP
    """

    def __init__(
        self,
        root: str | Path,
        recording: rr.RecordingStream,
        *,
        jpeg_quality: int | None = DEFAULT_JPEG_QUALITY,
        repo_id: str | None = None,
    ) -> None:
        from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata

        self.root = Path(root)
        if not is_dataset_root(self.root):
            raise ValueError(f"{self.root} is not a LeRobot dataset (no meta/info.json)")
        self.name = repo_id or self.root.resolve().name
        self.repo_id = repo_id or default_repo_id(self.root)
        self.meta = LeRobotDatasetMetadata(self.repo_id, root=self.root)
        self.recording = recording
        self.jpeg_quality = jpeg_quality

    @property
    def cameras(self) -> list[str]:
        """Camera names (the ``observation.images.<camera>`` features)."""
        return [key.removeprefix(IMAGE_PREFIX) for key in self.meta.camera_keys]

    def check_episodes(self, episodes: Sequence[int] | None) -> list[int]:
        """``episodes`` (default: all) after checking they exist."""
        total = self.meta.total_episodes
        chosen = list(range(total)) if episodes is None else [int(e) for e in episodes]
        missing = [e for e in chosen if not 0 <= e < total]
        if missing or not chosen:
            raise ValueError(
                f"episodes {missing or chosen} not in dataset {self.root} "
                f"({total} episodes: 0-{total - 1})"
            )
        return chosen

    def log(self, episodes: Sequence[int] | None = None) -> list[int]:
        """Log ``episodes`` (default all), each as a row of its own; returns them."""
        from lerobot.datasets.lerobot_dataset import LeRobotDataset

        chosen = self.check_episodes(episodes)
        self.recording.send_blueprint(
            default_blueprint(
                chosen,
                self.cameras,
                root=EPISODE_ROOT,
                topdown=None,
                signals=self._signals(),
                titles=[f"episode {episode}" for episode in chosen],
                owner=self.name,
            )
        )
        dataset = LeRobotDataset(
            self.repo_id, root=self.root, episodes=chosen, video_backend="pyav"
        )
        table = dataset.hf_dataset.with_format("numpy")
        episode_of_row = np.asarray(table["episode_index"]).reshape(-1)
        for episode in chosen:
            rows = table[np.flatnonzero(episode_of_row == episode)]
            self._log_episode(episode, rows)
            logger.info("replayed episode %d (%d frames)", episode, len(rows["frame_index"]))
        return chosen

    def _signals(self) -> set[str]:
        """The palette keys of the series a replay logs (which plots the layout shows)."""
        features = self.meta.features
        signals = {"reward/total"} if REWARD in features else set()
        for key, group in ((ACTION, "action"), (STATE, "state")):
            if key in features:
                width = int(np.prod(features[key]["shape"]))
                signals |= {f"{group}/{name}" for name in _names(features[key], width)}
        return signals

    def _log_episode(self, episode: int, rows: dict[str, np.ndarray]) -> None:
        paths = RowPaths(EPISODE_ROOT, episode)
        frames = np.asarray(rows["frame_index"]).reshape(-1).astype(np.int64)
        self._log_events(paths, episode, rows, frames)
        self._log_series(paths, rows, frames)
        for key in self.meta.camera_keys:
            self._log_camera(paths, episode, key, rows, frames)

    @property
    def frames_per_step(self) -> int:
        """Dataset rows per env step: 4 at the world's frame rate, 1 at its step rate."""
        return max(1, round(CHUNK * float(self.meta.fps) / FPS))

    def _at(self, frame: int) -> None:
        set_frame(self.recording, frame, float(self.meta.fps), self.frames_per_step)

    def _log_events(
        self, paths: RowPaths, episode: int, rows: dict[str, np.ndarray], frames: np.ndarray
    ) -> None:
        tasks = self.meta.episodes[episode]["tasks"]
        seed = f", seed {int(np.asarray(rows[SEED]).reshape(-1)[0])}" if SEED in rows else ""
        self._at(frames[0])
        text = f"episode {episode} starts: {', '.join(map(repr, tasks))}{seed}"
        self.recording.log(paths.events, rr.TextLog(text, level="INFO"))
        if DONE in rows:
            for frame in frames[np.asarray(rows[DONE]).reshape(-1).astype(bool)]:
                self._at(frame)
                ends = rr.TextLog(f"episode {episode} ends", level="INFO")
                self.recording.log(paths.events, ends)

    def _log_series(self, paths: RowPaths, rows: dict[str, np.ndarray], frames: np.ndarray) -> None:
        fps = float(self.meta.fps)
        for key, group in ((ACTION, "action"), (STATE, "state")):
            if key not in rows:
                continue
            values = np.asarray(rows[key], dtype=np.float64).reshape(len(frames), -1)
            names = _names(self.meta.features[key], values.shape[1])
            for column, name in enumerate(names):
                path = paths.scalar(group, name)
                send_series(
                    self.recording,
                    path,
                    frames,
                    values[:, column],
                    fps,
                    frames_per_step=self.frames_per_step,
                )
        if REWARD in rows:
            reward = np.asarray(rows[REWARD], dtype=np.float64).reshape(-1)
            send_series(
                self.recording,
                paths.scalar("reward", "total"),
                frames,
                reward,
                fps,
                frames_per_step=self.frames_per_step,
            )

    def _log_camera(
        self,
        paths: RowPaths,
        episode: int,
        key: str,
        rows: dict[str, np.ndarray],
        frames: np.ndarray,
    ) -> None:
        entity = paths.camera(key.removeprefix(IMAGE_PREFIX))
        images = self._images(episode, key, rows, len(frames))
        for frame, image in zip(frames, images, strict=False):
            self._at(frame)
            self.recording.log(entity, image_archetype(check_frame(image, key), self.jpeg_quality))

    def _images(
        self, episode: int, key: str, rows: dict[str, np.ndarray], count: int
    ) -> Iterator[np.ndarray]:
        if key not in self.meta.video_keys:  # stored as images: decoded with the table
            yield from (np.asarray(image, dtype=np.uint8) for image in rows[key])
            return
        yield from episode_frames(self.meta, episode, key, count)
