"""Frames to the page: one binary WebSocket message per frame time, every camera's frame as a
JPEG encoded by Pillow (native code).

Layout of a message: a 4-byte big-endian length ``n``, ``n`` bytes of UTF-8 JSON (``header``
plus ``"sizes"``, the byte length of each JPEG in camera order), then the JPEGs back to back.
"""

from __future__ import annotations

import io
import json
import struct
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from PIL import Image

HEADER_LENGTH = struct.Struct(">I")


def encode_jpeg(frame: np.ndarray, quality: int) -> bytes:
    """One uint8 ``[H, W, 3]`` RGB frame as JPEG bytes.

    Example:
        >>> encode_jpeg(np.zeros((64, 96, 3), np.uint8), 80)[:2]
        b'\\xff\\xd8'
    """
    out = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(frame)).save(out, "JPEG", quality=quality)
    return out.getvalue()


def pack_frames(
    frames: Mapping[str, np.ndarray],
    cameras: Sequence[str],
    header: Mapping[str, Any],
    quality: int,
) -> bytes:
    """The message of one frame time: ``header`` and each camera's JPEG.

    Example:
        >>> frame = np.zeros((64, 96, 3), np.uint8)
        >>> message = pack_frames({"front": frame}, ["front"], {"chunk": 3}, 80)
        >>> header, images = unpack_frames(message)
        >>> header["chunk"], header["cameras"], images[0][:2]
        (3, ['front'], b'\\xff\\xd8')
    """
    images = [encode_jpeg(frames[camera], quality) for camera in cameras]
    meta = {**header, "cameras": list(cameras), "sizes": [len(image) for image in images]}
    encoded = json.dumps(meta).encode()
    return b"".join([HEADER_LENGTH.pack(len(encoded)), encoded, *images])


def unpack_frames(message: bytes) -> tuple[dict[str, Any], list[bytes]]:
    """The header and the JPEGs of a :func:`pack_frames` message (what the page does)."""
    (length,) = HEADER_LENGTH.unpack_from(message)
    start = HEADER_LENGTH.size
    header = json.loads(message[start : start + length])
    images, offset = [], start + length
    for size in header["sizes"]:
        images.append(message[offset : offset + size])
        offset += size
    return header, images
