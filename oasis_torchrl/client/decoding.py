"""Per-stream frame decoders (VP9, JPEG, raw RGB) that write RGB straight into caller-owned arrays.

A decoder turns one packet into one ``uint8`` RGB ``[H, W, 3]`` image written into ``out`` at
``out``'s size, so a resize happens during decoding, with no separate pass or full-size copy:

- VP9: PyAV decodes the packet, then one libswscale pass converts YUV to RGB *and* scales it
  (``VideoReformatter``, reused per decoder so its context is built once). At the native size
  this is swscale's unscaled SIMD path and the pixels are exactly what
  ``frame.to_ndarray(format="rgb24")`` gives. Scaling leaves that path for swscale's generic
  filter chain, which costs more than the unscaled conversion (shrinking the YUV planes first is
  cheaper but halves the chroma resolution); decoding dominates either way, so resizing buys
  smaller arrays rather than speed (numbers: benchmarks/decode_speed.py). The
  only copy is from swscale's output frame into ``out``: PyAV cannot write into a caller buffer.
- JPEG: PIL's ``draft`` makes libjpeg decode at 1/2, 1/4 or 1/8 scale (DCT scaling, far cheaper
  than a full decode), then a bilinear resize covers any remaining ratio.

VP9 is a stateful stream: each stream needs its own decoder fed in order, and :meth:`reset` when
a new clip (Prompt) starts. PyAV releases the GIL while decoding and converting, so decoders of
different streams run in parallel on a thread pool.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from typing import Protocol

import av
import numpy as np
from av.video.reformatter import Interpolation, VideoReformatter
from PIL import Image

from oasis_torchrl.client.errors import DecodeError
from oasis_torchrl.client.types import FrameFormat

# AREA averages every source pixel of a destination pixel: no aliasing when shrinking, and
# faster than swscale's BILINEAR for large ratios.
RESIZE_INTERPOLATION = Interpolation.AREA


class FrameDecoder(Protocol):
    """Decodes one stream's packets in order into caller-provided RGB arrays."""

    stream: str
    #: Whether decoding is slow enough to run on a thread (it releases the GIL).
    threaded: bool

    def decode_into(self, packet: bytes, out: np.ndarray) -> None:
        """Decode ``packet`` into ``out`` (uint8 ``[H, W, 3]``), scaling to ``out``'s size."""
        ...

    def decode_full(self, packet: bytes) -> np.ndarray:
        """Decode ``packet`` to a uint8 ``[H, W, 3]`` image at the stream's own size."""
        ...

    def skip(self, packet: bytes) -> None:
        """Consume ``packet`` to keep the stream in sync, without producing RGB."""
        ...

    def reset(self) -> None:
        """Forget the stream's state: the next packet starts a new clip."""
        ...


class Vp9Decoder:
    """Stateful VP9 decoder for one stream.

    ``threads`` is libavcodec's thread count (0: automatic); a pool that decodes many streams in
    parallel passes 1 so decoders do not fight over cores.

    >>> import numpy as np
    >>> decoder = Vp9Decoder("front")
    >>> decoder.decode_into(b"not vp9", np.empty((64, 96, 3), np.uint8))
    Traceback (most recent call last):
    ...
    oasis_torchrl.client.errors.DecodeError: cannot decode stream 'front': ...
    """

    threaded = True

    def __init__(self, stream: str, *, threads: int = 0) -> None:
        self.stream = stream
        self._threads = threads
        self._reformatter = VideoReformatter()
        self._context = self._open()

    def reset(self) -> None:
        """Start a new clip: the next packet must be a key frame."""
        self._context = self._open()

    def decode_into(self, packet: bytes, out: np.ndarray) -> None:
        """Decode one VP9 packet into ``out``, converting (and scaling) in one swscale pass."""
        frame = self._decode(packet)
        height, width = out.shape[:2]
        scaled = (frame.height, frame.width) != (height, width)
        rgb = self._reformatter.reformat(
            frame,
            width=width,
            height=height,
            format="rgb24",
            interpolation=RESIZE_INTERPOLATION if scaled else None,
        )
        np.copyto(out, rgb.to_ndarray())

    def decode_full(self, packet: bytes) -> np.ndarray:
        """Decode one VP9 packet to RGB at the stream's size."""
        frame = self._decode(packet)
        return self._reformatter.reformat(frame, format="rgb24").to_ndarray()

    def skip(self, packet: bytes) -> None:
        """Decode ``packet`` (the stream state advances) but skip the RGB conversion."""
        self._decode(packet)

    def _decode(self, packet: bytes) -> av.VideoFrame:
        try:
            frames = self._context.decode(av.Packet(packet))
        except av.error.FFmpegError as error:
            raise DecodeError(self.stream, f"VP9 decoder rejected a packet: {error}") from error
        if not frames:
            raise DecodeError(
                self.stream, "VP9 packet produced no frame (lost packet or missing key frame)"
            )
        return frames[-1]

    def _open(self) -> av.CodecContext:
        context = av.CodecContext.create("vp9", "r")
        context.thread_count = self._threads
        context.open()
        return context


