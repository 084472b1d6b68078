"""Frame decoders against real VP9 and JPEG packets from the embedded server's encoders."""

from __future__ import annotations

import av
import numpy as np
import pytest
from PIL import Image

from oasis_torchrl.client.decoding import (
    JpegDecoder,
    Vp9Decoder,
    decode_chunk,
    make_decoder,
    validate_resize,
)
from oasis_torchrl.client.errors import DecodeError
from oasis_torchrl.client.types import FrameFormat
from oasis_torchrl.sim.encoding import JpegEncoder, Vp9Encoder

HEIGHT, WIDTH = 128, 192


def scene(step: int) -> np.ndarray:
    """A smooth moving test picture (uint8 RGB) that survives lossy coding well."""
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float32)
    red = 128 + 100 * np.sin((x + 4 * step) / 17.0)
    green = 128 + 100 * np.cos((y - 3 * step) / 13.0)
    blue = 255 * ((x // 32 + y // 32 + step // 2) % 2)
    return np.stack([red, green, blue], axis=-1).clip(0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def vp9_packets() -> list[bytes]:
    encoder = Vp9Encoder(WIDTH, HEIGHT, 20.0)
    return [encoder.encode(scene(step)) for step in range(8)]


def plain_pyav_decode(packets: list[bytes]) -> list[np.ndarray]:
    context = av.CodecContext.create("vp9", "r")
    context.open()
    return [context.decode(av.Packet(p))[-1].to_ndarray(format="rgb24") for p in packets]


def area_downscale(image: np.ndarray, factor: int) -> np.ndarray:
    height, width = image.shape[0] // factor, image.shape[1] // factor
    blocks = image.reshape(height, factor, width, factor, 3).astype(np.float32)
    return blocks.mean(axis=(1, 3))


def test_vp9_full_size_matches_plain_pyav_exactly(vp9_packets: list[bytes]) -> None:
    out = np.empty((len(vp9_packets), HEIGHT, WIDTH, 3), np.uint8)
    decode_chunk(Vp9Decoder("front"), vp9_packets, out)
    for ours, reference in zip(out, plain_pyav_decode(vp9_packets), strict=True):
        np.testing.assert_array_equal(ours, reference)


def test_vp9_resize_is_close_to_downscaled_full_decode(vp9_packets: list[bytes]) -> None:
    out = np.empty((len(vp9_packets), HEIGHT // 4, WIDTH // 4, 3), np.uint8)
    decode_chunk(Vp9Decoder("front"), vp9_packets, out)
    for small, full in zip(out, plain_pyav_decode(vp9_packets), strict=True):
        # Chroma is scaled before conversion, so sharp colour edges differ by a few levels.
        error = np.abs(small.astype(np.float32) - area_downscale(full, 4)).mean()
        assert error < 4.0, error


def test_vp9_reset_starts_a_new_clip(vp9_packets: list[bytes]) -> None:
    decoder = Vp9Decoder("front")
    first, again = (np.empty((2, HEIGHT, WIDTH, 3), np.uint8) for _ in range(2))
    decode_chunk(decoder, vp9_packets[:2], first)
    decoder.reset()
    decode_chunk(decoder, vp9_packets[:2], again)
    np.testing.assert_array_equal(first, again)


def test_vp9_desync_is_a_decode_error(vp9_packets: list[bytes]) -> None:
    out = np.empty((HEIGHT, WIDTH, 3), np.uint8)
    with pytest.raises(DecodeError, match="'left_forward'"):
        Vp9Decoder("left_forward").decode_into(b"\x00garbage", out)
    with pytest.raises(DecodeError):  # an inter frame without its key frame
        Vp9Decoder("front").decode_into(vp9_packets[3], out)


def test_chunk_with_wrong_frame_count_is_a_decode_error(vp9_packets: list[bytes]) -> None:
    with pytest.raises(DecodeError, match="expected 4 frames, got 2"):
        decode_chunk(
            Vp9Decoder("front"), vp9_packets[:2], np.empty((4, HEIGHT, WIDTH, 3), np.uint8)
        )


def test_jpeg_full_size_and_draft_resize() -> None:
    packet = JpegEncoder(quality=90).encode(scene(0))
    full = np.empty((HEIGHT, WIDTH, 3), np.uint8)
    JpegDecoder("front").decode_into(packet, full)
    assert np.abs(full.astype(np.float32) - scene(0)).mean() < 6.0
    for size in ((HEIGHT // 4, WIDTH // 4), (50, 70)):
        small = np.empty((*size, 3), np.uint8)
        JpegDecoder("front").decode_into(packet, small)
        reference = np.asarray(Image.fromarray(full).resize(size[::-1], Image.BILINEAR), np.float32)
        assert np.abs(small.astype(np.float32) - reference).mean() < 6.0
    with pytest.raises(DecodeError, match="invalid JPEG"):
        JpegDecoder("front").decode_into(b"not a jpeg", full)


def test_raw_frames_copy_exactly_and_scale_in_one_pass() -> None:
    image = scene(0)
    decoder = make_decoder(FrameFormat.RAW_RGB24, "front", (HEIGHT, WIDTH))
    out = np.empty_like(image)
    decoder.decode_into(image.tobytes(), out)
    assert np.array_equal(out, image)  # no codec, no loss
    small = np.empty((HEIGHT // 4, WIDTH // 4, 3), np.uint8)
    decoder.decode_into(image.tobytes(), small)
    reference = image.reshape(HEIGHT // 4, 4, WIDTH // 4, 4, 3).astype(np.float32).mean((1, 3))
    assert np.abs(small.astype(np.float32) - reference).mean() < 3.0
    with pytest.raises(DecodeError, match="expected 128x192x3"):
        decoder.decode_into(image.tobytes()[:-3], out)


def test_make_decoder_and_resize_validation() -> None:
    assert isinstance(make_decoder(FrameFormat.VP9, "front", (HEIGHT, WIDTH)), Vp9Decoder)
    with pytest.raises(ValueError, match="frame_format"):
        make_decoder(FrameFormat.H264, "front", (HEIGHT, WIDTH))
    assert validate_resize(None) is None
    for bad in ((0, 10), (10,), (1.5, 2), "ab"):
        with pytest.raises(ValueError, match="resize"):
            validate_resize(bad)  # type: ignore[arg-type]
