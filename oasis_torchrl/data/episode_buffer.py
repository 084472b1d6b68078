"""The rows of one still-running episode, with bounded memory.

LeRobot encodes one episode at a time, while N envs run N episodes at once; each open episode
is therefore kept here until it ends. Image columns (by far the bulk) go straight to a raw file
per key, so memory stays bounded however long episodes get; the small columns stay in memory.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np

from oasis_torchrl.data.features import Feature, numpy_dtype


class EpisodeBuffer:
    """Rows of one episode: ``features`` whose dtype is image/video are spilled to disk.

    Args:
        directory: parent folder of this episode's spill files (removed by :meth:`discard`).
        features: the dataset features the rows follow.
        task: the episode's prompt.
        seed: the episode's world seed.

    Example:
        >>> import tempfile
        >>> features = {"img": {"dtype": "video", "shape": (2, 2, 3)},
        ...             "action": {"dtype": "float32", "shape": (2,)}}
        >>> buffer = EpisodeBuffer(Path(tempfile.mkdtemp()), features, "city", 7)
        >>> buffer.append({"img": np.ones((4, 2, 2, 3), np.uint8),
        ...                "action": np.zeros((4, 2), np.float32)})
        >>> rows = list(buffer.rows())
        >>> len(rows), int(rows[3]["img"].sum())
        (4, 12)
        >>> buffer.discard()
    """

    def __init__(self, directory: Path, features: Mapping[str, Feature], task: str, seed: int):
        self.task = task
        self.seed = seed
        self._features = dict(features)
        self._directory = Path(tempfile.mkdtemp(prefix="episode-", dir=directory))
        self._spilled = {
            key: open(self._directory / f"{index}.raw", "wb")  # noqa: SIM115 (closed in rows/discard)
            for index, (key, feature) in enumerate(features.items())
            if feature["dtype"] in ("image", "video")
        }
        self._columns: dict[str, list[np.ndarray]] = {
            key: [] for key in features if key not in self._spilled
        }
        self._length = 0

    def __len__(self) -> int:
        return self._length

    def append(self, rows: Mapping[str, np.ndarray]) -> None:
        """Add rows ``key -> [R, *shape]`` (already checked against the features)."""
        for key, handle in self._spilled.items():
            np.ascontiguousarray(rows[key]).tofile(handle)
        for key, chunks in self._columns.items():
            chunks.append(rows[key])
        self._length += len(next(iter(rows.values())))

    def rows(self) -> Iterator[dict[str, np.ndarray]]:
        """The rows in order, ``key -> value``; images are read-only views of the spill files."""
        if self._length == 0:
            return
        images = {key: self._read_spilled(key) for key in self._spilled}
        small = {key: np.concatenate(chunks) for key, chunks in self._columns.items()}
        for index in range(self._length):
            row = {key: values[index] for key, values in small.items()}
            row.update({key: frames[index] for key, frames in images.items()})
            yield row

    def _read_spilled(self, key: str) -> np.ndarray:
        handle = self._spilled[key]
        handle.flush()
        feature = self._features[key]
        return np.memmap(
            handle.name,
            dtype=numpy_dtype(feature),
            mode="r",
            shape=(self._length, *feature["shape"]),
        )

    def discard(self) -> None:
        """Close and delete the spill files."""
        for handle in self._spilled.values():
            handle.close()
        shutil.rmtree(self._directory, ignore_errors=True)
