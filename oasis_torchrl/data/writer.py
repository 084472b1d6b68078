"""Writing episodes through LeRobot's own API (``create`` / ``add_frame`` / ``save_episode`` /
``finalize``), shared by the rollout exporter and the recordings importer.

Frames are streamed to LeRobot's per-camera encoder threads (``streaming_encoding=True``: no PNG
round trip), with the codec set through LeRobot's :class:`~lerobot.configs.video.RGBEncoderConfig`.
That encoder was built for live cameras and drops a frame when its queue stays full for 0.1 s;
replayed frames must all land, so :func:`write_episode` waits for queue room first and refuses
to save an episode that lost a frame anyway, and its threads keep their running image
statistics from level counts, at about a fifth of LeRobot's cost at 96x64
(:mod:`oasis_torchrl.compat`).
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path

import av
import numpy as np
from lerobot.configs.video import RGBEncoderConfig
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.datasets.utils import INFO_PATH

from oasis_torchrl.compat import (
    count_image_statistics,
    dropped_video_frames,
    embed_only_image_tables,
    wait_for_encoder_room,
)
from oasis_torchrl.config.recording import DEFAULT_CRF, DEFAULT_VCODEC
from oasis_torchrl.data.features import Feature, check_same_features
from oasis_torchrl.data.loading import default_repo_id, default_video_backend
from oasis_torchrl.data.quiet import keep_dataset_libraries_quiet

logger = logging.getLogger(__name__)

ROBOT_TYPE = "oasis"
"""The datasets' ``robot_type``: the oasis robot's (``--robot.type=oasis``), so a person's
recordings and the project's datasets can be merged (LeRobot merges only equal robot types)."""


CRF_RANGES: dict[str, tuple[int, int]] = {"h264": (0, 51), "hevc": (0, 51), "libsvtav1": (0, 63)}
"""The ``crf`` each codec accepts; LeRobot does not check it, and its encoder threads would fail
only at the first frame."""


VIDEO_FILE_MB = 4
"""Size (MB) at which a camera's video file is closed and the next episode starts a new one.
LeRobot appends each saved episode by remuxing the whole current file, so the cost of an
episode grows with the file: LeRobot's 200 MB default made recording 80 episodes at 96x64
quadratic. A new dataset stores the size in its ``info.json``; appends keep it."""


def camera_encoder(vcodec: str, crf: float = DEFAULT_CRF) -> RGBEncoderConfig:
    """LeRobot's encoder settings for the cameras: ``vcodec`` at quality ``crf``, LeRobot's
    defaults otherwise.

    Raises:
        ValueError: LeRobot does not know ``vcodec``, this PyAV build cannot encode it, or
            ``crf`` is outside the codec's range.

    Example:
        >>> camera_encoder("h264").crf
        18
        >>> camera_encoder("mjpeg")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: vcodec 'mjpeg': Invalid vcodec 'mjpeg'. Must be one of: ...
        >>> camera_encoder("h264", crf=60)
        Traceback (most recent call last):
        ...
        ValueError: crf 60 is outside h264's range [0, 51] (lower is better quality)
    """
    low, high = CRF_RANGES.get(vcodec, (0, float("inf")))
    if not low <= crf <= high:
        raise ValueError(
            f"crf {crf} is outside {vcodec}'s range [{low}, {high}] (lower is better quality)"
        )
    try:
        return RGBEncoderConfig(vcodec=vcodec, crf=crf)
    except ValueError as error:
        raise ValueError(f"vcodec {vcodec!r}: {error}") from error


def whole_fps(fps: float) -> int:
    """``fps`` as the int LeRobot stores, if it is a positive whole number.

    Example:
        >>> whole_fps(20.0)
        20
        >>> whole_fps(7.5)
        Traceback (most recent call last):
        ...
        ValueError: fps must be a positive whole number (LeRobot stores an int), got 7.5
    """
    if fps <= 0 or int(fps) != fps:
        raise ValueError(f"fps must be a positive whole number (LeRobot stores an int), got {fps}")
    return int(fps)


