"""Import human driving recordings (the reference SDK's episode folders) into a LeRobot dataset.

Source layout: ``<source>/episode_<id>/manifest.jsonl``, one JSON object per step with
``action`` (a 4x2 ``[throttle, steering]`` chunk in [-1, 1]) and ``frame_left_forward``,
``frame_front``, ``frame_right_forward`` (PNG paths relative to the episode folder, RGBA
768x512). The frames of a step are what the driver saw when choosing the chunk, so each step
becomes one chunk row (the mapping of :mod:`oasis_torchrl.data.chunk_rows` at world fps / 4):
image = the step's frames, ``observation.state`` = the previous chunk's last action (zeros on
the first row), ``action`` = the chunk flattened to 8 values, ``next.done`` on the last row.
Recordings have no reward and no world seed, so those columns are absent.

Episodes are read one at a time and their frames streamed to the encoder, so memory stays
bounded. Each manifest is checked first (JSON, action shapes and ranges, frame files present,
frame sizes from the PNG headers); a bad episode is reported with its path and line and skipped.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from lerobot.utils.constants import ACTION, DONE, OBS_STATE
from PIL import Image

from oasis_torchrl.config.recording import DEFAULT_CRF, DEFAULT_VCODEC
from oasis_torchrl.data.features import (
    DatasetLayout,
    build_features,
    image_key,
)
from oasis_torchrl.data.images import resize_frames
from oasis_torchrl.data.writer import open_dataset, write_episode
from oasis_torchrl.protocol import CAMERAS, CHUNK, FPS

logger = logging.getLogger(__name__)

MANIFEST = "manifest.jsonl"
SOURCE_SIZE = (512, 768)
"""``(height, width)`` of the reference recorder's frames."""
DEFAULT_TASK = "human driving"


class RecordingError(ValueError):
    """A recording that cannot be imported, with the file (and manifest line) at fault.

    Example:
        >>> str(RecordingError(Path("ep/manifest.jsonl"), "broken JSON", line=3))
        'ep/manifest.jsonl:3: broken JSON'
    """

    def __init__(self, path: Path, reason: str, line: int | None = None) -> None:
        self.path = path
        self.line = line
        self.reason = reason
        where = f"{path}:{line}" if line is not None else str(path)
        super().__init__(f"{where}: {reason}")


@dataclass(frozen=True)
class RecordedStep:
    """One manifest line: the chunk the driver chose and the frame file of each camera.

    Example:
        >>> RecordedStep(1, np.zeros((4, 2), np.float32), {"front": Path("f.png")}).line
        1
    """

    line: int
    action: np.ndarray
    frames: dict[str, Path]


@dataclass
class ImportReport:
    """What an import did: episodes imported, episodes skipped (with why), rows written.

    Example:
        >>> ImportReport().rows
        0
    """

    imported: list[Path] = field(default_factory=list)
    skipped: list[RecordingError] = field(default_factory=list)
    rows: int = 0


def _episode_order(path: Path) -> tuple[int, str]:
    suffix = path.name.removeprefix("episode_")
    return (int(suffix), path.name) if suffix.isdigit() else (2**63, path.name)


def find_episodes(source: str | Path) -> list[Path]:
    """The ``episode_*`` folders of ``source``, in episode order (``episode_2`` before ``_10``).

    Example:
        >>> import tempfile
        >>> root = Path(tempfile.mkdtemp())
        >>> for name in ("episode_10", "episode_2", "notes"):
        ...     (root / name).mkdir()
        >>> [path.name for path in find_episodes(root)]
        ['episode_2', 'episode_10']
    """
    source = Path(source)
    if not source.is_dir():
        raise FileNotFoundError(f"recordings folder {source} does not exist")
    return sorted((p for p in source.glob("episode_*") if p.is_dir()), key=_episode_order)


