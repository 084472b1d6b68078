"""Write camera chunks to an H.264 MP4 as a left | front | right strip, streaming.

Frames are appended as they arrive, so memory stays bounded however long the drive is.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from fractions import Fraction
from pathlib import Path

import av
import numpy as np

from oasis_torchrl.closing import Closing


class StripVideoWriter(Closing):
    """Append per-camera frames side by side to an MP4 file.

    Args:
        path: output ``.mp4`` path (parent folders are created).
        cameras: camera names, left to right.
        fps: frame rate of the file.

    Example:
        >>> import numpy as np, tempfile, os
        >>> path = os.path.join(tempfile.mkdtemp(), "drive.mp4")
        >>> frame = np.zeros((64, 96, 3), np.uint8)
        >>> with StripVideoWriter(path, ["left", "front"], fps=20) as video:
        ...     video.write({"left": [frame] * 4, "front": [frame] * 4})
        >>> video.frames_written
        4
    """

    def __init__(self, path: str | Path, cameras: Sequence[str], fps: float = 20.0) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.cameras = tuple(cameras)
        self.fps = fps
        self.frames_written = 0
        self._container = av.open(str(self.path), mode="w")
        self._stream: av.VideoStream | None = None

    def write(self, frames: Mapping[str, Sequence[np.ndarray]]) -> None:
        """Append a chunk: ``frames[camera]`` is a sequence of HWC uint8 frames, same length."""
        counts = {len(frames[camera]) for camera in self.cameras}
        if len(counts) != 1:
            raise ValueError(f"cameras have different frame counts: {counts}")
        for k in range(counts.pop()):
            strip = np.concatenate([frames[camera][k] for camera in self.cameras], axis=1)
            self._encode(strip)

    def _encode(self, strip: np.ndarray) -> None:
        if self._stream is None:
            self._stream = self._open_stream(strip.shape[1], strip.shape[0])
        frame = av.VideoFrame.from_ndarray(strip, format="rgb24")
        for packet in self._stream.encode(frame):
            self._container.mux(packet)
        self.frames_written += 1

    def _open_stream(self, width: int, height: int) -> av.VideoStream:
        stream = self._container.add_stream("libx264", rate=Fraction(self.fps).limit_denominator())
        stream.width, stream.height = width - width % 2, height - height % 2
        stream.pix_fmt = "yuv420p"
        stream.options = {"crf": "23", "preset": "veryfast"}
        return stream

    def close(self) -> None:
        """Flush the encoder and close the file (safe to call twice)."""
        if self._container is None:
            return
        try:
            if self._stream is not None:
                for packet in self._stream.encode(None):
                    self._container.mux(packet)
        finally:
            self._container.close()
            self._container = None
