"""A served policy: batched server vs one request at a time, and the per-call overhead.

Policy servers (:class:`~oasis_torchrl.serving.server.PolicyServer`, each in a process of its
own, one torch thread) serve our driving network from a LeRobot folder (3 cameras x 2 frames
of 64x96) in two ways:

- ``cpu``: as it is, on this machine's CPU, where a forward pass costs about the same per
  row at any batch size (convolutions dominate): batching can only save the per-call work;
- ``gpu_like``: every forward pass takes at least ``--gpu-ms`` (the network still runs), as
  on a GPU where a pass over 1 or 64 rows costs about the same; what batching is for.

For each, one server merges concurrent requests into one forward pass (the default) and one
runs every request alone (``batch_rows=1``). ``--sessions`` clients (one ``RemotePolicy``
each, in threads) ask for one chunk after another (one row each) for ``--seconds``; the rate
is chunks per second over all clients, rounds alternating the two servers.

Per-call overhead: one client, one row, the same ``PolicyDriver`` called in this process vs
``RemotePolicy.predict_action_chunk`` on the ``cpu`` batched server, alternating.

Usage: ``python benchmarks/remote_policy.py [--sessions 16 --seconds 5 --rounds 2]``; prints
JSON. Target: batched >= 4x one request at a time (``gpu_like``).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import multiprocessing
import os
import statistics
import tempfile
import threading
import time
from collections.abc import Iterator
from functools import partial
from pathlib import Path

import torch
from tensordict import TensorDictBase

from oasis_torchrl.config.policy_serving import PolicyServerConfig
from oasis_torchrl.drivers import Driver, PolicyDriver
from oasis_torchrl.drivers.folders import export_lerobot
from oasis_torchrl.models import DrivingNet
from oasis_torchrl.remote import RemotePolicy
from oasis_torchrl.remote.features import as_tensordict
from oasis_torchrl.serving.served import ServedPolicy
from oasis_torchrl.serving.server import PolicyServer

KEY = "benchmark-key"


class AtLeast(Driver):
    """A driver whose every call takes at least ``seconds``, whatever its rows (the network
    still runs): a policy on a GPU, as the embedded A2V server's ``latency_ms`` emulates the
    hosted model."""

    def __init__(self, inner: PolicyDriver, seconds: float) -> None:
        super().__init__()
        self.inner = inner
        self.seconds = seconds
        self.image_size, self.observation_spec = inner.image_size, inner.observation_spec

    def chunks(self, td: TensorDictBase) -> torch.Tensor:
        began = time.perf_counter()
        chunk = self.inner.chunks(td)
        time.sleep(max(0.0, self.seconds - (time.perf_counter() - began)))
        return chunk


def load(folder: Path, gpu_ms: float) -> ServedPolicy:
    """The served policy: the folder's network, padded to ``gpu_ms`` per call if set."""
    driver = PolicyDriver.load(folder)
    return ServedPolicy.of_driver(AtLeast(driver, gpu_ms / 1000) if gpu_ms else driver, "bench")


def serve(folder: Path, gpu_ms: float, settings: dict, ports: multiprocessing.Queue) -> None:
    """A policy server process: reports its port, serves until terminated."""
    torch.set_num_threads(1)
    config = PolicyServerConfig(api_keys=(KEY,), **settings)
    server = PolicyServer(config, partial(load, folder, gpu_ms))
    server.start()
    server.wait_until_loaded()
    ports.put(server.port)
    threading.Event().wait()


@contextlib.contextmanager
def policy_server(folder: Path, gpu_ms: float, **settings: float) -> Iterator[str]:
    """A policy server (``PolicyServerConfig`` settings) in a process of its own; yields its
    endpoint."""
    context = multiprocessing.get_context("spawn")
    ports = context.Queue()
    process = context.Process(target=serve, args=(folder, gpu_ms, settings, ports), daemon=True)
    process.start()
    try:
        yield f"grpc://127.0.0.1:{ports.get(timeout=300)}"
    finally:
        process.terminate()
        process.join(30)


