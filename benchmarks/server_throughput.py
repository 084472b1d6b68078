"""Infer throughput of the embedded A2V server through a real loopback gRPC channel.

Measures Infer calls per second (each call: 4 simulated frames x 3 cameras, encoded) at
768x512 and 192x128, with 1 session and with 4 sessions driven concurrently from threads.
Prints one JSON document.

    .venv/bin/python benchmarks/server_throughput.py --seconds 5
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import grpc

from oasis_torchrl.proto import a2v_pb2, a2v_pb2_grpc, common_pb2, sim_pb2
from oasis_torchrl.sim.launcher import LocalServer

TRUTH_METADATA = "x-oasis-truth-bin"
RESOLUTIONS = ((768, 512), (192, 128))
SESSION_COUNTS = (1, 4)
WARMUP_CALLS = 3


class BenchSession:
    """One A2V session driven with raw stubs, sequence numbers tracked."""

    def __init__(self, stub: a2v_pb2_grpc.A2VServiceStub, api_key: str, index: int) -> None:
        request = a2v_pb2.InitializeRequest(
            client_sdk_version="oasis-torchrl-bench/0.1",
            api_key=api_key,
            accepted_output_formats=[common_pb2.FRAME_FORMAT_VP9],
        )
        response, call = stub.Initialize.with_call(request, metadata=[("x-api-key", api_key)])
        target = dict(call.initial_metadata())["x-session-target"]
        self.stub = stub
        self.session_id = response.session_id
        self.metadata = (("x-api-key", api_key), ("x-session-target", target))
        self.seed = index
        self.sequence_num = 0
        self.bytes_received = 0
        self.responses = 0
        self.restarts = 0
        self.prompt()

    def prompt(self) -> None:
        """(Re)start the rollout in this session's scene."""
        request = a2v_pb2.PromptRequest(session_id=self.session_id, prompt="a busy city street")
        self.stub.Prompt(request, metadata=(*self.metadata, ("x-oasis-seed", str(self.seed))))
        self.sequence_num = 0

    def infer(self) -> None:
        """One Infer with a gentle left-right weave; a crashed car starts over (as in RL)."""
        steering = 0.3 if self.sequence_num % 8 < 4 else -0.3
        request = a2v_pb2.InferRequest(
            session_id=self.session_id,
            sequence_num=self.sequence_num,
            actions=[a2v_pb2.Action(throttle=0.6, steering=steering)] * 4,
        )
        response, call = self.stub.Infer.with_call(request, metadata=self.metadata, timeout=60)
        if response.HasField("error"):
            raise RuntimeError(f"Infer failed: {response.error}")
        self.sequence_num += 1
        self.bytes_received += response.ByteSize()
        self.responses += 1
        truth = sim_pb2.InferTruth.FromString(dict(call.trailing_metadata())[TRUTH_METADATA])
        if truth.frames[-1].collided:
            self.restarts += 1
            self.prompt()


def measure(width: int, height: int, sessions: int, seconds: float) -> dict[str, float | int]:
    """Calls/s (and derived numbers) for ``sessions`` concurrent sessions at one resolution."""
    with (
        LocalServer(width=width, height=height, max_sessions=sessions + 1) as server,
        grpc.insecure_channel(server.address) as channel,
    ):
        stub = a2v_pb2_grpc.A2VServiceStub(channel)
        drivers = [BenchSession(stub, server.api_key, index) for index in range(sessions)]
        for driver in drivers:
            for _ in range(WARMUP_CALLS):
                driver.infer()
        counts = [0] * sessions
        deadline = threading.Event()

        def drive(index: int) -> None:
            while not deadline.is_set():
                drivers[index].infer()
                counts[index] += 1

        start = time.perf_counter()
        with ThreadPoolExecutor(sessions) as pool:
            futures = [pool.submit(drive, index) for index in range(sessions)]
            time.sleep(seconds)
            deadline.set()
            for future in futures:
                future.result()
        elapsed = time.perf_counter() - start
    calls = sum(counts)
    received = sum(d.bytes_received for d in drivers)
    return {
        "infer_calls_per_s": round(calls / elapsed, 2),
        "frames_per_s": round(calls * 4 * 3 / elapsed, 1),
        "mean_latency_ms": round(1000 * elapsed * sessions / max(calls, 1), 1),
        "mean_response_kib": round(received / sum(d.responses for d in drivers) / 1024, 1),
        "rollout_restarts": sum(d.restarts for d in drivers),
        "calls": calls,
    }


def main() -> None:
    """Run every resolution x session-count case and print the JSON report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="measuring time per case")
    args = parser.parse_args()
    load_before = os.getloadavg()[0]  # other work on the machine skews every number
    results = {
        f"{width}x{height}": {
            f"{count}_session{'s' if count > 1 else ''}": measure(
                width, height, count, args.seconds
            )
            for count in SESSION_COUNTS
        }
        for width, height in RESOLUTIONS
    }
    report = {
        "benchmark": "server_throughput",
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "seconds_per_case": args.seconds,
        "load_average_1min_before": round(load_before, 2),
        "results": results,
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
