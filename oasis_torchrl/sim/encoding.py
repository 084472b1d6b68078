"""Frame encoders of the embedded A2V server: one stateful encoder per camera stream.

The A2V wire format carries one compressed packet per frame. The official SDK decodes every
packet on its own (``av.CodecContext.create("vp9", "r")``) and keeps the last decoded frame, so
each input frame must yield exactly one packet, immediately: the VP9 encoder runs libvpx in
realtime mode with no look-ahead and no alternate reference frames (no superframes, no hidden
frames), and the first frame after :meth:`FrameEncoder.restart` is a key frame.
"""

from __future__ import annotations

import io
import logging
from fractions import Fraction
from typing import Protocol

import av
import numpy as np
from PIL import Image

from oasis_torchrl.proto import common_pb2
from oasis_torchrl.protocol import FrameFormat

logger = logging.getLogger(__name__)

#: Formats the embedded server can produce (a client's order of preference decides).
SUPPORTED_FORMATS: tuple[int, ...] = (FrameFormat.RAW_RGB24, FrameFormat.VP9, FrameFormat.JPEG)

# libvpx treats the GOP length as the maximum key-frame distance; key frames are only wanted
# after a restart, so the distance is effectively unbounded.
_NO_PERIODIC_KEY_FRAMES = 1 << 30
# Default VP9 budget in bits per pixel per frame: keeps 768x512 at 20 fps near 2 Mbit/s.
_VP9_BITS_PER_PIXEL = 0.25


class FrameEncoder(Protocol):
    """A stateful encoder turning RGB frames of one stream into wire packets.

    Example:
        >>> import numpy as np
        >>> encoder: FrameEncoder = JpegEncoder()
        >>> isinstance(encoder.encode(np.zeros((16, 16, 3), np.uint8)), bytes)
        True
    """

    #: Whether encoding is slow enough to run on a thread per stream (it releases the GIL).
    threaded: bool

    def encode(self, rgb: np.ndarray) -> bytes:
        """Encode one uint8 RGB frame ``[H, W, 3]`` into exactly one packet."""
        ...

    def restart(self) -> None:
        """Start a new clip: the next encoded frame decodes on its own (a key frame)."""
        ...


def _check_frame(rgb: np.ndarray, shape: tuple[int, int, int] | None = None) -> None:
    """Raise a clear error unless ``rgb`` is a uint8 ``[H, W, 3]`` array (of ``shape`` if given)."""
    if not isinstance(rgb, np.ndarray) or rgb.dtype != np.uint8:
        kind = getattr(rgb, "dtype", type(rgb).__name__)
        raise TypeError(f"rgb must be a uint8 numpy array, got {kind}")
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"rgb must have shape [H, W, 3], got {rgb.shape}")
    if shape is not None and rgb.shape != shape:
        raise ValueError(f"rgb must have shape {shape}, got {rgb.shape}")


class Vp9Encoder:
    """VP9 (libvpx) realtime encoder emitting exactly one self-contained packet per frame.

    Args:
        width: Frame width in pixels.
        height: Frame height in pixels.
        fps: Frame rate, used for the time base and rate control.
        cpu_used: libvpx speed/quality trade-off, 0 (slow, best) to 8 (fastest).
        bit_rate: Target bits per second; ``None`` scales with the frame size.
        threads: libvpx worker threads for this one stream.

    Example:
        >>> import numpy as np
        >>> encoder = Vp9Encoder(64, 48, 20.0)
        >>> packets = [encoder.encode(np.zeros((48, 64, 3), np.uint8)) for _ in range(3)]
        >>> len(packets), Vp9Encoder.is_key_frame(packets[0]), Vp9Encoder.is_key_frame(packets[1])
        (3, True, False)
    """

    threaded = True

    def __init__(
        self,
        width: int,
        height: int,
        fps: float,
        *,
        cpu_used: int = 8,
        bit_rate: int | None = None,
        threads: int = 1,
    ) -> None:
        self.width = width
        self.height = height
        self.fps = fps
        self.cpu_used = cpu_used
        self.bit_rate = bit_rate or int(width * height * fps * _VP9_BITS_PER_PIXEL)
        self.threads = threads
        self._codec: av.video.codeccontext.VideoCodecContext | None = None
        self._pts = 0

    def restart(self) -> None:
        """Drop the codec state; the next frame opens a fresh context and is a key frame."""
        self._codec = None

    def encode(self, rgb: np.ndarray) -> bytes:
        """Encode one ``[height, width, 3]`` uint8 RGB frame into one VP9 packet."""
        _check_frame(rgb, (self.height, self.width, 3))
        if self._codec is None:
            self._codec = self._open_codec()
            self._pts = 0
        frame = av.VideoFrame.from_ndarray(rgb, format="rgb24")
        frame.pts = self._pts
        self._pts += 1
        packets = self._codec.encode(frame)
        if len(packets) != 1:
            raise RuntimeError(f"libvpx-vp9 returned {len(packets)} packets for one frame, not 1")
        return bytes(packets[0])

    @staticmethod
    def is_key_frame(packet: bytes) -> bool:
        """Whether a VP9 packet (profile 0, as produced here) is a key frame.

        Reads the uncompressed header: frame marker (2 bits), profile (2 bits),
        show_existing_frame (1 bit), then frame_type (0 = key frame).

        Example:
            >>> Vp9Encoder.is_key_frame(bytes([0x82])), Vp9Encoder.is_key_frame(bytes([0x86]))
            (True, False)
        """
        return len(packet) > 0 and (packet[0] & 0b1100_1100) == 0b1000_0000

    def _open_codec(self) -> av.video.codeccontext.VideoCodecContext:
        """Open a libvpx-vp9 context configured for one packet per frame, no look-ahead."""
        codec = av.CodecContext.create("libvpx-vp9", "w")
        codec.width = self.width
        codec.height = self.height
        codec.pix_fmt = "yuv420p"
        rate = Fraction(self.fps).limit_denominator(1000)
        codec.time_base = 1 / rate
        codec.framerate = rate
        codec.bit_rate = self.bit_rate
        codec.thread_count = self.threads
        codec.gop_size = _NO_PERIODIC_KEY_FRAMES
        codec.options = {
            "deadline": "realtime",
            "cpu-used": str(self.cpu_used),
            "lag-in-frames": "0",
            "auto-alt-ref": "0",
            "error-resilient": "1",
            "row-mt": "1",
        }
        codec.open()
        return codec


