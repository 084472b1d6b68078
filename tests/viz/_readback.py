"""Reading recordings back with rerun's own readers: ``rerun.experimental.RrdReader`` (rerun-sdk
0.32 and newer, where ``rerun.dataframe`` is gone) or ``rerun.dataframe`` (older releases)."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import rerun as rr
from PIL import Image

try:
    from rerun.experimental import RrdReader
except ImportError:  # rerun-sdk < 0.32
    RrdReader = None


class Readback:
    """One ``.rrd`` recording, queried by entity and component."""

    def __init__(self, path: str | Path) -> None:
        if RrdReader is None:
            self.recording = rr.dataframe.load_recording(str(path))
            self.schema = self.recording.schema()
        else:
            self.store = RrdReader(path).stream().collect()  # also reads files still being written
            self.schema = self.store.schema()

    def entities(self) -> set[str]:
        """Every entity path with data (without the leading ``/``)."""
        return {
            column.entity_path.lstrip("/")
            for column in self.schema.component_columns()
            if not column.entity_path.startswith("/__")
        }

    def timelines(self) -> set[str]:
        return {column.name for column in self.schema.index_columns()}

    def column(self, entity: str, component: str, index: str = "frame") -> tuple[list, list]:
        """``(index values, component values)`` of the rows where ``entity`` logged data, in
        index order (the last value logged at an index wins)."""
        if RrdReader is None:
            name = f"/{entity}:{component}"
            view = self.recording.view(index=index, contents=f"/{entity}")
            pairs = _pairs(view.select(index, name).read_all(), index, name)
        else:
            pairs = [
                pair
                for chunk in self.store.stream()
                if chunk.entity_path == f"/{entity}"
                for pair in _pairs(chunk.to_record_batch(), index, component)
            ]
        kept = dict(sorted((pair for pair in pairs if None not in pair), key=lambda pair: pair[0]))
        return list(kept), list(kept.values())

    def scalars(self, entity: str) -> tuple[list[int], list[float]]:
        frames, values = self.column(entity, "Scalars:scalars")
        return frames, [value[0] for value in values]

    def texts(self, entity: str) -> tuple[list[int], list[str]]:
        frames, values = self.column(entity, "TextLog:text")
        return frames, [value[0] for value in values]

    def images(self, entity: str) -> tuple[list[int], list[np.ndarray]]:
        """Decoded JPEG frames of an ``EncodedImage`` entity."""
        frames, blobs = self.column(entity, "EncodedImage:blob")
        decoded = [np.asarray(Image.open(io.BytesIO(bytes(blob[0])))) for blob in blobs]
        return frames, decoded


def _pairs(table: object, index: str, name: str) -> list[tuple]:
    """``(index, value)`` rows of an arrow table or record batch (none if it lacks a column)."""
    if index not in table.schema.names or name not in table.schema.names:
        return []
    return list(zip(table.column(index).to_pylist(), table.column(name).to_pylist(), strict=True))
