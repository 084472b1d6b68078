"""Random-shift augmentation (DrQ style): each sample's frames moved by a few pixels.

One function serves both layouts the project trains on: behaviour cloning's batches
(``[B, T, 3, H, W]``, floats or the BC cache's bytes) and PPO's TensorDicts
(``("frame_stack", <camera>)`` ``[B, depth, H, W, 3]`` bytes, the auxiliary fits' minibatches).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F


def random_shift(images: torch.Tensor, pad: int, channels_last: bool = False) -> torch.Tensor:
    """Shift each sample's frames by up to ``pad`` pixels, all frames of a sample alike
    (replicate padding). ``images`` is ``[B, ..., H, W]``, or ``[B, ..., H, W, C]`` with
    ``channels_last``; uint8 or float, returned in the same layout and dtype.

    Example:
        >>> random_shift(torch.rand(2, 2, 3, 8, 12), pad=2).shape
        torch.Size([2, 2, 3, 8, 12])
        >>> random_shift(torch.zeros(2, 2, 8, 12, 3, dtype=torch.uint8), 2, True).shape
        torch.Size([2, 2, 8, 12, 3])
    """
    if pad <= 0:
        return images
    if channels_last:
        return random_shift(images.movedim(-1, -3), pad).movedim(-3, -1)
    height, width = images.shape[-2:]
    flat = images.reshape(images.shape[0], -1, height, width)
    padded = F.pad(flat, (pad, pad, pad, pad), mode="replicate")
    offsets = torch.randint(0, 2 * pad + 1, (images.shape[0], 2)).tolist()
    # One slice copy per sample is several times faster than a gather over every pixel.
    shifted = torch.stack(
        [
            sample[:, r : r + height, c : c + width]
            for sample, (r, c) in zip(padded, offsets, strict=True)
        ]
    )
    return shifted.reshape(images.shape)