class JpegDecoder:
    """Stateless JPEG decoder for one stream; shrinks with libjpeg's DCT scaling when asked.

    >>> import io, numpy as np
    >>> from PIL import Image
    >>> buffer = io.BytesIO()
    >>> Image.new("RGB", (96, 64), (200, 10, 10)).save(buffer, format="JPEG")
    >>> out = np.empty((32, 48, 3), np.uint8)
    >>> JpegDecoder("front").decode_into(buffer.getvalue(), out)
    >>> bool(abs(int(out[..., 0].mean()) - 200) < 8)
    True
    """

    threaded = True

    def __init__(self, stream: str) -> None:
        self.stream = stream

    def reset(self) -> None:
        """JPEG frames are independent: nothing to reset."""

    def skip(self, packet: bytes) -> None:
        """JPEG frames are independent: a skipped frame needs no decoding."""

    def decode_into(self, packet: bytes, out: np.ndarray) -> None:
        """Decode one JPEG image into ``out``, scaled to ``out``'s size."""
        height, width = out.shape[:2]
        try:
            with Image.open(io.BytesIO(packet)) as image:
                if image.size != (width, height):
                    image.draft("RGB", (width, height))
                rgb = image if image.mode == "RGB" else image.convert("RGB")
                if rgb.size != (width, height):
                    rgb = rgb.resize((width, height), Image.Resampling.BILINEAR)
                np.copyto(out, np.asarray(rgb))
        except (OSError, ValueError) as error:
            raise DecodeError(self.stream, f"invalid JPEG image: {error}") from error

    def decode_full(self, packet: bytes) -> np.ndarray:
        """Decode one JPEG image at its own size."""
        try:
            with Image.open(io.BytesIO(packet)) as image:
                return np.asarray(image.convert("RGB"))
        except (OSError, ValueError) as error:
            raise DecodeError(self.stream, f"invalid JPEG image: {error}") from error


class RawRgbDecoder:
    """Uncompressed RGB frames (``FrameFormat.RAW_RGB24``) of one stream of a known size: one
    copy into ``out``, or one swscale pass when ``out`` is another size.

    >>> import numpy as np
    >>> out = np.empty((2, 3, 3), np.uint8)
    >>> RawRgbDecoder("front", (2, 3)).decode_into(bytes(range(18)), out)
    >>> out[1, 2].tolist()
    [15, 16, 17]
    """

    threaded = False  # a copy: faster than a hop to a thread

    def __init__(self, stream: str, size: tuple[int, int]) -> None:
        self.stream = stream
        self.size = size
        self._resizer = RgbResizer()

    def reset(self) -> None:
        """Raw frames are independent: nothing to reset."""

    def skip(self, packet: bytes) -> None:
        """Raw frames are independent: a skipped frame needs no work."""

    def decode_into(self, packet: bytes, out: np.ndarray) -> None:
        """Copy (or scale) one frame into ``out``."""
        self._resizer.resize_into(self.decode_full(packet), out)

    def decode_full(self, packet: bytes) -> np.ndarray:
        """The frame itself, as an array over ``packet`` (no copy)."""
        height, width = self.size
        if len(packet) != height * width * 3:
            raise DecodeError(
                self.stream,
                f"raw RGB frame of {len(packet)} bytes, expected {height}x{width}x3",
            )
        return np.frombuffer(packet, np.uint8).reshape(height, width, 3)


class RgbResizer:
    """Resizes RGB images into caller-owned arrays: a copy at the same size, else one swscale
    pass (:data:`RESIZE_INTERPOLATION`); its swscale context is kept between calls, so give
    each output size a resizer of its own.

    >>> import numpy as np
    >>> out = np.empty((2, 2, 3), np.uint8)
    >>> RgbResizer().resize_into(np.full((4, 4, 3), 7, np.uint8), out)
    >>> out.min(), out.max()
    (np.uint8(7), np.uint8(7))
    """

    def __init__(self) -> None:
        self._reformatter = VideoReformatter()

    def resize_into(self, rgb: np.ndarray, out: np.ndarray) -> None:
        """Write ``rgb`` (uint8 ``[h, w, 3]``, any strides) into ``out`` at ``out``'s size."""
        if rgb.shape == out.shape:
            np.copyto(out, rgb)
            return
        scaled = self._reformatter.reformat(
            av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb), format="rgb24"),
            width=out.shape[1],
            height=out.shape[0],
            format="rgb24",
            interpolation=RESIZE_INTERPOLATION,
        )
        np.copyto(out, scaled.to_ndarray())


