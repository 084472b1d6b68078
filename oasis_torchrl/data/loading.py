"""Open an oasis LeRobot dataset for behaviour cloning of an action-chunk policy."""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from lerobot.utils.constants import ACTION

from oasis_torchrl.protocol import CHUNK

logger = logging.getLogger(__name__)

"""Actions a chunk policy predicts per sample by default (one world-model call)."""


def default_repo_id(root: str | Path) -> str:
    """The local repo id of a dataset folder (LeRobot wants one even offline).

    Example:
        >>> default_repo_id("/data/city_drives")
        'local/city_drives'
    """
    return f"local/{Path(root).name}"


def is_dataset_root(path: str | Path) -> bool:
    """Whether ``path`` is a LeRobot dataset folder (it has ``meta/info.json``).

    Example:
        >>> is_dataset_root("/nonexistent")
        False
    """
    return (Path(path) / "meta" / "info.json").is_file()


def dataset_repo_id(root: str | Path, repo_id: str | None = None) -> str:
    """The repo id to open the dataset at ``root`` with: ``repo_id``, or (none given) the local
    one, for a folder that must then hold a dataset: LeRobot would otherwise try to download
    ``local/<name>`` and fail with a network error that names no folder.

    Raises:
        FileNotFoundError: no ``repo_id`` and ``root`` holds no LeRobot dataset.

    Example:
        >>> dataset_repo_id("/nowhere/drives", "me/drives")
        'me/drives'
        >>> dataset_repo_id("/nowhere/drives")
        Traceback (most recent call last):
        ...
        FileNotFoundError: /nowhere/drives is not a LeRobot dataset (no meta/info.json)
    """
    if repo_id:
        return repo_id
    if not is_dataset_root(root):
        raise FileNotFoundError(f"{root} is not a LeRobot dataset (no meta/info.json)")
    return default_repo_id(root)


@functools.cache
def default_video_backend() -> str:
    """``"torchcodec"`` when its FFmpeg libraries load on this machine, ``"pyav"`` otherwise.

    LeRobot picks torchcodec whenever the package is installed, even when its shared libraries
    cannot load; this checks that they actually do.

    Example:
        >>> default_video_backend() in ("torchcodec", "pyav")
        True
    """
    try:
        import torchcodec.decoders  # noqa: F401
    except Exception as error:  # a missing FFmpeg surfaces as OSError or RuntimeError
        logger.info("torchcodec cannot load (%s); decoding videos with pyav", type(error).__name__)
        return "pyav"
    return "torchcodec"


def action_delta_timestamps(fps: int, action_dim: int, horizon: int = CHUNK) -> list[float]:
    """Offsets (seconds) of the rows that together hold the next ``horizon`` actions.

    A dataset with one ``[throttle, steering]`` per row (``action_dim`` 2) needs ``horizon``
    rows; one whose rows hold a flattened chunk (``action_dim`` 8) needs ``horizon / 4`` rows.

    Example:
        >>> action_delta_timestamps(20, 2)
        [0.0, 0.05, 0.1, 0.15]
        >>> action_delta_timestamps(5, 8, horizon=8)
        [0.0, 0.2]
    """
    if horizon < 1:
        raise ValueError(f"horizon must be >= 1, got {horizon}")
    actions_per_row = action_dim // 2
    return [k / fps for k in range(math.ceil(horizon / actions_per_row))]


def open_for_bc(
    root: str | Path,
    *,
    horizon: int = CHUNK,
    repo_id: str | None = None,
    episodes: Sequence[int] | None = None,
    image_transforms: Callable[[Any], Any] | None = None,
    video_backend: str | None = None,
) -> Any:
    """A ``LeRobotDataset`` whose samples carry the next ``horizon`` actions.

    Each sample has the current frames (``observation.images.<camera>``, float ``[3, H, W]``
    in ``[0, 1]``), ``observation.state``, ``task``, and ``action`` stacked over the rows of
    :func:`action_delta_timestamps` with ``action_is_pad`` marking rows past the episode end:
    ``[horizon, 2]`` for frame-row datasets; ``[rows, 8]`` for chunk-row datasets
    (``sample["action"].reshape(-1, 2)[:horizon]`` gives the actions in order either way).

    Args:
        root: the dataset folder.
        horizon: actions per sample.
        repo_id: LeRobot repo id (default ``local/<folder name>``).
        episodes: load only these episode indices.
        image_transforms: torchvision v2 transforms for the images.
        video_backend: ``"pyav"`` or ``"torchcodec"``; default: :func:`default_video_backend`.

    Example:
        >>> dataset = open_for_bc("drives")  # doctest: +SKIP
        >>> dataset[0]["action"].shape  # doctest: +SKIP
        torch.Size([4, 2])
    """
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata

    root = Path(root)
    repo_id = dataset_repo_id(root, repo_id)
    meta = LeRobotDatasetMetadata(repo_id, root=root)
    action_dim = meta.features[ACTION]["shape"][0]
    delta = {ACTION: action_delta_timestamps(meta.fps, action_dim, horizon)}
    return LeRobotDataset(
        repo_id,
        root=root,
        episodes=list(episodes) if episodes is not None else None,
        image_transforms=image_transforms,
        delta_timestamps=delta,
        video_backend=video_backend or default_video_backend(),
    )
