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
from pathlib import Path

import numpy as np

from oasis_torchrl.client import SessionPool
from oasis_torchrl.sim.launcher import ServerProcess

PROMPT = "a quiet suburban road"


def process_cpu_seconds(pid: int) -> float | None:
    """User + system CPU seconds of process ``pid`` and its children (the server's worker
    processes), from Linux /proc; None elsewhere."""
    stat = Path(f"/proc/{pid}/stat")
    if not stat.exists():
        return None
    children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    total = 0.0
    for process in (pid, *map(int, children)):
        fields = Path(f"/proc/{process}/stat").read_text().rsplit(")", 1)[1].split()
        total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return total


def session_steps_per_second(server: ServerProcess, sessions: int, seconds: float) -> dict:
    """Step a pool of ``sessions`` for about ``seconds``; returns its measured rates."""
    rng = np.random.default_rng(0)
    with SessionPool(server.endpoint, sessions, api_key=server.api_key) as pool:
        pool.reset(None, [PROMPT] * sessions, seeds=list(range(sessions)))
        pool.infer(np.zeros((sessions, 4, 2), np.float32))  # warm-up
        steps = 0
        started, cpu_started = time.perf_counter(), time.process_time()
        server_cpu_started = process_cpu_seconds(server.pid)
        while time.perf_counter() - started < seconds:
            actions = rng.uniform(-1, 1, size=(sessions, 4, 2)).astype(np.float32)
            step = pool.infer(actions)
            if step.status.any():
                raise RuntimeError(f"a session failed during the benchmark: {step.errors}")
            steps += 1
        elapsed = time.perf_counter() - started
        cpu = time.process_time() - cpu_started
        server_cpu = process_cpu_seconds(server.pid)
    session_steps = steps * sessions
    if server_cpu is not None and server_cpu_started is not None:
        server_cpu = round(1000 * (server_cpu - server_cpu_started) / session_steps, 2)
    return {
        "pool_steps_per_s": round(steps / elapsed, 2),
        "session_steps_per_s": round(session_steps / elapsed, 2),
        "mean_step_ms": round(1000 * elapsed / steps, 1),
        # CPU per session-step of the client (all its threads) and of the server process:
        # shows which side's work bounds the rate on this machine.
        "client_cpu_ms_per_session_step": round(1000 * cpu / session_steps, 2),
        "server_cpu_ms_per_session_step": server_cpu,
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
