"""Reading recordings back with rerun's own reader (``rerun.dataframe``)."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import rerun as rr
from PIL import Image


class Readback:
    """One ``.rrd`` recording, queried by entity and component."""

    def __init__(self, path: str | Path) -> None:
        self.recording = rr.dataframe.load_recording(str(path))

    def entities(self) -> set[str]:
        """Every entity path with data (without the leading ``/``)."""
        return {
            column.entity_path.lstrip("/")
            for column in self.recording.schema().component_columns()
            if not column.entity_path.startswith("/__")
        }

    def timelines(self) -> set[str]:
        return {column.name for column in self.recording.schema().index_columns()}

    def column(self, entity: str, component: str, index: str = "frame") -> tuple[list, list]:
        """``(index values, component values)`` of the rows where ``entity`` logged data."""
        name = f"/{entity}:{component}"
        view = self.recording.view(index=index, contents=f"/{entity}")
        table = view.select(index, name).read_all()
        index_values, values = table.column(index).to_pylist(), table.column(name).to_pylist()
        kept = [(i, v) for i, v in zip(index_values, values, strict=True) if v is not None]
        return [i for i, _ in kept], [v for _, v in kept]

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
