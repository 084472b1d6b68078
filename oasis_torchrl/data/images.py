"""Frame resizing shared by the exporter and the importer (vectorised, uint8 in and out)."""

from __future__ import annotations

import torch
import torch.nn.functional as F


def resize_frames(frames: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """Resize uint8 HWC frames ``[..., H, W, 3]`` to ``size = (height, width)``.

    Antialiased bilinear filtering (a fair downscale); returns ``frames`` itself when the size
    already matches, so full-resolution recording costs no copy here.

    Example:
        >>> frames = torch.zeros(2, 5, 64, 96, 3, dtype=torch.uint8)
        >>> resize_frames(frames, (32, 48)).shape
        torch.Size([2, 5, 32, 48, 3])
    """
    if tuple(frames.shape[-3:-1]) == tuple(size):
        return frames
    if frames.dtype != torch.uint8 or frames.shape[-1] != 3:
        raise TypeError(
            f"frames must be uint8 [..., H, W, 3], got {frames.dtype} {tuple(frames.shape)}"
        )
    lead = frames.shape[:-3]
    flat = frames.reshape(-1, *frames.shape[-3:]).permute(0, 3, 1, 2)
    resized = F.interpolate(flat, size=tuple(size), mode="bilinear", antialias=True)
    return resized.permute(0, 2, 3, 1).contiguous().reshape(*lead, *size, 3)