class FrontCrop:
    """A narrow forward camera cut from a wide one: the centre ``fraction`` of a frame's height
    and width. One frame is decoded once at full size, then resized into the wide camera's
    output and, cropped, into the narrow one's (in swscale, no per-pixel Python).

    Keeps swscale contexts: one per stream decoder (a session's ``front``).

    >>> FrontCrop(0.25).box(512, 768)
    (192, 288, 128, 192)
    >>> FrontCrop(0)
    Traceback (most recent call last):
    ...
    ValueError: front_crop must be a fraction in (0, 1], got 0
    """

    def __init__(self, fraction: float) -> None:
        self.fraction = validate_front_crop(fraction)
        self._wide = RgbResizer()
        self._narrow = RgbResizer()

    def box(self, height: int, width: int) -> tuple[int, int, int, int]:
        """``(top, left, height, width)`` of the centre crop of a ``height x width`` frame."""
        crop_h = max(1, round(height * self.fraction))
        crop_w = max(1, round(width * self.fraction))
        return (height - crop_h) // 2, (width - crop_w) // 2, crop_h, crop_w

    def cut(self, full: np.ndarray) -> np.ndarray:
        """The centre crop of ``full`` (a view, no copy)."""
        top, left, height, width = self.box(*full.shape[:2])
        return full[top : top + height, left : left + width]

    def decode_into(
        self, decoder: FrameDecoder, packet: bytes, wide: np.ndarray, narrow: np.ndarray
    ) -> None:
        """Decode ``packet`` once at full size into ``wide`` and its centre into ``narrow``."""
        full = decoder.decode_full(packet)
        self._wide.resize_into(full, wide)
        self._narrow.resize_into(self.cut(full), narrow)


def validate_front_crop(fraction: float | None) -> float | None:
    """Check ``env.front_crop``: None (no crop) or a fraction in ``(0, 1]``.

    >>> validate_front_crop(0.25), validate_front_crop(None)
    (0.25, None)
    """
    if fraction is None:
        return None
    if isinstance(fraction, bool) or not isinstance(fraction, (int, float)):
        raise ValueError(f"front_crop must be a fraction in (0, 1], got {fraction!r}")
    if not 0 < fraction <= 1:
        raise ValueError(f"front_crop must be a fraction in (0, 1], got {fraction!r}")
    return float(fraction)


DECODABLE_FORMATS: tuple[FrameFormat, ...] = (
    FrameFormat.RAW_RGB24,
    FrameFormat.VP9,
    FrameFormat.JPEG,
)


def make_decoder(
    frame_format: int, stream: str, size: tuple[int, int], *, threads: int = 0
) -> FrameDecoder:
    """Create the decoder for ``frame_format`` for one stream of ``(height, width)`` pixels.

    >>> type(make_decoder(FrameFormat.JPEG, "front", (64, 96))).__name__
    'JpegDecoder'
    """
    if frame_format == FrameFormat.VP9:
        return Vp9Decoder(stream, threads=threads)
    if frame_format == FrameFormat.JPEG:
        return JpegDecoder(stream)
    if frame_format == FrameFormat.RAW_RGB24:
        return RawRgbDecoder(stream, size)
    raise ValueError(
        f"frame_format must be one of {[f.name for f in DECODABLE_FORMATS]}, got {frame_format!r}"
    )


def decode_chunk(
    decoder: FrameDecoder,
    packets: Sequence[bytes],
    out: np.ndarray,
    chunk: int | None = None,
    crop: tuple[FrontCrop, np.ndarray] | None = None,
) -> None:
    """Decode a chunk of ``chunk`` packets in order; ``out`` (uint8 ``[k, H, W, 3]``) receives
    its last ``k`` frames. Earlier frames are still decoded, keeping a stateful stream in sync,
    but never converted to RGB (the conversion is most of the cost). With ``crop`` (a
    :class:`FrontCrop` and its ``[k, h, w, 3]`` output) each kept frame is decoded at full size
    once and its centre crop written beside it.

    >>> import numpy as np
    >>> decode_chunk(JpegDecoder("front"), [], np.empty((1, 8, 8, 3), np.uint8), chunk=4)
    Traceback (most recent call last):
    ...
    oasis_torchrl.client.errors.DecodeError: cannot decode stream 'front': expected 4 frames, got 0
    """
    expected = len(out) if chunk is None else chunk
    if len(packets) != expected or len(out) > expected:
        raise DecodeError(decoder.stream, f"expected {expected} frames, got {len(packets)}")
    skipped = len(packets) - len(out)
    for packet in packets[:skipped]:
        decoder.skip(packet)
    if crop is None:
        for packet, slot in zip(packets[skipped:], out, strict=True):
            decoder.decode_into(packet, slot)
        return
    front_crop, narrow = crop
    for packet, slot, narrow_slot in zip(packets[skipped:], out, narrow, strict=True):
        front_crop.decode_into(decoder, packet, slot, narrow_slot)


def validate_resize(resize: tuple[int, int] | None) -> tuple[int, int] | None:
    """Check a decode-time ``resize``: None or ``(height, width)`` positive ints.

    >>> validate_resize((128, 192))
    (128, 192)
    >>> validate_resize((128,))
    Traceback (most recent call last):
    ...
    ValueError: resize must be None or (height, width) positive ints, got (128,)
    """
    if resize is None:
        return None
    values = tuple(resize)
    if len(values) != 2 or not all(_is_positive_int(v) for v in values):
        raise ValueError(f"resize must be None or (height, width) positive ints, got {resize!r}")
    return int(values[0]), int(values[1])


def _is_positive_int(value: object) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value > 0
