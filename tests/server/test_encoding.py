"""Frame encoders: one packet per frame, key frames on restart, decodable the SDK's way."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from oasis_torchrl.proto import common_pb2
from oasis_torchrl.protocol import FrameFormat
from oasis_torchrl.sim.encoding import (
    SUPPORTED_FORMATS,
    JpegEncoder,
    Vp9Encoder,
    make_encoder,
)

from ._vp9 import sdk_decode

WIDTH, HEIGHT = 96, 64


def moving_frames(count: int, offset: int = 0) -> list[np.ndarray]:
    """Smooth gradients sliding sideways: realistic enough for rate control."""
    rows, columns = np.mgrid[0:HEIGHT, 0:WIDTH]
    return [
        np.stack(
            [(columns * 2 + 5 * (k + offset)) % 256, rows * 3, (rows + columns) % 256], axis=-1
        ).astype(np.uint8)
        for k in range(count)
    ]


def test_vp9_one_packet_per_frame_and_only_the_first_is_a_key_frame() -> None:
    encoder = Vp9Encoder(WIDTH, HEIGHT, 20.0)
    frames = moving_frames(12)
    packets = [encoder.encode(frame) for frame in frames]
    assert [Vp9Encoder.is_key_frame(p) for p in packets] == [True] + [False] * 11
    # A VP9 superframe (several frames in one packet) ends with an index byte 0b110xxxxx.
    assert not any(p[-1] & 0xE0 == 0xC0 for p in packets)
    decoded = sdk_decode(packets)
    assert all(frame.shape == (HEIGHT, WIDTH, 3) for frame in decoded)
    error = np.abs(np.stack(decoded).astype(int) - np.stack(frames).astype(int)).mean()
    assert error < 12, f"mean absolute error {error:.1f} is too high for a smooth image"


def test_vp9_restart_gives_a_key_frame_a_fresh_decoder_can_start_at() -> None:
    encoder = Vp9Encoder(WIDTH, HEIGHT, 20.0)
    first_clip = [encoder.encode(frame) for frame in moving_frames(3)]
    encoder.restart()
    second_clip = [encoder.encode(frame) for frame in moving_frames(3, offset=10)]
    assert Vp9Encoder.is_key_frame(second_clip[0])
    assert not Vp9Encoder.is_key_frame(second_clip[1])
    # The SDK keeps one decoder across clips; a new one must also start at the key frame.
    continuing = sdk_decode(first_clip + second_clip)[3:]
    fresh = sdk_decode(second_clip)
    assert all(np.array_equal(a, b) for a, b in zip(continuing, fresh, strict=True))


def test_vp9_is_deterministic() -> None:
    frames = moving_frames(6)
    encoders = [Vp9Encoder(WIDTH, HEIGHT, 20.0) for _ in range(2)]
    streams = [[encoder.encode(f) for f in frames] for encoder in encoders]
    assert streams[0] == streams[1]


def test_jpeg_round_trip() -> None:
    encoder = JpegEncoder(quality=95)
    frame = moving_frames(1)[0]
    packet = encoder.encode(frame)
    encoder.restart()  # no state: must not change the output
    assert encoder.encode(frame) == packet
    decoded = np.asarray(Image.open(io.BytesIO(packet)).convert("RGB"))
    assert decoded.shape == frame.shape
    assert np.abs(decoded.astype(int) - frame.astype(int)).mean() < 6


@pytest.mark.parametrize(
    ("frame", "error", "message"),
    [
        (np.zeros((HEIGHT, WIDTH, 3), np.float32), TypeError, "uint8"),
        (np.zeros((HEIGHT, WIDTH), np.uint8), ValueError, r"\[H, W, 3\]"),
        (np.zeros((HEIGHT, WIDTH + 2, 3), np.uint8), ValueError, r"\(64, 96, 3\)"),
    ],
)
def test_bad_frames_are_rejected_with_the_problem_named(
    frame: np.ndarray, error: type[Exception], message: str
) -> None:
    with pytest.raises(error, match=message):
        Vp9Encoder(WIDTH, HEIGHT, 20.0).encode(frame)


def test_make_encoder_and_supported_formats() -> None:
    assert SUPPORTED_FORMATS == (FrameFormat.RAW_RGB24, FrameFormat.VP9, FrameFormat.JPEG)
    frame = (
        np.arange(HEIGHT * WIDTH * 3, dtype=np.uint32).astype(np.uint8).reshape(HEIGHT, WIDTH, 3)
    )
    raw = make_encoder(FrameFormat.RAW_RGB24, WIDTH, HEIGHT, 20.0)
    assert raw.encode(frame) == frame.tobytes()  # the frame as it is, no codec
    vp9 = make_encoder(common_pb2.FRAME_FORMAT_VP9, WIDTH, HEIGHT, 20.0, vp9_cpu_used=6)
    assert isinstance(vp9, Vp9Encoder) and vp9.cpu_used == 6
    jpeg = make_encoder(common_pb2.FRAME_FORMAT_JPEG, WIDTH, HEIGHT, 20.0, jpeg_quality=70)
    assert isinstance(jpeg, JpegEncoder) and jpeg.quality == 70
    with pytest.raises(ValueError, match="FRAME_FORMAT_H264 is not supported"):
        make_encoder(common_pb2.FRAME_FORMAT_H264, WIDTH, HEIGHT, 20.0)
