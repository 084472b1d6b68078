"""The client's CPU per session-step against the hosted-like server, and how many hosted sessions
one core keeps fed at the world's real-time rate (a chunk every 200 ms).

A hosted-like embedded server (``ServerConfig(hosted=True)``: three VP9 streams at 768x512, 4
frames per Infer, nothing else) runs in processes of its own; this process drives ``--sessions``
sessions through :class:`~oasis_torchrl.envs.OasisEnv` with a reward that costs nothing, so its
CPU time is the client's alone: the gRPC calls, the stateful VP9 decoding of the 12 frames of
each session-step and the env's TensorDicts. Two decode sizes, measured in the same run:

- ``policy``: frames decoded straight to the policy's size (``--policy-size``, 64x96 by default),
  the chunk's last frame converted to RGB (what ``make_env(all_frames=False)`` asks for);
- ``full``: the same at 768x512, the baseline (``ratio`` = full / policy CPU per step).

``sessions_per_core`` = 200 ms / CPU ms per session-step. CPU time (not wall time) is the
figure: the server shares the machine's cores with the client here.

Usage: ``python benchmarks/hosted_client.py [--sessions 4 --steps 30]``; prints JSON.
"""

from __future__ import annotations

import argparse
import json
import time

import torch
from _process_cpu import CpuMeter
from tensordict import TensorDictBase

from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.protocol import CHUNK, FPS, HOSTED_FRAME_SIZE
from oasis_torchrl.sim.config import ServerConfig

REAL_TIME_MS = 1000.0 * CHUNK / FPS
"""World time of one chunk: the rate at which a hosted session must be fed."""


def no_reward(td: TensorDictBase) -> torch.Tensor:
    """Zero reward: the measurement is the client's, not a reward model's."""
    return torch.zeros(td.batch_size[0], 1)


def measure(size: tuple[int, int] | None, sessions: int, steps: int) -> dict[str, float | None]:
    """Client CPU ms per session-step (and wall ms per step) at decode size ``size``."""
    server = ServerConfig(hosted=True, processes=min(sessions, 2))
    env = OasisEnv(
        "local", sessions, server=server, frame_size=size, reward=no_reward, max_steps=10**6
    )
    action = torch.tensor([[0.6, 0.0]] * CHUNK).expand(sessions, CHUNK, 2)
    try:
        td = env.step(env.reset().set("action", action))["next"]  # past the key frames
        meter = CpuMeter(server_pid=None)
        started = time.perf_counter()
        for _ in range(steps):
            td = env.step(td.set("action", action))["next"]
        wall_ms = 1000.0 * (time.perf_counter() - started) / steps
        client_ms = meter.ms_per(steps * sessions)["this_process"]
    finally:
        env.close()
    return {"client_cpu_ms_per_session_step": client_ms, "wall_ms_per_step": round(wall_ms, 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=4)
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--policy-size", type=int, nargs=2, default=(64, 96))
    args = parser.parse_args()
    policy = measure(tuple(args.policy_size), args.sessions, args.steps)
    full = measure(None, args.sessions, args.steps)
    per_step = policy["client_cpu_ms_per_session_step"]
    baseline = full["client_cpu_ms_per_session_step"]
    result = {
        "server": {"hosted": True, "frame_size": list(HOSTED_FRAME_SIZE), "format": "vp9"},
        "sessions": args.sessions,
        "steps": args.steps,
        "policy_size": list(args.policy_size),
        "policy": policy,
        "full": full,
        "ratio": round(baseline / per_step, 2),
        "real_time_ms_per_chunk": REAL_TIME_MS,
        "sessions_per_core": round(REAL_TIME_MS / per_step, 1),
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
