"""Rendering the 4 frames of an Infer one pose at a time versus in one batched pass.

Drives the autopilot through a few scenes (physics only) and keeps the car pose of every frame.
Each step (4 frames x 3 cameras) is then rendered both ways with the same renderer:
``Renderer.render`` once per pose, and ``Renderer.render_many`` on the 4 poses (what the
embedded simulator does). The two variants alternate step by step, so both see the same machine
load; the ratio is taken per repeat (same run) and its median reported. Prints JSON:
milliseconds per Infer of each variant (wall and process CPU time, all threads; median of the
repeats) and the speedup ``one_pose / batched`` per size.

Run: ``python benchmarks/render_batch.py [--steps 30] [--repeats 5]``
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import numpy as np

from oasis_torchrl.protocol import CAMERAS, CHUNK
from oasis_torchrl.sim.autopilot import Autopilot
from oasis_torchrl.sim.render import Renderer
from oasis_torchrl.sim.simulator import Simulator
from oasis_torchrl.sim.vehicle import VehicleState

PROMPTS = ("urban", "highway", "rural at night", "city in the rain", "rural snow")
SIZES = ((96, 64), (192, 128), (768, 512))
Step = tuple[list[VehicleState], list[int]]


def drive(simulator: Simulator, prompt: str, steps: int) -> list[Step]:
    """Poses and frame numbers of each step of an autopilot drive (physics only)."""
    simulator.reset(prompt, seed=0)
    pilot = Autopilot(simulator)
    drive_steps = []
    for step in range(steps):
        truth = simulator.step(pilot.act(), render=False).truth
        poses = [VehicleState(frame.x, frame.y, frame.heading, frame.speed) for frame in truth]
        drive_steps.append((poses, list(range(step * CHUNK + 1, (step + 1) * CHUNK + 1))))
    return drive_steps


def one_pose_at_a_time(renderer: Renderer, step: Step, out: dict[str, np.ndarray]) -> None:
    """Render the step's poses one call each."""
    for index, (pose, frame) in enumerate(zip(*step, strict=True)):
        renderer.render(pose, frame, {name: out[name][index] for name in CAMERAS})


def batched(renderer: Renderer, step: Step, out: dict[str, np.ndarray]) -> None:
    """Render the step's poses in one call."""
    renderer.render_many(*step, out)


VARIANTS: dict[str, Callable[[Renderer, Step, dict[str, np.ndarray]], None]] = {
    "one_pose": one_pose_at_a_time,
    "batched": batched,
}


def time_size(width: int, height: int, steps: int, repeats: int) -> dict[str, object]:
    """Milliseconds per Infer of each variant at one size, and the same-run speedup."""
    simulator = Simulator(width, height)
    renderer = Renderer(width, height)
    out = {name: np.empty((CHUNK, height, width, 3), np.uint8) for name in CAMERAS}
    drives = []
    for prompt in PROMPTS:
        drive_steps = drive(simulator, prompt, steps)
        drives.append((simulator.scene, drive_steps))
    totals = np.zeros((repeats, len(VARIANTS), 2))  # wall, cpu
    for repeat in range(repeats + 1):  # the first pass warms up caches and threads
        for scene, drive_steps in drives:
            renderer.prepare(scene)
            for step in drive_steps:
                for variant, render in enumerate(VARIANTS.values()):
                    start = np.array([time.perf_counter(), time.process_time()])
                    render(renderer, step, out)
                    elapsed = np.array([time.perf_counter(), time.process_time()]) - start
                    if repeat:
                        totals[repeat - 1, variant] += elapsed
    infers = sum(len(drive_steps) for _, drive_steps in drives)
    per_infer = totals * 1000 / infers
    median = np.median(per_infer, axis=0)
    speedup = np.median(per_infer[:, 0] / per_infer[:, 1], axis=0)
    result: dict[str, object] = {
        f"{name}_ms_per_infer": round(float(median[index, 0]), 3)
        for index, name in enumerate(VARIANTS)
    }
    result |= {
        f"{name}_cpu_ms_per_infer": round(float(median[index, 1]), 3)
        for index, name in enumerate(VARIANTS)
    }
    result["speedup"] = round(float(speedup[0]), 3)
    result["cpu_speedup"] = round(float(speedup[1]), 3)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=30, help="steps (4 frames each) per scene")
    parser.add_argument("--repeats", type=int, default=5, help="timed repeats (median is kept)")
    args = parser.parse_args()
    results = {
        f"{width}x{height}": time_size(width, height, args.steps, args.repeats)
        for width, height in SIZES
    }
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
