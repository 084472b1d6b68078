"""Decode VP9 packets exactly as the official SDK does."""

from __future__ import annotations

from collections.abc import Iterable

import av
import numpy as np


def sdk_decode(
    packets: Iterable[bytes], decoder: av.CodecContext | None = None
) -> list[np.ndarray]:
    """One persistent ``vp9`` context, one packet at a time, each giving exactly one frame."""
    if decoder is None:
        decoder = av.CodecContext.create("vp9", "r")
        decoder.open()
    decoded = []
    for packet in packets:
        frames = list(decoder.decode(av.Packet(packet)))
        assert len(frames) == 1, f"a packet decoded to {len(frames)} frames"
        decoded.append(frames[-1].to_ndarray(format="rgb24"))
    return decoded
