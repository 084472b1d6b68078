"""Render cost of the embedded simulator versus VP9 encoding of the same frames.

Drives the autopilot through a few scenes, then replays each drive: every step is rendered
(4 frames x 3 cameras) and its front frames are encoded with libvpx-vp9 realtime
(deadline=realtime, cpu-used=8, lag-in-frames=0, row-mt=1, 2 Mb/s, from ``rgb24`` ndarrays, the
embedded server's settings), alternating so both see the same machine load. Prints JSON:
milliseconds per camera-frame to render and per frame to encode (median of the repeats), as
wall time and as process CPU time (all threads), at 768x512 and 192x128, and their ratios
(the target at 768x512 is <= 0.5).

Run: ``python benchmarks/render_speed.py [--steps 40] [--repeats 3]``
"""

from __future__ import annotations

import argparse
import fractions
import json
import time

import av
import numpy as np

from oasis_torchrl.protocol import CAMERAS
from oasis_torchrl.sim.autopilot import Autopilot
from oasis_torchrl.sim.simulator import Simulator

PROMPTS = ("urban", "highway", "rural at night", "city in the rain")
SIZES = ((768, 512), (192, 128))
FPS = 20


def drive(simulator: Simulator, prompt: str, steps: int) -> list[np.ndarray]:
    """Actions of an autopilot drive of ``steps`` steps (physics only)."""
    simulator.reset(prompt, seed=0)
    pilot = Autopilot(simulator)
    chunks = []
    for _ in range(steps):
        chunks.append(pilot.act())
        simulator.step(chunks[-1], render=False)
    return chunks


def new_encoder(width: int, height: int) -> av.CodecContext:
    """A libvpx-vp9 realtime encoder with the embedded server's settings."""
    codec = av.CodecContext.create("libvpx-vp9", "w")
    codec.width, codec.height, codec.pix_fmt = width, height, "yuv420p"
    codec.time_base = fractions.Fraction(1, FPS)
    codec.framerate = FPS
    codec.bit_rate = 2_000_000
    codec.options = {"deadline": "realtime", "cpu-used": "8", "lag-in-frames": "0", "row-mt": "1"}
    return codec


def replay(simulator: Simulator, prompt: str, chunks: list[np.ndarray]) -> np.ndarray:
    """Wall and CPU milliseconds per camera-frame to render, and per frame to encode, over
    one replay: ``[render wall, encode wall, render cpu, encode cpu]``.

    Rendering a step and encoding its front frames alternate, so both see the same machine
    load (the ratio stays meaningful on a busy machine). CPU time is the process's, all threads.
    """
    simulator.reset(prompt, seed=0)
    codec = new_encoder(simulator.width, simulator.height)
    totals = np.zeros(4)
    frames = 0
    for chunk in chunks:
        start = np.array([time.perf_counter(), time.process_time()])
        rgb = simulator.step(chunk).rgb["front"]
        rendered = np.array([time.perf_counter(), time.process_time()])
        for frame in rgb:
            video_frame = av.VideoFrame.from_ndarray(frame, format="rgb24")
            video_frame.pts = frames
            codec.encode(video_frame)
            frames += 1
        encoded = np.array([time.perf_counter(), time.process_time()])
        totals += np.concatenate([rendered - start, encoded - rendered])[[0, 2, 1, 3]]
    codec.encode(None)
    return totals * 1000 / (frames * np.array([len(CAMERAS), 1, len(CAMERAS), 1]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=40, help="steps (4 frames each) per scene")
    parser.add_argument("--repeats", type=int, default=3, help="timed repeats (best is kept)")
    args = parser.parse_args()
    results = {}
    for width, height in SIZES:
        simulator = Simulator(width, height, fps=FPS)
        per_scene = {}
        for prompt in PROMPTS:
            chunks = drive(simulator, prompt, args.steps)
            runs = np.array([replay(simulator, prompt, chunks) for _ in range(args.repeats)])
            render, encode, render_cpu, encode_cpu = np.median(runs, axis=0)
            per_scene[prompt] = {
                "render_ms": round(float(render), 3),
                "encode_ms": round(float(encode), 3),
                "ratio": round(float(render / encode), 3),
                "render_cpu_ms": round(float(render_cpu), 3),
                "encode_cpu_ms": round(float(encode_cpu), 3),
                "cpu_ratio": round(float(render_cpu / encode_cpu), 3),
            }
        mean = {
            key: float(np.mean([scene[key] for scene in per_scene.values()]))
            for key in ("render_ms", "encode_ms", "render_cpu_ms", "encode_cpu_ms")
        }
        results[f"{width}x{height}"] = {
            "render_ms_per_camera_frame": round(mean["render_ms"], 3),
            "vp9_encode_ms_per_frame": round(mean["encode_ms"], 3),
            "ratio_render_to_encode": round(mean["render_ms"] / mean["encode_ms"], 3),
            "render_cpu_ms_per_camera_frame": round(mean["render_cpu_ms"], 3),
            "vp9_encode_cpu_ms_per_frame": round(mean["encode_cpu_ms"], 3),
            "cpu_ratio_render_to_encode": round(mean["render_cpu_ms"] / mean["encode_cpu_ms"], 3),
            "scenes": per_scene,
        }
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
