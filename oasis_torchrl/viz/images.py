"""Camera frames and depth maps as rerun archetypes (JPEG by default, to keep recordings small)."""

from __future__ import annotations

import io

import numpy as np
import rerun as rr
from PIL import Image

DEFAULT_JPEG_QUALITY = 85
JPEG_MEDIA_TYPE = "image/jpeg"
DEFAULT_DISPLAY_WIDTH = 384
"""Frames narrower than this are upscaled for display (a policy's 96x64 becomes 384x256)."""


def check_frame(frame: np.ndarray, name: str) -> np.ndarray:
    """``frame`` if it is uint8 ``[H, W, 3]``, else a TypeError/ValueError naming ``name``.

    Example:
        >>> check_frame(np.zeros((2, 2), np.uint8), "front")
        Traceback (most recent call last):
        ...
        ValueError: front: expected a uint8 [H, W, 3] RGB frame, got shape (2, 2)
    """
    if frame.dtype != np.uint8:
        raise TypeError(f"{name}: expected a uint8 [H, W, 3] RGB frame, got dtype {frame.dtype}")
    if frame.ndim != 3 or frame.shape[-1] != 3:
        raise ValueError(f"{name}: expected a uint8 [H, W, 3] RGB frame, got shape {frame.shape}")
    return frame


def encode_jpeg(frame: np.ndarray, quality: int) -> bytes:
    """JPEG bytes of a uint8 RGB ``[H, W, 3]`` frame (Pillow releases the GIL while encoding).

    Example:
        >>> encode_jpeg(np.zeros((8, 8, 3), np.uint8), 85)[:2]
        b'\\xff\\xd8'
    """
    buffer = io.BytesIO()
    Image.fromarray(frame).save(buffer, format="JPEG", quality=quality)
    return buffer.getvalue()


def display_size(frame: np.ndarray, min_width: int | None) -> np.ndarray:
    """``frame`` upscaled by the smallest whole factor that makes it at least ``min_width``
    pixels wide (bilinear), for display only; as it is when wide enough or ``min_width`` is None.

    Example:
        >>> display_size(np.zeros((64, 96, 3), np.uint8), 384).shape
        (256, 384, 3)
        >>> display_size(np.zeros((512, 768, 3), np.uint8), 384).shape
        (512, 768, 3)
    """
    width = frame.shape[1]
    if min_width is None or width >= min_width:
        return frame
    factor = -(-min_width // width)
    size = (width * factor, frame.shape[0] * factor)
    return np.asarray(Image.fromarray(frame).resize(size, Image.Resampling.BILINEAR))


def image_archetype(
    frame: np.ndarray, jpeg_quality: int | None, min_width: int | None = None
) -> rr.EncodedImage | rr.Image:
    """A JPEG ``EncodedImage`` (``jpeg_quality`` 1-100) or, with None, a raw ``Image``, of the
    frame upscaled to at least ``min_width`` pixels wide (:func:`display_size`).

    Example:
        >>> type(image_archetype(np.zeros((8, 8, 3), np.uint8), 85)).__name__
        'EncodedImage'
    """
    frame = display_size(frame, min_width)
    if jpeg_quality is None:
        return rr.Image(frame)
    return rr.EncodedImage(contents=encode_jpeg(frame, jpeg_quality), media_type=JPEG_MEDIA_TYPE)


def depth_archetype(depth: np.ndarray) -> rr.DepthImage:
    """A metric ``DepthImage`` (metres, float16: half the size, millimetres up close); sky
    (+inf) and unknown (NaN) become 0, rerun's "no depth".

    Example:
        >>> image = depth_archetype(np.array([[1.0, np.inf]], np.float32))
        >>> type(image).__name__
        'DepthImage'
    """
    finite = np.where(np.isfinite(depth), depth, 0.0).astype(np.float16)
    return rr.DepthImage(finite, meter=1.0)
