"""The rows of one still-running episode, with bounded memory.

LeRobot encodes one episode at a time, while N envs run N episodes at once; each open episode
is therefore kept here until it ends. Rows stay in memory up to ``memory_limit`` bytes; past
that, the image columns (by far the bulk) go to one raw file per key, so memory stays bounded
however long episodes get, while short episodes never touch the disk.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import BinaryIO

import numpy as np

from oasis_torchrl.data.features import Feature, numpy_dtype

DEFAULT_MEMORY_LIMIT = 256 << 20


class EpisodeBuffer:
    """Rows of one episode; past ``memory_limit`` bytes its image columns spill to disk.

    Args:
        directory: parent folder of this episode's spill files (made only when it spills).
        features: the dataset features the rows follow.
        task: the episode's prompt.
        seed: the episode's world seed.
        memory_limit: bytes of rows kept in memory before spilling.

    Example:
        >>> import tempfile
        >>> features = {"img": {"dtype": "video", "shape": (2, 2, 3)},
        ...             "action": {"dtype": "float32", "shape": (2,)}}
        >>> buffer = EpisodeBuffer(Path(tempfile.mkdtemp()), features, "city", 7, memory_limit=64)
        >>> for _ in range(3):
        ...     buffer.append({"img": np.ones((4, 2, 2, 3), np.uint8),
        ...                    "action": np.zeros((4, 2), np.float32)})
        >>> rows = list(buffer.rows())
        >>> len(rows), buffer.spilled, int(rows[11]["img"].sum())
        (12, True, 12)
        >>> buffer.discard()
    """

    def __init__(
        self,
        directory: Path,
        features: Mapping[str, Feature],
        task: str,
        seed: int,
        memory_limit: int = DEFAULT_MEMORY_LIMIT,
    ) -> None:
        self.task = task
        self.seed = seed
        self._parent = Path(directory)
        self._features = dict(features)
        self._image_keys = [k for k, f in features.items() if f["dtype"] in ("image", "video")]
        self._memory_limit = memory_limit
        self._memory = 0
        self._chunks: list[tuple[int, dict[str, np.ndarray]]] = []
        self._files: dict[str, BinaryIO] = {}
        self._directory: Path | None = None
        self._length = 0

    def __len__(self) -> int:
        return self._length

    @property
    def spilled(self) -> bool:
        """Whether the image columns live on disk."""
        return self._directory is not None

    def append(self, rows: Mapping[str, np.ndarray]) -> None:
        """Add rows ``key -> [R, *shape]`` (already checked against the features)."""
        incoming = sum(rows[key].nbytes for key in self._features)
        if not self.spilled and self._memory + incoming > self._memory_limit:
            self._spill()
        chunk = {}
        for key in self._features:
            if key in self._files:
                np.ascontiguousarray(rows[key]).tofile(self._files[key])
            else:  # a copy: a view would keep the caller's whole batch alive
                chunk[key] = np.array(rows[key])
        length = len(rows[next(iter(self._features))])
        self._memory += sum(values.nbytes for values in chunk.values())
        self._chunks.append((length, chunk))
        self._length += length

    def _spill(self) -> None:
        """Move the image columns of the rows so far to disk; later ones go straight there."""
        self._directory = Path(tempfile.mkdtemp(prefix="episode-", dir=self._parent))
        for index, key in enumerate(self._image_keys):
            self._files[key] = open(self._directory / f"{index}.raw", "wb")  # noqa: SIM115
            for _, chunk in self._chunks:
                frames = chunk.pop(key)
                frames.tofile(self._files[key])
                self._memory -= frames.nbytes

    def rows(self) -> Iterator[dict[str, np.ndarray]]:
        """The rows in order, ``key -> value`` (spilled images as read-only file views)."""
        images = {key: self._read_spilled(key) for key in self._files}
        index = 0
        for length, chunk in self._chunks:
            for offset in range(length):
                row = {key: values[offset] for key, values in chunk.items()}
                row.update({key: frames[index] for key, frames in images.items()})
                index += 1
                yield row

    def _read_spilled(self, key: str) -> np.ndarray:
        handle = self._files[key]
        handle.flush()
        feature = self._features[key]
        return np.memmap(
            handle.name,
            dtype=numpy_dtype(feature),
            mode="r",
            shape=(self._length, *feature["shape"]),
        )

    def discard(self) -> None:
        """Drop the rows and delete any spill files."""
        for handle in self._files.values():
            handle.close()
        self._files.clear()
        self._chunks.clear()
        if self._directory is not None:
            shutil.rmtree(self._directory, ignore_errors=True)