def _parse_action(value: Any, manifest: Path, line: int) -> np.ndarray:
    try:
        action = np.asarray(value, dtype=np.float32)
    except (TypeError, ValueError):
        raise RecordingError(manifest, f"action is not a numeric array: {value!r}", line) from None
    if action.shape != (CHUNK, 2):
        raise RecordingError(
            manifest, f"action must have shape ({CHUNK}, 2), got {action.shape}", line
        )
    if not np.isfinite(action).all() or np.abs(action).max() > 1.0:
        raise RecordingError(manifest, f"action outside [-1, 1]: {action.tolist()}", line)
    return action


def _frame_path(
    record: dict, camera: str, episode: Path, size: tuple[int, int], manifest: Path, line: int
) -> Path:
    relative = record.get(f"frame_{camera}")
    if not isinstance(relative, str):
        raise RecordingError(manifest, f"frame_{camera} is missing or not a path", line)
    path = (episode / relative).resolve()
    if not path.is_relative_to(episode.resolve()):
        raise RecordingError(manifest, f"frame_{camera} is outside the episode: {relative}", line)
    if not path.is_file():
        raise RecordingError(manifest, f"missing frame file {relative}", line)
    try:
        with Image.open(path) as image:
            width, height = image.size
    except OSError as error:
        raise RecordingError(manifest, f"unreadable frame {relative}: {error}", line) from None
    if (height, width) != tuple(size):
        raise RecordingError(
            manifest,
            f"frame {relative} is {width}x{height}, expected {size[1]}x{size[0]} (width x height)",
            line,
        )
    return path


def read_manifest(
    episode: Path,
    cameras: Sequence[str] = CAMERAS,
    source_size: tuple[int, int] = SOURCE_SIZE,
) -> list[RecordedStep]:
    """Parse and check one episode's manifest without decoding any frame.

    Raises:
        RecordingError: the first problem found, with the file and line.

    Example:
        >>> read_manifest(Path("no_such_episode"))
        Traceback (most recent call last):
        ...
        oasis_torchrl.data.importer.RecordingError: no_such_episode/manifest.jsonl: missing file
    """
    manifest = episode / MANIFEST
    if not manifest.is_file():
        raise RecordingError(manifest, "missing file")
    steps = []
    with manifest.open(encoding="utf-8") as handle:
        for line, text in enumerate(handle, start=1):
            if not text.strip():
                continue
            try:
                record = json.loads(text)
            except json.JSONDecodeError as error:
                raise RecordingError(manifest, f"broken JSON: {error.msg}", line) from None
            if not isinstance(record, dict) or "action" not in record:
                raise RecordingError(manifest, "a step must be an object with an action", line)
            action = _parse_action(record["action"], manifest, line)
            frames = {
                camera: _frame_path(record, camera, episode, source_size, manifest, line)
                for camera in cameras
            }
            steps.append(RecordedStep(line, action, frames))
    if not steps:
        raise RecordingError(manifest, "no steps")
    return steps


def drop_idle_start(steps: Sequence[RecordedStep]) -> list[RecordedStep]:
    """``steps`` without the leading all-zero chunks (the car waiting before the drive starts).

    Only the leading ones go: dropping idle steps mid-episode would join frames that are not
    consecutive in time.

    Example:
        >>> idle, go = np.zeros((4, 2), np.float32), np.ones((4, 2), np.float32)
        >>> steps = [RecordedStep(n, a, {}) for n, a in enumerate((idle, go, idle), 1)]
        >>> [step.line for step in drop_idle_start(steps)]
        [2, 3]
    """
    first = next((i for i, step in enumerate(steps) if np.any(step.action)), len(steps))
    return list(steps[first:])


def _load_frame(path: Path, size: tuple[int, int], manifest: Path, line: int) -> np.ndarray:
    try:
        with Image.open(path) as image:
            rgb = np.array(image.convert("RGB"))  # writable, as torch wants
    except OSError as error:
        raise RecordingError(manifest, f"cannot decode {path.name}: {error}", line) from None
    return resize_frames(torch.from_numpy(rgb), size).numpy()