def open_dataset(
    root: str | Path,
    features: Mapping[str, Feature],
    fps: float,
    *,
    repo_id: str | None = None,
    vcodec: str = DEFAULT_VCODEC,
    crf: float = DEFAULT_CRF,
    append: bool = False,
) -> LeRobotDataset:
    """Create a dataset at ``root``, or (``append=True``) reopen the one there to add episodes.

    Raises:
        FileExistsError: ``root`` holds data and ``append`` is false.
        ValueError: ``fps`` is not a whole number (LeRobot stores an int); ``vcodec`` or
            ``crf`` is not usable (:func:`camera_encoder`); appending with another fps or other
            features (naming the key).

    See :func:`write_episode` for an example.
    """
    fps = whole_fps(fps)
    root = Path(root)
    repo_id = repo_id or default_repo_id(root)
    encoder = camera_encoder(vcodec, crf)
    # LeRobot's encoder threads hand FFmpeg its default stderr logger back when they finish;
    # without this, every episode prints the encoder's banner and statistics.
    av.logging.set_libav_level(av.logging.ERROR)
    count_image_statistics()
    embed_only_image_tables()
    if (root / INFO_PATH).exists():
        if not append:
            raise FileExistsError(f"{root} already holds a LeRobot dataset; append to add episodes")
        dataset = LeRobotDataset.resume(
            repo_id,
            root=root,
            video_backend=default_video_backend(),
            rgb_encoder=encoder,
            streaming_encoding=True,
        )
        if dataset.fps != fps:
            raise ValueError(f"{root} is a {dataset.fps} fps dataset; the new rows are {fps} fps")
        check_same_features(features, dataset.features)
        return dataset
    if root.exists():
        if any(root.iterdir()):
            raise FileExistsError(f"{root} exists and is not a LeRobot dataset")
        root.rmdir()  # LeRobot creates the folder itself and refuses an existing one
    return LeRobotDataset.create(
        repo_id,
        fps,
        dict(features),
        root=root,
        robot_type=ROBOT_TYPE,
        use_videos=True,
        video_backend=default_video_backend(),
        rgb_encoder=encoder,
        streaming_encoding=True,
        video_files_size_in_mb=VIDEO_FILE_MB,
    )


def _check_no_dropped_frames(dataset: LeRobotDataset) -> None:
    dropped = dropped_video_frames(dataset)
    if dropped:
        raise RuntimeError(f"the video encoder dropped frames {dropped}; episode not saved")


@contextlib.contextmanager
def _interrupts_deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM until the block ends, so an episode is saved whole or not at all."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []
    previous = {
        signum: signal.signal(signum, lambda signum, frame: received.append(signum))
        for signum in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        for signum in dict.fromkeys(received):
            signal.raise_signal(signum)  # now handled as it would have been


def write_episode(
    dataset: LeRobotDataset, rows: Iterable[Mapping[str, np.ndarray]], task: str
) -> int:
    """Add ``rows`` (feature key -> value) as one episode with ``task`` and save it.

    On any error (or Ctrl-C) before the save, LeRobot's episode buffer is cleared so the dataset
    holds exactly the episodes saved before; the save itself is never interrupted halfway.

    Returns:
        The number of rows written.

    Example:
        >>> import tempfile
        >>> from oasis_torchrl.data.features import DatasetLayout, build_features
        >>> layout = DatasetLayout(("front",), (16, 16), with_reward=False, with_seed=False)
        >>> dataset = open_dataset(Path(tempfile.mkdtemp()) / "demo", build_features(layout), 20)
        >>> row = {"observation.images.front": np.zeros((16, 16, 3), np.uint8),
        ...        "observation.state": np.zeros(2, np.float32),
        ...        "action": np.zeros(2, np.float32), "next.done": np.array([False])}
        >>> write_episode(dataset, [row] * 3, "parking")
        3
        >>> dataset.finalize()
    """
    count = 0
    try:
        for row in rows:
            wait_for_encoder_room(dataset)
            dataset.add_frame({**row, "task": task})
            count += 1
        if count == 0:
            raise ValueError("an episode needs at least one row")
        _check_no_dropped_frames(dataset)
    except BaseException:
        if dataset.has_pending_frames():
            dataset.clear_episode_buffer(delete_images=False)
        raise
    keep_dataset_libraries_quiet()
    with _interrupts_deferred():
        dataset.save_episode()
    return count
