"""The reference way (N Gymnasium-style envs on the official client, stepped in turn) vs OasisEnv.

The reference RL extras wrap one blocking ``decart_oasis`` session per Gymnasium env and a
vectorised SB3 loop steps them one after another; reset re-prompts and sends one zero chunk, the
observation is the last frame per camera. This script reproduces that loop (in a subprocess: the
official protos clash with ours in one process) and compares env steps per second with one
``OasisEnv`` of the same N on the same server (a subprocess adding ``latency_ms`` per Infer, as a
GPU world model does). Targets: >= 6x at N=8, >= 10x at N=16.

Usage: ``python benchmarks/env_vs_reference.py [--envs 8 16 --latency-ms 200 --seconds 8]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np
import torch
from tensordict import TensorDict

PROMPT = "urban street"


class ReferenceStyleEnv:
    """One official-client session with the reference env's reset/step semantics."""

    def __init__(self, endpoint: str) -> None:
        from decart_oasis import A2VClient

        self.client = A2VClient(endpoint)
        self.client.initialize()

    def reset(self) -> dict[str, np.ndarray]:
        self.client.prompt(PROMPT)
        return self.step(np.zeros((4, 2), np.float32))

    def step(self, action: np.ndarray) -> dict[str, np.ndarray]:
        frames = self.client.infer(action).frames
        return {camera: chunk[-1] for camera, chunk in frames.items()}


def reference_worker(endpoint: str, n: int, seconds: float) -> dict:
    rng = np.random.default_rng(0)
    envs = [ReferenceStyleEnv(endpoint) for _ in range(n)]
    try:
        for env in envs:
            env.reset()
        rounds, started = 0, time.perf_counter()
        while time.perf_counter() - started < seconds:
            for env in envs:
                env.step(rng.uniform(-0.2, 1, size=(4, 2)).astype(np.float32))
            rounds += 1
        elapsed = time.perf_counter() - started
    finally:
        for env in envs:
            env.client.close()
    return {"env_steps_per_s": round(rounds * n / elapsed, 2), "rounds": rounds}


def oasis_rate(endpoint: str, api_key: str, n: int, seconds: float) -> dict:
    from oasis_torchrl.envs import OasisEnv

    env = OasisEnv(endpoint, n, PROMPT, api_key=api_key, max_steps=10_000)
    generator = torch.Generator().manual_seed(0)
    try:
        env.reset()
        steps, started = 0, time.perf_counter()
        while time.perf_counter() - started < seconds:
            action = torch.rand(env.action_spec.shape, generator=generator) * 1.2 - 0.2
            env.step(TensorDict(action=action, batch_size=env.batch_size))
            steps += 1
        elapsed = time.perf_counter() - started
    finally:
        env.close()
    return {"env_steps_per_s": round(steps * n / elapsed, 2), "batched_steps": steps}


def run_reference(endpoint: str, api_key: str, n: int, seconds: float) -> dict:
    command = [sys.executable, __file__, "--reference-worker", "--endpoint", endpoint]
    command += ["--envs", str(n), "--seconds", str(seconds)]
    environment = {**os.environ, "DECART_API_KEY": api_key}
    done = subprocess.run(command, env=environment, capture_output=True, text=True, check=True)
    return json.loads(done.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, nargs="+", default=[8, 16])
    parser.add_argument("--latency-ms", type=float, default=200.0)
    parser.add_argument("--width", type=int, default=96)
    parser.add_argument("--height", type=int, default=64)
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--endpoint", help=argparse.SUPPRESS)
    parser.add_argument("--reference-worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.reference_worker:
        print(json.dumps(reference_worker(args.endpoint, args.envs[0], args.seconds)))
        return

    from oasis_torchrl.sim.launcher import ServerProcess

    targets = {8: 6.0, 16: 10.0}
    results = []
    with ServerProcess(width=args.width, height=args.height, latency_ms=args.latency_ms) as srv:
        for n in args.envs:
            reference = run_reference(srv.endpoint, srv.api_key, n, args.seconds)
            ours = oasis_rate(srv.endpoint, srv.api_key, n, args.seconds)
            speedup = ours["env_steps_per_s"] / reference["env_steps_per_s"]
            results.append(
                {
                    "num_envs": n,
                    "reference_sequential": reference,
                    "oasis_env": ours,
                    "speedup": round(speedup, 2),
                    "target": targets.get(n),
                }
            )
    server = {"width": args.width, "height": args.height, "latency_ms": args.latency_ms}
    print(json.dumps({"server": server, "results": results}, indent=2))


if __name__ == "__main__":
    main()