def episode_rows(
    steps: Sequence[RecordedStep], manifest: Path, image_size: tuple[int, int]
) -> Iterator[dict[str, np.ndarray]]:
    """The dataset rows of an episode, decoding each step's frames as it goes.

    Example:
        >>> import tempfile
        >>> folder = Path(tempfile.mkdtemp())
        >>> Image.new("RGBA", (8, 6)).save(folder / "f.png")
        >>> step = RecordedStep(1, np.ones((4, 2), np.float32), {"front": folder / "f.png"})
        >>> row = next(episode_rows([step], folder / MANIFEST, (6, 8)))
        >>> row["observation.images.front"].shape, row["action"].shape, bool(row["next.done"])
        ((6, 8, 3), (8,), True)
    """
    previous = np.zeros(2, np.float32)
    for index, step in enumerate(steps):
        row = {
            image_key(camera): _load_frame(path, image_size, manifest, step.line)
            for camera, path in step.frames.items()
        }
        row[OBS_STATE] = previous
        row[ACTION] = step.action.reshape(-1)
        row[DONE] = np.array([index == len(steps) - 1])
        previous = step.action[-1]
        yield row


def _read_steps(episode: Path, source_size: tuple[int, int], drop_idle: bool) -> list[RecordedStep]:
    steps = read_manifest(episode, source_size=source_size)
    if drop_idle:
        steps = drop_idle_start(steps)
        if not steps:
            raise RecordingError(episode / MANIFEST, "every step is idle (all-zero actions)")
    return steps


def import_recordings(
    source: str | Path,
    root: str | Path,
    *,
    repo_id: str | None = None,
    task: str = DEFAULT_TASK,
    fps: int = FPS,
    drop_idle: bool = False,
    source_size: tuple[int, int] = SOURCE_SIZE,
    image_size: tuple[int, int] | None = None,
    vcodec: str = DEFAULT_VCODEC,
    crf: float = DEFAULT_CRF,
    append: bool = False,
    on_episode: Callable[[Path, int], None] | None = None,
) -> ImportReport:
    """Import every ``episode_*`` folder of ``source`` into the LeRobot dataset at ``root``.

    Args:
        source: folder of ``episode_*`` recordings.
        root: dataset folder (created; must not exist unless ``append``).
        repo_id: LeRobot repo id (default ``local/<folder name>``).
        task: the task (prompt) of every imported episode.
        fps: world-model frame rate of the recordings (the dataset runs at ``fps / 4``).
        drop_idle: drop each episode's leading all-zero chunks.
        source_size: ``(height, width)`` every frame must have.
        image_size: stored ``(height, width)`` (even); default ``source_size``.
        vcodec: video codec.
        crf: video quality (lower is better).
        append: add the episodes to the dataset at ``root``.
        on_episode: called as ``on_episode(folder, rows)`` after each episode (0 rows: skipped).

    Returns:
        An :class:`ImportReport`; skipped episodes are also logged as warnings.

    Example:
        >>> report = import_recordings("recordings", "human_drives")  # doctest: +SKIP
        >>> [str(error) for error in report.skipped]  # doctest: +SKIP
        ['recordings/episode_7/manifest.jsonl:12: broken JSON: Expecting value']
    """
    if fps % CHUNK:
        raise ValueError(f"fps {fps} is not divisible by {CHUNK} (one row per chunk)")
    layout = DatasetLayout(
        CAMERAS,
        image_size or source_size,
        actions_per_row=CHUNK,
        with_reward=False,
        with_seed=False,
    )
    report, dataset = ImportReport(), None
    try:
        for episode in find_episodes(source):
            try:
                steps = _read_steps(episode, source_size, drop_idle)
                if dataset is None:
                    dataset = open_dataset(
                        root,
                        build_features(layout),
                        fps // CHUNK,
                        repo_id=repo_id,
                        vcodec=vcodec,
                        crf=crf,
                        append=append,
                    )
                rows = write_episode(
                    dataset, episode_rows(steps, episode / MANIFEST, layout.image_size), task
                )
            except RecordingError as error:
                logger.warning("skipping episode %s: %s", episode.name, error)
                report.skipped.append(error)
                rows = 0
            else:
                report.imported.append(episode)
                report.rows += rows
            if on_episode is not None:
                on_episode(episode, rows)
    finally:
        if dataset is not None:
            dataset.finalize()
    return report
