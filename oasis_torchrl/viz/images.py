"""Camera frames and depth maps as rerun archetypes (JPEG by default, to keep recordings small).

Frames are logged at the size the env serves them: the viewer scales an image to its panel, so
more pixels in the file would add size, not detail.
"""

from __future__ import annotations

import io

import numpy as np
import rerun as rr
from PIL import Image

DEFAULT_JPEG_QUALITY = 70
"""JPEG quality of logged frames (Huffman tables optimized per frame)."""
JPEG_MEDIA_TYPE = "image/jpeg"


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
    Image.fromarray(frame).save(buffer, format="JPEG", quality=quality, optimize=True)
    return buffer.getvalue()


def image_archetype(frame: np.ndarray, jpeg_quality: int | None) -> rr.EncodedImage | rr.Image:
    """A JPEG ``EncodedImage`` (``jpeg_quality`` 1-100) of the frame or, with None, a raw
    ``Image`` (rerun's encoded image: the same on every supported rerun-sdk).

    Example:
        >>> type(image_archetype(np.zeros((8, 8, 3), np.uint8), 85)).__name__
        'EncodedImage'
    """
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
