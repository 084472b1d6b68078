"""16 sessions: the official ``decart_oasis`` client stepping them one after another vs our pool.

Both drive the same server (a subprocess with ``latency_ms`` per Infer, like a remote model).
The official SDK has one blocking session per client, so 16 sessions are stepped in turn; our
SessionPool steps all 16 concurrently over one channel. The official client runs in its own
subprocess (its protobuf symbols clash with ours in one process). Target: pool >= 10x.

Usage: ``python benchmarks/pool_vs_official.py [--sessions 16 --latency-ms 100 --seconds 6]``;
prints JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

PROMPT = "a quiet suburban road"


def official_worker(endpoint: str, sessions: int, seconds: float) -> dict:
    """Step ``sessions`` official clients round-robin for about ``seconds`` (subprocess side)."""
    from decart_oasis import A2VClient

    rng = np.random.default_rng(0)
    clients = [A2VClient(endpoint) for _ in range(sessions)]
    try:
        for client in clients:
            client.initialize()
            client.prompt(PROMPT)
            client.infer(np.zeros((4, 2), np.float32))  # warm-up
        rounds = 0
        started = time.perf_counter()
        while time.perf_counter() - started < seconds:
            for client in clients:
                client.infer(rng.uniform(-1, 1, size=(4, 2)).astype(np.float32))
            rounds += 1
        elapsed = time.perf_counter() - started
    finally:
        for client in clients:
            client.close()
    return {"session_steps_per_s": round(rounds * sessions / elapsed, 2), "rounds": rounds}


def pool_run(endpoint: str, api_key: str, sessions: int, seconds: float) -> dict:
    """Step one SessionPool of ``sessions`` for about ``seconds``."""
    from oasis_torchrl.client import SessionPool

    rng = np.random.default_rng(0)
    with SessionPool(endpoint, sessions, api_key=api_key) as pool:
        pool.reset(None, [PROMPT] * sessions)
        steps = 0
        started = time.perf_counter()
        while time.perf_counter() - started < seconds:
            pool.infer(rng.uniform(-1, 1, size=(sessions, 4, 2)).astype(np.float32))
            steps += 1
        elapsed = time.perf_counter() - started
    return {"session_steps_per_s": round(steps * sessions / elapsed, 2), "rounds": steps}


def run_official_subprocess(endpoint: str, api_key: str, sessions: int, seconds: float) -> dict:
    command = [
        sys.executable,
        __file__,
        "--official-worker",
        "--endpoint",
        endpoint,
        "--sessions",
        str(sessions),
        "--seconds",
        str(seconds),
    ]
    environment = {**os.environ, "DECART_API_KEY": api_key}
    output = subprocess.run(command, env=environment, capture_output=True, text=True, check=True)
    return json.loads(output.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=16)
    parser.add_argument("--latency-ms", type=float, default=100.0)
    parser.add_argument("--width", type=int, default=96)
    parser.add_argument("--height", type=int, default=64)
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--endpoint", help=argparse.SUPPRESS)
    parser.add_argument("--official-worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.official_worker:
        print(json.dumps(official_worker(args.endpoint, args.sessions, args.seconds)))
        return

    from oasis_torchrl.sim.launcher import ServerProcess

    server = ServerProcess(width=args.width, height=args.height, latency_ms=args.latency_ms)
    with server:
        official = run_official_subprocess(
            server.endpoint, server.api_key, args.sessions, args.seconds
        )
        pool = pool_run(server.endpoint, server.api_key, args.sessions, args.seconds)
    report = {
        "server": {"width": args.width, "height": args.height, "latency_ms": args.latency_ms},
        "sessions": args.sessions,
        "official_sequential": official,
        "oasis_torchrl_pool": pool,
        "speedup": round(pool["session_steps_per_s"] / official["session_steps_per_s"], 2),
        "target_speedup": 10.0,
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
