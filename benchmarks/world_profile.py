"""Where one session's world spends its time: a cProfile of ``SessionWorld.infer``.

Steps one world (what a server worker runs per session: physics, rendering of 4 frames x 3
cameras, ground truth, the expert, the serialised answer) with raw frames and a constant
throttle, crashes restarting the scene, and prints JSON: the CPU milliseconds per Infer without
the profiler, and the top entries by own time under it (share, milliseconds and calls per
Infer). Run it on two commits to compare them.

Run: ``python benchmarks/world_profile.py [--infers 500] [--top 10] [--size 96x64]``
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import time

import numpy as np

from oasis_torchrl.protocol import FrameFormat
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.session_world import SessionWorld

PROMPT = "urban street"
WARMUP_INFERS = 30


class Drive:
    """One world driven straight on, its scene restarted after a crash."""

    def __init__(self, width: int, height: int) -> None:
        config = ServerConfig(width=width, height=height, api_keys=("benchmark",))
        self.world = SessionWorld(FrameFormat.RAW_RGB24, config, None)
        self.actions = np.tile(np.float32([0.5, 0.0]), (4, 1))
        self.sequence_num = 0
        self.world.prompt(PROMPT, 0)

    def infers(self, count: int) -> None:
        """Run ``count`` Infers."""
        for _ in range(count):
            self.world.infer(self.sequence_num, self.actions)
            self.sequence_num += 1
            if self.sequence_num % 100 == 0:  # a new scene now and then, as episodes do
                self.world.prompt(PROMPT, self.sequence_num)
                self.sequence_num = 0


def _short(path: str) -> str:
    """A source path from its package on."""
    return path.rsplit("site-packages/", 1)[-1].rsplit("oasis_torchrl/", 1)[-1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--infers", type=int, default=500, help="Infers measured")
    parser.add_argument("--top", type=int, default=10, help="entries listed")
    parser.add_argument("--size", default="96x64", help="frame size WIDTHxHEIGHT")
    args = parser.parse_args()
    width, height = (int(value) for value in args.size.split("x"))
    drive = Drive(width, height)
    drive.infers(WARMUP_INFERS)
    started = time.process_time()
    drive.infers(args.infers)
    cpu_ms = (time.process_time() - started) / args.infers * 1000
    profile = cProfile.Profile()
    profile.enable()
    drive.infers(args.infers)
    profile.disable()
    stats = pstats.Stats(profile)
    entries = sorted(stats.stats.items(), key=lambda item: -item[1][2])[: args.top]
    report = {
        "benchmark": "world_profile",
        "frame_size": args.size,
        "load_average_1min": round(os.getloadavg()[0], 2),
        "cpu_ms_per_infer": round(cpu_ms, 3),
        "profiled_ms_per_infer": round(stats.total_tt / args.infers * 1000, 3),
        "top_by_own_time": [
            {
                "function": f"{_short(path)}:{line}({name})",
                "share": round(own / stats.total_tt, 3),
                "ms_per_infer": round(own / args.infers * 1000, 3),
                "calls_per_infer": round(calls / args.infers, 1),
            }
            for (path, line, name), (_, calls, own, _, _) in entries
        ],
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
