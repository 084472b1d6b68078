"""Reading recordings back with rerun's own readers: ``rerun.experimental.RrdReader`` (rerun-sdk
0.32 and newer, where ``rerun.dataframe`` is gone) or ``rerun.dataframe`` (older releases)."""

from __future__ import annotations

import io
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import rerun as rr
from PIL import Image

try:
    from rerun.experimental import RrdReader
except ImportError:  # rerun-sdk < 0.32
    RrdReader = None


def printed(path: Path) -> str:
    """The file's every chunk, printed by the rerun CLI."""
    return subprocess.run(
        [sys.executable, "-m", "rerun", "rrd", "print", "-vvv", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    ).stdout


def blueprint_views(path: Path) -> set[tuple[str, str, str]]:
    """(view class, name, origin) of every view in the file's blueprint, via the rerun CLI."""
    kinds = "2D|TimeSeries|TextLog|BarChart|TextDocument"
    pattern = rf"\[({kinds})\]\s+┆\s+\[([^\]]*)\]\s+┆\s+\[([^\]]*)\]"
    return set(re.findall(pattern, printed(path)))


def chunk_paths(path: Path) -> list[str]:
    """The entity path of every chunk in the order the file holds them (blueprint stores'
    included), via the rerun CLI."""
    return re.findall(r"^Chunk\(\S+\) with .*? - (/\S*) - ", printed(path), re.MULTILINE)


def blueprint_count(path: Path) -> int:
    """How many layouts (blueprint stores) the file holds, via the rerun CLI."""
    return len(set(re.findall(r'StoreId\(\s*Blueprint,\s*"[^"]*",\s*"([^"]*)"', printed(path))))


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

    def frames(self, prefix: str) -> list[int]:
        """Every ``frame`` at which anything under entity ``prefix`` was logged, sorted."""
        if RrdReader is None:
            view = self.recording.view(index="frame", contents=f"/{prefix}/**")
            values = view.select("frame").read_all().column("frame").to_pylist()
        else:
            values = [
                value
                for chunk in self.store.stream()
                if chunk.entity_path.startswith(f"/{prefix}/")
                and "frame" in (batch := chunk.to_record_batch()).schema.names
                for value in batch.column("frame").to_pylist()
            ]
        return sorted({value for value in values if value is not None})

    def static(self, entity: str, component: str) -> list:
        """The value of a component logged statically at ``entity`` (the last one logged)."""
        if RrdReader is None:
            name = f"/{entity}:{component}"
            view = self.recording.view(index="frame", contents=f"/{entity}")
            values = view.select(name).read_all().column(name).to_pylist()
        else:
            values = [
                value
                for chunk in self.store.stream()
                if chunk.entity_path == f"/{entity}"
                and "frame" not in (batch := chunk.to_record_batch()).schema.names
                and component in batch.schema.names
                for value in batch.column(component).to_pylist()
            ]
        found = [value for value in values if value is not None]
        if not found:
            raise KeyError(f"no static {component} at {entity}")
        return found[-1]

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
