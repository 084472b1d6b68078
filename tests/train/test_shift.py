"""Random-shift augmentation on both layouts: BC's channels-first batches and PPO's bytes."""

from __future__ import annotations

import torch

from oasis_torchrl.train.shift import random_shift


def _bright_pixel_positions(frames: torch.Tensor) -> torch.Tensor:
    """Where the one bright pixel of each ``[B, H, W]`` frame landed, as row * 9 + column."""
    return frames.flatten(1).argmax(1)


def _assert_within_pad(positions: torch.Tensor, pad: int) -> None:
    rows, cols = positions // 9, positions % 9
    assert rows.min() >= 4 - pad and rows.max() <= 4 + pad
    assert cols.min() >= 4 - pad and cols.max() <= 4 + pad
    assert len(set(positions.tolist())) > 5  # the shifts differ between samples


def test_random_shift_moves_content_within_the_pad() -> None:
    image = torch.zeros(64, 2, 1, 9, 9)
    image[..., 4, 4] = 1.0
    shifted = random_shift(image, pad=2)
    torch.testing.assert_close(shifted[:, 0], shifted[:, 1])  # both frames alike
    _assert_within_pad(_bright_pixel_positions(shifted[:, 0, 0]), pad=2)


def test_channels_last_bytes_shift_every_channel_and_frame_alike() -> None:
    frames = torch.zeros(64, 2, 9, 9, 3, dtype=torch.uint8)
    frames[:, :, 4, 4, :] = 255
    shifted = random_shift(frames, pad=2, channels_last=True)
    assert shifted.dtype == torch.uint8 and shifted.shape == frames.shape
    assert torch.equal(shifted[:, 0], shifted[:, 1])
    assert torch.equal(shifted[..., 0], shifted[..., 2])  # channels move together
    _assert_within_pad(_bright_pixel_positions(shifted[:, 0, ..., 0]), pad=2)


def test_no_pad_returns_the_frames_unchanged() -> None:
    frames = torch.rand(2, 2, 3, 8, 12)
    assert random_shift(frames, pad=0) is frames
