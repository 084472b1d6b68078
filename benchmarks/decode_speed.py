"""Decoder throughput of the client vs plain PyAV, on packets recorded from the real server.

Records VP9 and JPEG packets from an embedded server session (768x512 by default), then decodes
the same packets, single-threaded caller, best of several repeats:

- ``pyav_plain``: what the official SDK does: ``CodecContext.decode`` + ``to_ndarray("rgb24")``;
- ``ours_full``: :class:`Vp9Decoder` writing into a preallocated array (target >= 0.9x plain);
- ``ours_resized``: the same decoder writing 192x128 frames (target >= 1.5x ours_full);
- ``pyav_decode_only``: VP9 decoding without any conversion, the ceiling of any resize gain;
- the JPEG equivalents (plain PIL ``convert("RGB")`` vs ours, full and resized).

Usage: ``python benchmarks/decode_speed.py [--width 768 --height 512 --chunks 30]``; prints JSON.
"""

from __future__ import annotations

import argparse
import io
import json
import time
from collections.abc import Callable

import av
import grpc
import numpy as np
from PIL import Image

from oasis_torchrl.client.decoding import JpegDecoder, Vp9Decoder
from oasis_torchrl.proto import a2v_pb2, a2v_pb2_grpc, common_pb2
from oasis_torchrl.sim.launcher import LocalServer

STREAM = "front"
SMALL = (128, 192)
# One libavcodec thread everywhere: measures per-core cost, as in the pool (one decoder per
# stream on a thread pool), and stays comparable when other processes load the machine.
DECODER_THREADS = 1


def record_packets(server: LocalServer, frame_format: int, chunks: int) -> list[bytes]:
    """Drive one session through ``chunks`` Infers and return the front stream's packets."""
    with grpc.insecure_channel(server.address) as channel:
        stub = a2v_pb2_grpc.A2VServiceStub(channel)
        key = (("x-api-key", server.api_key),)
        response, call = stub.Initialize.with_call(
            a2v_pb2.InitializeRequest(
                client_sdk_version="0.0.2",
                api_key=server.api_key,
                accepted_output_formats=[frame_format],
            ),
            metadata=key,
        )
        metadata = (*key, ("x-session-target", dict(call.initial_metadata())["x-session-target"]))
        session_id = response.session_id
        stub.Prompt(
            a2v_pb2.PromptRequest(session_id=session_id, prompt="a busy city street"),
            metadata=(*metadata, ("x-oasis-seed", "1")),
        )
        rng = np.random.default_rng(0)
        packets: list[bytes] = []
        for sequence_num in range(chunks):
            throttle_steer = rng.uniform([0.3, -0.6], [1.0, 0.6], size=(4, 2))
            request = a2v_pb2.InferRequest(
                session_id=session_id,
                sequence_num=sequence_num,
                actions=[a2v_pb2.Action(throttle=t, steering=s) for t, s in throttle_steer],
            )
            streams = {s.name: s.frames for s in stub.Infer(request, metadata=metadata).streams}
            packets.extend(streams[STREAM])
        stub.Finish(a2v_pb2.FinishRequest(session_id=session_id), metadata=metadata)
    return packets


def best_rates(runs: dict[str, Callable[[], None]], frames: int, repeats: int) -> dict[str, float]:
    """Frames per second of each run (best of ``repeats``), interleaved so load drifts hit all."""
    best = dict.fromkeys(runs, float("inf"))
    for _ in range(repeats):
        for name, run in runs.items():
            started = time.perf_counter()
            run()
            best[name] = min(best[name], time.perf_counter() - started)
    return {name: frames / seconds for name, seconds in best.items()}


def pyav_plain(packets: list[bytes]) -> Callable[[], None]:
    def run() -> None:
        context = av.CodecContext.create("vp9", "r")
        context.thread_count = DECODER_THREADS
        context.open()
        for packet in packets:
            context.decode(av.Packet(packet))[-1].to_ndarray(format="rgb24")

    return run


def pyav_decode_only(packets: list[bytes]) -> Callable[[], None]:
    def run() -> None:
        context = av.CodecContext.create("vp9", "r")
        context.thread_count = DECODER_THREADS
        context.open()
        for packet in packets:
            context.decode(av.Packet(packet))

    return run


def pil_plain(packets: list[bytes]) -> Callable[[], None]:
    def run() -> None:
        for packet in packets:
            with Image.open(io.BytesIO(packet)) as image:
                np.asarray(image.convert("RGB"))

    return run


def ours(
    make: Callable[[], object], packets: list[bytes], size: tuple[int, int]
) -> Callable[[], None]:
    out = np.empty((len(packets), *size, 3), np.uint8)

    def run() -> None:
        decoder = make()
        for packet, slot in zip(packets, out, strict=True):
            decoder.decode_into(packet, slot)

    return run


def measure(
    packets: list[bytes],
    baselines: dict[str, Callable[[list[bytes]], Callable[[], None]]],
    make: Callable[[], object],
    full: tuple[int, int],
    repeats: int,
) -> dict:
    """Rates of the baselines and of our decoder at full and reduced size, with the ratios."""
    runs = {name: baseline(packets) for name, baseline in baselines.items()}
    runs["ours_full"] = ours(make, packets, full)
    runs["ours_resized"] = ours(make, packets, SMALL)
    rates = best_rates(runs, len(packets), repeats)
    return {
        "frames": len(packets),
        "fps": {name: round(rate, 1) for name, rate in rates.items()},
        "ours_full_vs_plain": round(rates["ours_full"] / rates["plain"], 3),
        "resized_vs_ours_full": round(rates["ours_resized"] / rates["ours_full"], 3),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--width", type=int, default=768)
    parser.add_argument("--height", type=int, default=512)
    parser.add_argument(
        "--chunks", type=int, default=30, help="Infer calls recorded (4 frames each)"
    )
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    full = (args.height, args.width)
    with LocalServer(width=args.width, height=args.height) as server:
        vp9 = record_packets(server, common_pb2.FRAME_FORMAT_VP9, args.chunks)
        jpeg = record_packets(server, common_pb2.FRAME_FORMAT_JPEG, args.chunks)
    # Resizing saves only RGB conversion work; decoding cannot shrink, so the VP9 decode-only
    # rate is the ceiling of any resize gain. It is reported beside the gain.
    vp9_baselines = {"plain": pyav_plain, "pyav_decode_only": pyav_decode_only}
    vp9_report = measure(
        vp9, vp9_baselines, lambda: Vp9Decoder(STREAM, threads=DECODER_THREADS), full, args.repeats
    )
    fps = vp9_report["fps"]
    vp9_report["resize_ceiling_vs_ours_full"] = round(fps["pyav_decode_only"] / fps["ours_full"], 3)
    report = {
        "frame_size": {"width": args.width, "height": args.height},
        "resized_to": {"width": SMALL[1], "height": SMALL[0]},
        "vp9": vp9_report,
        "jpeg": measure(
            jpeg, {"plain": pil_plain}, lambda: JpegDecoder(STREAM), full, args.repeats
        ),
        "targets": {"ours_full_vs_plain": 0.9, "resized_vs_ours_full": 1.5},
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
