"""OasisEnv steps per second vs the bare SessionPool on the same sessions, same server.

The env adds action validation, tensor conversion, the ground-truth reward and the TensorDict
plumbing on top of the pool. Both loops drive the same N sessions of one server subprocess with
the same random actions; the ratio env/pool is the env's efficiency. Target: >= 0.9.

Usage: ``python benchmarks/env_overhead.py [--envs 8 --latency-ms 0 --seconds 6]``; prints JSON.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.launcher import ServerProcess

PROMPT = "urban street"


def pool_rate(env: OasisEnv, seconds: float) -> float:
    """Pool steps/s of the env's own (already open) pool, no env code on the path."""
    rng = np.random.default_rng(0)
    pool, n = env.pool, env.num_envs
    pool.reset(list(range(n)), [PROMPT] * n, list(range(n)))
    steps, started = 0, time.perf_counter()
    while time.perf_counter() - started < seconds:
        pool.infer(rng.uniform(-0.2, 1, size=(n, 4, 2)).astype(np.float32))
        steps += 1
    return steps / (time.perf_counter() - started)


def env_rate(env: OasisEnv, seconds: float) -> float:
    """Env steps/s, resetting rows that finish, like a collector."""
    generator = torch.Generator().manual_seed(0)
    td = env.reset()
    steps, started = 0, time.perf_counter()
    while time.perf_counter() - started < seconds:
        action = torch.rand(env.action_spec.shape, generator=generator) * 1.2 - 0.2
        _, td = env.step_and_maybe_reset(td.set("action", action))
        steps += 1
    return steps / (time.perf_counter() - started)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=8)
    parser.add_argument("--latency-ms", type=float, default=0.0)
    parser.add_argument("--width", type=int, default=96)
    parser.add_argument("--height", type=int, default=64)
    parser.add_argument("--seconds", type=float, default=6.0)
    args = parser.parse_args()
    with ServerProcess(width=args.width, height=args.height, latency_ms=args.latency_ms) as srv:
        env = OasisEnv(
            srv.endpoint, args.envs, PROMPT, api_key=srv.api_key, ground_truth=True, max_steps=64
        )
        try:
            env.reset()
            pool = pool_rate(env, args.seconds)
            envs = env_rate(env, args.seconds)
        finally:
            env.close()
    report = {
        "server": {"width": args.width, "height": args.height, "latency_ms": args.latency_ms},
        "num_envs": args.envs,
        "pool_steps_per_s": round(pool, 2),
        "env_steps_per_s": round(envs, 2),
        "env_over_pool": round(envs / pool, 3),
        "target": 0.9,
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
