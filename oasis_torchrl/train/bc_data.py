"""A LeRobot dataset decoded once into memory, for fast behaviour-cloning epochs.

``LeRobotDataset.__getitem__`` decodes every camera's video from the nearest keyframe for every
sample, which costs far more than a training step of the oasis network.
:class:`InMemoryBCDataset` decodes each video file in one sequential pass (PyAV's frames, as
LeRobot's ``pyav`` backend gives them; :mod:`oasis_torchrl.data.video_frames`), keeps the
frames as uint8 (at the policy's size, if given: resized once, not per batch), and serves the
same sample dict
(``observation.images.<camera>`` float in ``[0, 1]``, ``observation.state``, ``action``,
``privileged_state`` where recorded, the ``<key>_is_pad`` masks and the indices) by LeRobot's
delta-index rules: a key with delta indices stacks the rows at those offsets within the same
episode, clamped at its ends and marked as padding there (e.g. the frame one chunk earlier and
the next 4 actions). A ``DataLoader`` gets whole batches from it (``__getitems__``, one
indexing per key), not one sample at a time. An optional ``frame_transform`` (e.g. random
shifts) runs on each camera's batch while it is still bytes, a quarter of the memory traffic of
the same transform on the floats.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from contextlib import closing
from pathlib import Path
from typing import Any

import numpy as np
import torch
from lerobot.datasets.feature_utils import get_delta_indices
from lerobot.utils.constants import ACTION, OBS_STATE
from torch.utils.data import Dataset
from tqdm import tqdm

from oasis_torchrl.data.images import resize_frames
from oasis_torchrl.data.video_frames import MissingFrameError, frames_at
from oasis_torchrl.models.privileged import PRIVILEGED_KEY

logger = logging.getLogger(__name__)

_COLUMNS = (OBS_STATE, ACTION, "episode_index", "index", "frame_index", "timestamp")


class InMemoryBCDataset(Dataset):
    """Every row of a ``LeRobotDataset`` (opened with ``delta_timestamps``, at least for
    ``action``).

    Args:
        dataset: the LeRobot dataset (its ``delta_timestamps`` say which action rows to stack).
        image_size: ``(height, width)`` to keep the frames at, resized once while decoding
            (antialiased bilinear, as the policy's preprocessor would resize every batch;
            ``None``: the dataset's size).
        progress: show a progress bar while decoding.
        frame_transform: applied to each camera's frames of a batch, uint8
            ``[B, ..., 3, H, W]``, before their conversion to float (augmentation such as
            :func:`~oasis_torchrl.train.shift.random_shift`; ``None``: none).
        camera_keys: the cameras' features to keep (``None``: every stored camera).

    Example:
        >>> cached = InMemoryBCDataset(open_for_bc("drives"))  # doctest: +SKIP
        >>> cached[0]["action"].shape  # doctest: +SKIP
        torch.Size([4, 2])
    """

    def __init__(
        self,
        dataset: Any,
        *,
        image_size: tuple[int, int] | None = None,
        progress: bool = True,
        frame_transform: Callable[[torch.Tensor], torch.Tensor] | None = None,
        camera_keys: Sequence[str] | None = None,
    ) -> None:
        if not dataset.delta_timestamps or ACTION not in dataset.delta_timestamps:
            raise ValueError(
                "open the dataset with delta_timestamps for 'action' (an action chunk)"
            )
        stored = list(dataset.meta.video_keys) + list(dataset.meta.image_keys)
        self.camera_keys = stored if camera_keys is None else list(camera_keys)
        delta_indices = get_delta_indices(dataset.delta_timestamps, dataset.fps)
        self.deltas = {key: torch.tensor(d) for key, d in delta_indices.items()}
        # The privileged state, where recorded, is the auxiliary head's target.
        targets = [PRIVILEGED_KEY] if PRIVILEGED_KEY in dataset.features else []
        names = [*_COLUMNS, *targets]
        columns = dataset.hf_dataset.with_format("torch", columns=names)[:]
        self.columns = {key: torch.as_tensor(columns[key]) for key in names}
        self.row_keys = [OBS_STATE, ACTION, *targets]
        # Absolute dataset indices (what episode bounds use) -> positions in the loaded rows.
        indices = self.columns["index"]
        self._first_index = int(indices.min())
        self._position = torch.full((int(indices.max()) - self._first_index + 1,), -1)
        self._position[indices - self._first_index] = torch.arange(len(indices))
        episodes = sorted(set(self.columns["episode_index"].tolist()))
        bounds = {
            ep: (
                int(dataset.meta.episodes[ep]["dataset_from_index"]),
                int(dataset.meta.episodes[ep]["dataset_to_index"]),
            )
            for ep in episodes
        }
        # Each row's episode bounds [start, end), absolute indices.
        self._bounds = torch.tensor([bounds[int(ep)] for ep in self.columns["episode_index"]])
        self.image_size = image_size
        self.frame_transform = frame_transform
        self.frames = {
            key: self._decode(dataset, key, episodes, progress) for key in self.camera_keys
        }

    def _decode(self, dataset: Any, key: str, episodes: list[int], progress: bool) -> torch.Tensor:
        """uint8 ``[rows, 3, H, W]`` of one camera, in hf-dataset row order (at
        ``image_size`` if set): each video file decoded in one pass, images read with the
        table."""
        rows = {ep: (self.columns["episode_index"] == ep).nonzero().flatten() for ep in episodes}
        if key in dataset.meta.video_keys:
            frames = self._decode_videos(dataset, key, rows, progress)
        else:
            frames = {}
            for ep, ep_rows in rows.items():
                images = torch.stack([dataset[int(row)][key] for row in ep_rows])
                frames[ep] = self._kept((images * 255).round_().to(torch.uint8).movedim(1, -1))
        return torch.cat([frames[ep] for ep in episodes])

    def _kept(self, frames: torch.Tensor) -> torch.Tensor:
        """uint8 HWC frames as the cache keeps them: ``[N, 3, H, W]`` at ``image_size`` (each
        episode resized as it is decoded, so no more than one is held at the dataset's size)."""
        if self.image_size is not None:
            frames = resize_frames(frames, self.image_size)
        return frames.permute(0, 3, 1, 2)

    def _decode_videos(
        self, dataset: Any, key: str, rows: dict[int, torch.Tensor], progress: bool
    ) -> dict[int, torch.Tensor]:
        """Each episode's frames of camera ``key`` as the cache keeps them, every video file
        decoded once (:func:`~oasis_torchrl.data.video_frames.frames_at`)."""
        files: dict[Path, list[tuple[float, int]]] = {}
        for ep in rows:
            start = float(dataset.meta.episodes[ep][f"videos/{key}/from_timestamp"])
            path = dataset.root / dataset.meta.get_video_file_path(ep, key)
            files.setdefault(path, []).append((start, ep))
        frames: dict[int, torch.Tensor] = {}
        for path, starts in tqdm(files.items(), desc=f"decoding {key}", disable=not progress):
            starts.sort()  # the file's episodes in the order they were written
            # float64: float32 sums lose the 0.1 ms tolerance after ~15 min of video.
            times = [start + self.columns["timestamp"][rows[ep]].double() for start, ep in starts]
            wanted = torch.cat(times).numpy()
            with closing(frames_at(path, wanted, dataset.tolerance_s)) as decoded:
                for (_, ep), ep_times in zip(starts, times, strict=True):
                    try:
                        images = [next(decoded) for _ in range(len(ep_times))]
                    except MissingFrameError as error:
                        raise MissingFrameError(f"episode {ep} of {key}: {error}") from error
                    frames[ep] = self._kept(torch.from_numpy(np.stack(images)))
        return frames

    def __len__(self) -> int:
        return len(self.columns["index"])

    def __getitem__(self, position: int) -> dict[str, Any]:
        """One sample, as ``LeRobotDataset[position]`` gives it (without the task columns)."""
        return {key: value[0] for key, value in self.__getitems__([position]).items()}

    def __getitems__(self, positions: list[int]) -> dict[str, Any]:
        """The collated batch of these samples, gathered in one indexing per key (the
        ``DataLoader`` calls it with a batch's indices; pass :meth:`collate` as its
        ``collate_fn``)."""
        rows = torch.as_tensor(positions, dtype=torch.long)
        index = self.columns["index"][rows, None]
        start, end = self._bounds[rows, :1], self._bounds[rows, 1:]
        sources = {**self.frames, **{key: self.columns[key] for key in self.row_keys}}
        batch: dict[str, Any] = {}
        for key, source in sources.items():
            deltas = self.deltas.get(key)
            if deltas is None:
                batch[key] = source[rows]
                continue
            wanted = index + deltas
            clamped = torch.minimum(torch.maximum(wanted, start), end - 1)
            batch[key] = source[self._position[clamped - self._first_index]]
            batch[f"{key}_is_pad"] = (wanted < start) | (wanted >= end)
        for key in self.camera_keys:
            frames = (
                batch[key] if self.frame_transform is None else self.frame_transform(batch[key])
            )
            batch[key] = frames.float().div_(255)
        for key in ("episode_index", "index", "frame_index", "timestamp"):
            batch[key] = self.columns[key][rows]
        return batch

    @staticmethod
    def collate(batch: dict[str, Any]) -> dict[str, Any]:
        """The ``DataLoader``'s ``collate_fn``: :meth:`__getitems__` already collates.

        Example:
            >>> batches = DataLoader(cached, 64, collate_fn=cached.collate)  # doctest: +SKIP
        """
        return batch
