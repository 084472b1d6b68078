"""The chunks of a LeRobot dataset with crash marks, labelled for the frames-only reward's heads.

A person drives the hosted model on the drive page and presses C at a crash; the episode ends
there with its last row marked (``next.crash``; on an endpoint with ground truth the world's
collisions fill the column too). Each episode's rows become chunks of 4 front frames with their
actions; a chunk is collided where one of its rows is marked, and the chunks before a mark get
the collision-ahead head's target (chunks to the crash). Such datasets hold no progress, so the
progress label is NaN and the progress head keeps what it learned from the embedded world.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch
from lerobot.utils.constants import ACTION
from tqdm import tqdm

from oasis_torchrl.data.features import CRASH_KEY, image_key
from oasis_torchrl.data.images import resize_frames
from oasis_torchrl.data.loading import dataset_repo_id
from oasis_torchrl.data.video_frames import episode_frames
from oasis_torchrl.protocol import CHUNK, FRONT
from oasis_torchrl.train.motion_chunks import MotionChunks, chunk_labels

if TYPE_CHECKING:
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata

logger = logging.getLogger(__name__)


def _checked_metadata(root: Path, repo_id: str | None) -> LeRobotDatasetMetadata:
    """The dataset's metadata, refused where it cannot label the motion heads."""
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata

    meta = LeRobotDatasetMetadata(dataset_repo_id(root, repo_id), root=root)
    if CRASH_KEY not in meta.features:
        raise ValueError(
            f"{root} has no {CRASH_KEY} column: record on the drive page (`oasis-torchrl play "
            "root=DIR`; C marks a crash) to label crashes"
        )
    if image_key(FRONT) not in meta.video_keys:
        raise ValueError(f"{root} has no {image_key(FRONT)} video: the motion network reads it")
    if tuple(meta.features[ACTION]["shape"]) != (2,):
        raise ValueError(
            f"{root} stores one row per chunk (action {tuple(meta.features[ACTION]['shape'])}); "
            f"the motion network reads all {CHUNK} frames of a chunk: record one row per frame"
        )
    return meta


def dataset_motion_chunks(
    root: str | Path,
    image_size: tuple[int, int],
    horizon: int,
    *,
    repo_id: str | None = None,
    progress: bool = True,
) -> MotionChunks:
    """Every whole chunk of every episode of the dataset at ``root``, one round per episode
    (so a validation share keeps whole episodes out), front frames resized to ``image_size``.

    Raises:
        ValueError: the dataset has no crash marks, no front video, or one row per chunk.
        FileNotFoundError: ``root`` holds no LeRobot dataset.

    Example:
        >>> chunks = dataset_motion_chunks("drives", (64, 96), horizon=5)  # doctest: +SKIP
        >>> chunks.collided.sum()  # doctest: +SKIP
        tensor(12)
    """
    root = Path(root)
    meta = _checked_metadata(root, repo_id)
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    table = LeRobotDataset(meta.repo_id, root=root).hf_dataset.with_format("numpy")
    episode_of = np.asarray(table["episode_index"])
    actions = torch.from_numpy(np.stack(table[ACTION])).float()
    marks = torch.from_numpy(np.asarray(table[CRASH_KEY]).reshape(-1)).float()
    parts = []
    for episode in tqdm(np.unique(episode_of), desc="reading episodes", disable=not progress):
        rows = np.flatnonzero(episode_of == episode)
        chunks = len(rows) // CHUNK
        if not chunks:
            continue
        rows = torch.from_numpy(rows[: chunks * CHUNK])
        frames = np.stack(list(episode_frames(meta, int(episode), image_key(FRONT), len(rows))))
        marked = marks[rows].reshape(1, chunks, CHUNK)
        unknown = torch.full_like(marked, float("nan"))
        gained, hit, time_to = chunk_labels(unknown, marked, horizon)
        parts.append(
            MotionChunks(
                frames=resize_frames(torch.from_numpy(frames), image_size).reshape(
                    chunks, CHUNK, *image_size, 3
                ),
                actions=actions[rows].reshape(chunks, CHUNK, 2),
                progress=gained.flatten(),
                collided=hit.flatten(),
                time_to=time_to.flatten().long(),
                rounds=torch.full((chunks,), int(episode)),
            )
        )
    if not parts:
        raise ValueError(f"{root} holds no episode of at least {CHUNK} rows")
    data = MotionChunks.concat(parts)
    logger.info(
        "%s: %d chunks of %d episodes, %d marked crashes",
        root,
        len(data),
        len(parts),
        int(data.collided.sum()),
    )
    return data


def episodes_of(chunks: MotionChunks) -> list[MotionChunks]:
    """The chunks of each round (one episode each in a dataset's chunks), in order.

    Example:
        >>> rows = MotionChunks(*(torch.zeros(3) for _ in range(5)), torch.tensor([0, 0, 1]))
        >>> [len(episode) for episode in episodes_of(rows)]
        [2, 1]
    """
    return [chunks.select(chunks.rounds == index) for index in chunks.rounds.unique()]
