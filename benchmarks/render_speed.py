"""Render cost of the embedded simulator versus VP9 encoding of the same frames.

Drives the autopilot through a few scenes, then replays each drive: every step is rendered
(4 frames x 3 cameras) and its front frames are encoded with libvpx-vp9 realtime
(deadline=realtime, cpu-used=8, lag-in-frames=0, row-mt=1, 2 Mb/s, from ``rgb24`` ndarrays, the
embedded server's settings), alternating so both see the same machine load. Prints JSON:
milliseconds per camera-frame to render and per frame to encode (median of the repeats) at
768x512 and 192x128, and their ratio (the target at 768x512 is <= 0.5).

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


def new_encoder(width: int, height: int) -> av.CodecContext:
    """A libvpx-vp9 realtime encoder with the embedded server's settings."""
    codec = av.CodecContext.create("libvpx-vp9", "w")
    codec.width, codec.height, codec.pix_fmt = width, height, "yuv420p"
    codec.time_base = fractions.Fraction(1, FPS)
    codec.framerate = FPS
    codec.bit_rate = 2_000_000
    codec.options = {"deadline": "realtime", "cpu-used": "8", "lag-in-frames": "0", "row-mt": "1"}
    return codec


def replay(simulator: Simulator, prompt: str, chunks: list[np.ndarray]) -> tuple[float, float]:
    """Milliseconds per camera-frame to render, and per frame to encode, over one replay.

    Rendering a step and encoding its front frames alternate, so both see the same machine
    load (the ratio stays meaningful on a busy machine).
    """
    simulator.reset(prompt, seed=0)
    codec = new_encoder(simulator.width, simulator.height)
    render = encode = 0.0
    frames = 0
    for chunk in chunks:
        start = time.perf_counter()
        rgb = simulator.step(chunk).rgb["front"]
        rendered = time.perf_counter()
        for frame in rgb:
            video_frame = av.VideoFrame.from_ndarray(frame, format="rgb24")
            video_frame.pts = frames
            codec.encode(video_frame)
            frames += 1
        render += rendered - start
        encode += time.perf_counter() - rendered
    codec.encode(None)
    return render * 1000 / (frames * len(CAMERA_NAMES)), encode * 1000 / frames


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
            render, encode = np.median(runs, axis=0)
            per_scene[prompt] = {
                "render_ms": round(float(render), 3),
                "encode_ms": round(float(encode), 3),
                "ratio": round(float(render / encode), 3),
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
