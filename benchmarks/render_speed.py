"""Render cost of the embedded simulator versus VP9 encoding of the same frames.

Drives the autopilot through a few scenes, renders every step (4 frames x 3 cameras), and
encodes the frames of one camera with libvpx-vp9 realtime (deadline=realtime, cpu-used=8,
lag-in-frames=0, row-mt=1, 2 Mb/s, from ``rgb24`` ndarrays), the settings of the embedded server.
Prints JSON: milliseconds per camera-frame for rendering and encoding at 768x512 and 192x128,
and their ratio (the target is <= 0.5).

Run: ``python benchmarks/render_speed.py [--steps 40] [--repeats 3]``
"""

from __future__ import annotations

import argparse
import fractions
import json
import time

import av
import numpy as np

from oasis_torchrl.sim.autopilot import Autopilot
from oasis_torchrl.sim.simulator import CAMERA_NAMES, Simulator

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


def render_ms(simulator: Simulator, prompt: str, chunks: list[np.ndarray], repeats: int) -> tuple:
    """Best milliseconds per camera-frame over ``repeats`` replays, and the front frames."""
    best, frames = float("inf"), []
    for _ in range(repeats):
        simulator.reset(prompt, seed=0)
        frames = []
        start = time.perf_counter()
        for chunk in chunks:
            frames.extend(simulator.step(chunk).rgb["front"])
        elapsed = time.perf_counter() - start
        best = min(best, elapsed * 1000 / (len(chunks) * 4 * len(CAMERA_NAMES)))
    return best, frames


def encode_ms(frames: list[np.ndarray], repeats: int) -> float:
    """Best milliseconds per frame to VP9-encode ``frames`` (one stream)."""
    height, width = frames[0].shape[:2]
    best = float("inf")
    for _ in range(repeats):
        codec = av.CodecContext.create("libvpx-vp9", "w")
        codec.width, codec.height, codec.pix_fmt = width, height, "yuv420p"
        codec.time_base = fractions.Fraction(1, FPS)
        codec.framerate = FPS
        codec.bit_rate = 2_000_000
        codec.options = {"deadline": "realtime", "cpu-used": "8", "lag-in-frames": "0"}
        codec.options["row-mt"] = "1"
        start = time.perf_counter()
        for index, frame in enumerate(frames):
            video_frame = av.VideoFrame.from_ndarray(frame, format="rgb24")
            video_frame.pts = index
            codec.encode(video_frame)
        codec.encode(None)
        best = min(best, (time.perf_counter() - start) * 1000 / len(frames))
    return best


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
            render, frames = render_ms(simulator, prompt, chunks, args.repeats)
            encode = encode_ms(frames, args.repeats)
            per_scene[prompt] = {
                "render_ms": round(render, 3),
                "encode_ms": round(encode, 3),
                "ratio": round(render / encode, 3),
            }
        render = float(np.mean([scene["render_ms"] for scene in per_scene.values()]))
        encode = float(np.mean([scene["encode_ms"] for scene in per_scene.values()]))
        results[f"{width}x{height}"] = {
            "render_ms_per_camera_frame": round(render, 3),
            "vp9_encode_ms_per_frame": round(encode, 3),
            "ratio_render_to_encode": round(render / encode, 3),
            "scenes": per_scene,
        }
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
