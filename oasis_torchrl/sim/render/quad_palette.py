"""Palette indices to packed RGB, three table gathers per 4 pixels."""

from __future__ import annotations

import numpy as np

from oasis_torchrl.sim.render.threads import thread_array


class QuadPalette:
    """Palette lookup straight into packed RGB, without per-frame allocations.

    The 12 bytes of every 4 pixels ``p0..p3`` are three little-endian uint32 words, each a
    function of two neighbouring palette indices: ``(p0, p1)``, ``(p1, p2)``, ``(p2, p3)``. A
    65536-entry table per word turns the conversion into three gathers.

    Example:
        >>> palette = np.arange(768, dtype=np.uint16).reshape(256, 3).astype(np.uint8)
        >>> indices = np.array([0, 1, 2, 3, 255], dtype=np.uint8)
        >>> out = np.empty((5, 3), dtype=np.uint8)
        >>> QuadPalette(palette).convert(indices, out)
        >>> bool(np.array_equal(out, palette[indices]))
        True
    """

    def __init__(self, palette: np.ndarray) -> None:
        self.palette = palette
        channels = palette.astype(np.uint32)
        first, second = np.arange(65536) & 255, np.arange(65536) >> 8
        red, green, blue = channels[:, 0], channels[:, 1], channels[:, 2]
        self.tables = np.stack(
            [
                red[first] | green[first] << 8 | blue[first] << 16 | red[second] << 24,
                green[first] | blue[first] << 8 | red[second] << 16 | green[second] << 24,
                blue[first] | red[second] << 8 | green[second] << 16 | blue[second] << 24,
            ]
        ).astype(np.uint32)

    def convert(self, indices: np.ndarray, out: np.ndarray) -> None:
        """Write the colours of ``indices`` (uint8, contiguous, 1-D) into ``out`` (uint8,
        contiguous, ``indices.size * 3`` bytes)."""
        quads = indices.size // 4
        flat = out.reshape(-1)
        if quads:
            pairs = thread_array("quad_pairs", (3, quads), np.intp)
            words = thread_array("quad_words", (3, quads), np.uint32)
            leading = indices[: 4 * quads].view(np.uint16)
            middle = indices[1 : 4 * quads - 1].view(np.uint16)
            np.copyto(pairs[0], leading[0::2])
            np.copyto(pairs[1], middle[0::2])
            np.copyto(pairs[2], leading[1::2])
            packed = flat[: 12 * quads].view(np.uint32).reshape(quads, 3)
            for word in range(3):
                np.take(self.tables[word], pairs[word], out=words[word], mode="clip")
                np.copyto(packed[:, word], words[word])
        tail = indices[4 * quads :]
        flat[12 * quads :] = self.palette[tail].reshape(-1)