class JpegEncoder:
    """Baseline JPEG encoder (Pillow: faster than PyAV's mjpeg).

    Every frame is independent, so :meth:`restart` has nothing to reset.

    Example:
        >>> import numpy as np
        >>> JpegEncoder(quality=80).encode(np.zeros((8, 8, 3), np.uint8))[:2]
        b'\\xff\\xd8'
    """

    threaded = True

    def __init__(self, quality: int = 90) -> None:
        self.quality = quality

    def restart(self) -> None:
        """No state to reset: every JPEG frame decodes on its own."""

    def encode(self, rgb: np.ndarray) -> bytes:
        """Encode one uint8 RGB frame ``[H, W, 3]`` into one JPEG image."""
        _check_frame(rgb)
        buffer = io.BytesIO()
        Image.fromarray(rgb, mode="RGB").save(buffer, format="JPEG", quality=self.quality)
        return buffer.getvalue()


class RawRgbEncoder:
    """Frames as they are: 3 bytes a pixel, row-major (``FrameFormat.RAW_RGB24``).

    Example:
        >>> len(RawRgbEncoder().encode(np.zeros((48, 64, 3), np.uint8)))
        9216
    """

    threaded = False  # a copy: faster than handing it to a thread

    def restart(self) -> None:
        """No state to reset: every raw frame stands on its own."""

    def encode(self, rgb: np.ndarray) -> bytes:
        """The frame's bytes."""
        _check_frame(rgb)
        return rgb.tobytes()


def format_name(frame_format: int) -> str:
    """Human-readable name of a ``FrameFormat`` value, tolerant of unknown numbers.

    Example:
        >>> format_name(3), format_name(42)
        ('FRAME_FORMAT_VP9', 'FrameFormat(42)')
    """
    try:
        return f"FRAME_FORMAT_{FrameFormat(frame_format).name}"
    except ValueError:
        return f"FrameFormat({frame_format})"


def make_encoder(
    frame_format: int,
    width: int,
    height: int,
    fps: float,
    *,
    vp9_cpu_used: int = 8,
    vp9_bit_rate: int | None = None,
    vp9_threads: int = 1,
    jpeg_quality: int = 90,
) -> FrameEncoder:
    """Create the encoder for one stream in ``frame_format`` (a ``common_pb2.FRAME_FORMAT_*``).

    Example:
        >>> from oasis_torchrl.proto import common_pb2
        >>> type(make_encoder(common_pb2.FRAME_FORMAT_VP9, 64, 48, 20.0)).__name__
        'Vp9Encoder'
    """
    if frame_format == common_pb2.FRAME_FORMAT_VP9:
        return Vp9Encoder(
            width, height, fps, cpu_used=vp9_cpu_used, bit_rate=vp9_bit_rate, threads=vp9_threads
        )
    if frame_format == common_pb2.FRAME_FORMAT_JPEG:
        return JpegEncoder(quality=jpeg_quality)
    if frame_format == FrameFormat.RAW_RGB24:
        return RawRgbEncoder()
    supported = ", ".join(format_name(f) for f in SUPPORTED_FORMATS)
    raise ValueError(
        f"frame_format {format_name(frame_format)} is not supported; expected one of {supported}"
    )