def chunks_per_second(endpoint: str, sessions: int, seconds: float) -> float:
    """Chunks per second ``sessions`` concurrent clients get, one row per request."""
    clients = [RemotePolicy(endpoint, api_key=KEY) for _ in range(sessions)]
    observations = [client.sample_input(1, seed=index) for index, client in enumerate(clients)]
    for client, observation in zip(clients, observations, strict=True):
        client.predict_action_chunk(observation)  # warm-up
    counts = [0] * sessions
    start = threading.Barrier(sessions + 1)
    stop = threading.Event()

    def ask(index: int) -> None:
        start.wait()
        while not stop.is_set():
            clients[index].predict_action_chunk(observations[index])
            counts[index] += 1

    threads = [threading.Thread(target=ask, args=(index,)) for index in range(sessions)]
    for thread in threads:
        thread.start()
    start.wait()
    began = time.perf_counter()
    time.sleep(seconds)
    stop.set()
    for thread in threads:
        thread.join()
    elapsed = time.perf_counter() - began
    for client in clients:
        client.close()
    return sum(counts) / elapsed


def batching_speedup(folder: Path, gpu_ms: float, args: argparse.Namespace) -> dict:
    """Chunks per second of the batched server and of the one-request-at-a-time one."""
    rates: dict[str, list[float]] = {"one_at_a_time": [], "batched": []}
    with (
        policy_server(folder, gpu_ms, batch_wait_ms=args.batch_wait_ms) as batched,
        policy_server(folder, gpu_ms, batch_rows=1) as alone,
    ):
        for _ in range(args.rounds):
            for name, endpoint in (("one_at_a_time", alone), ("batched", batched)):
                rates[name].append(chunks_per_second(endpoint, args.sessions, args.seconds))
    means = {name: statistics.mean(values) for name, values in rates.items()}
    return {
        "chunks_per_s": {name: [round(v, 1) for v in values] for name, values in rates.items()},
        "batched_over_one_at_a_time": round(means["batched"] / means["one_at_a_time"], 2),
    }


def call_overhead(folder: Path, calls: int) -> dict[str, float]:
    """Median ms of one one-row chunk: in this process vs through the server."""
    driver = PolicyDriver.load(folder)
    with (
        policy_server(folder, 0.0) as endpoint,
        RemotePolicy(endpoint, api_key=KEY) as remote,
    ):
        observation = remote.sample_input(1, seed=0)
        local_input = as_tensordict(observation, rows=1)
        timings: dict[str, list[float]] = {"in_process": [], "remote": []}
        for _ in range(calls):
            for name, call in (
                ("in_process", lambda: driver(local_input.clone())),
                ("remote", lambda: remote.predict_action_chunk(observation)),
            ):
                began = time.perf_counter()
                call()
                timings[name].append(1000 * (time.perf_counter() - began))
    local, served = (statistics.median(timings[name]) for name in ("in_process", "remote"))
    return {
        "in_process_ms": round(local, 2),
        "remote_ms": round(served, 2),
        "overhead_ms": round(served - local, 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=16)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--gpu-ms", type=float, default=20.0)
    parser.add_argument("--batch-wait-ms", type=float, default=PolicyServerConfig.batch_wait_ms)
    parser.add_argument("--overhead-calls", type=int, default=100)
    args = parser.parse_args()
    # One thread everywhere: on a loaded 2-core machine, torch's default (one per core, in
    # every process) makes OpenMP threads wait on each other and every call slow.
    torch.set_num_threads(1)
    torch.manual_seed(0)
    with tempfile.TemporaryDirectory() as scratch:
        folder = export_lerobot(DrivingNet(), Path(scratch) / "policy")
        report = {
            "policy": "DrivingNet from a LeRobot folder, 3 cameras x 2 frames of 64x96",
            "sessions": args.sessions,
            "batch_wait_ms": args.batch_wait_ms,
            "cpus": os.cpu_count(),
            "gpu_like": {
                "forward_ms_at_least": args.gpu_ms,
                **batching_speedup(folder, args.gpu_ms, args),
            },
            "cpu": batching_speedup(folder, 0.0, args),
            "per_call": call_overhead(folder, args.overhead_calls),
            "target": "gpu_like: batched >= 4x one request at a time",
        }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
