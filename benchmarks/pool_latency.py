"""SessionPool throughput vs pool size against a server with a fixed Infer latency.

The embedded server runs in a subprocess (its own GIL) with its worker processes and
``latency_ms`` added to every Infer, like a remote GPU model; the pool steps N sessions at once
(raw frames: the server is on this machine). Throughput is session-steps per
second (N chunks per pool step); the target is N=16 >= 12x N=1 (latency hidden by concurrency).

Usage: ``python benchmarks/pool_latency.py [--latency-ms 100 --sizes 1 4 16 --seconds 4]``;
prints JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
from _process_cpu import CpuMeter

from oasis_torchrl.client import SessionPool
from oasis_torchrl.sim.launcher import ServerProcess

PROMPT = "a quiet suburban road"


def session_steps_per_second(server: ServerProcess, sessions: int, seconds: float) -> dict:
    """Step a pool of ``sessions`` for about ``seconds``; returns its measured rates."""
    rng = np.random.default_rng(0)
    with SessionPool(server.endpoint, sessions, api_key=server.api_key) as pool:
        pool.reset(None, [PROMPT] * sessions, seeds=list(range(sessions)))
        pool.infer(np.zeros((sessions, 4, 2), np.float32))  # warm-up
        steps = 0
        started, meter = time.perf_counter(), CpuMeter(server.pid)
        while time.perf_counter() - started < seconds:
            actions = rng.uniform(-1, 1, size=(sessions, 4, 2)).astype(np.float32)
            step = pool.infer(actions)
            if step.status.any():
                raise RuntimeError(f"a session failed during the benchmark: {step.errors}")
            steps += 1
        elapsed = time.perf_counter() - started
        session_steps = steps * sessions
        cpu_ms = meter.ms_per(session_steps)
    return {
        "pool_steps_per_s": round(steps / elapsed, 2),
        "session_steps_per_s": round(session_steps / elapsed, 2),
        "mean_step_ms": round(1000 * elapsed / steps, 1),
        # CPU per session-step of the client (all its threads), the server's front and its
        # workers: shows which side's work bounds the rate on this machine.
        "client_cpu_ms_per_session_step": cpu_ms["this_process"],
        "server_front_cpu_ms_per_session_step": cpu_ms["front"],
        "server_workers_cpu_ms_per_session_step": cpu_ms["workers"],
        "total_cpu_ms_per_session_step": cpu_ms["total"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--latency-ms", type=float, default=100.0)
    parser.add_argument("--width", type=int, default=96)
    parser.add_argument("--height", type=int, default=64)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 4, 16])
    parser.add_argument("--seconds", type=float, default=4.0)
    args = parser.parse_args()
    server = ServerProcess(width=args.width, height=args.height, latency_ms=args.latency_ms)
    with server:
        results = {str(n): session_steps_per_second(server, n, args.seconds) for n in args.sizes}
    base = results[str(args.sizes[0])]["session_steps_per_s"]
    for result in results.values():
        result["speedup_vs_smallest"] = round(result["session_steps_per_s"] / base, 2)
    report = {
        "server": {"width": args.width, "height": args.height, "latency_ms": args.latency_ms},
        "cpus": os.cpu_count(),
        "pools": results,
        "target": "N=16 session_steps_per_s >= 12x N=1",
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
