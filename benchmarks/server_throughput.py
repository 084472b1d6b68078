"""Infer throughput of the embedded A2V server through a real loopback gRPC channel.

Measures Infer calls per second (each call: 4 simulated frames x 3 cameras, VP9-encoded, as
the official client gets them) at 768x512 and 192x128, with 1 session and with 4 sessions
driven concurrently from threads, against a server process with ``--processes`` worker
processes (default 2). Prints one JSON document with the ratio 4 sessions / 1 session.

    .venv/bin/python benchmarks/server_throughput.py --seconds 5 --processes 2 --repeats 3

With ``--repeats`` the two session counts alternate and the ratio is of their medians.
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
import numpy as np

from oasis_torchrl.proto import a2v_pb2, a2v_pb2_grpc, common_pb2, sim_pb2
from oasis_torchrl.protocol import (
    API_KEY_METADATA,
    SEED_METADATA,
    SESSION_TARGET_METADATA,
    TRUTH_METADATA,
)
from oasis_torchrl.sim.launcher import ServerProcess

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
        response, call = stub.Initialize.with_call(request, metadata=[(API_KEY_METADATA, api_key)])
        target = dict(call.initial_metadata())[SESSION_TARGET_METADATA]
        self.stub = stub
        self.session_id = response.session_id
        self.metadata = ((API_KEY_METADATA, api_key), (SESSION_TARGET_METADATA, target))
        self.seed = index
        self.sequence_num = 0
        self.bytes_received = 0
        self.responses = 0
        self.restarts = 0
        self.prompt()

    def prompt(self) -> None:
        """(Re)start the rollout in this session's scene."""
        request = a2v_pb2.PromptRequest(session_id=self.session_id, prompt="a busy city street")
        self.stub.Prompt(request, metadata=(*self.metadata, (SEED_METADATA, str(self.seed))))
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


def measure(
    width: int, height: int, sessions: int, seconds: float, processes: int
) -> dict[str, float | int]:
    """Calls/s (and derived numbers) for ``sessions`` concurrent sessions at one resolution."""
    with (
        ServerProcess(width=width, height=height, processes=processes) as server,
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
    parser.add_argument("--processes", type=int, default=2, help="server worker processes")
    parser.add_argument(
        "--repeats", type=int, default=1, help="measurements per case, alternating 1 and 4"
    )
    args = parser.parse_args()
    load_before = os.getloadavg()[0]  # other work on the machine skews every number
    results = {}
    for width, height in RESOLUTIONS:
        runs: dict[int, list[dict[str, float | int]]] = {count: [] for count in SESSION_COUNTS}
        for repeat in range(args.repeats):  # alternating: both counts see the same load
            counts = SESSION_COUNTS if repeat % 2 == 0 else SESSION_COUNTS[::-1]
            for count in counts:
                runs[count].append(measure(width, height, count, args.seconds, args.processes))
        rates = {count: [run["infer_calls_per_s"] for run in runs[count]] for count in runs}
        single, many = (float(np.median(rates[count])) for count in SESSION_COUNTS)
        results[f"{width}x{height}"] = {
            **{
                f"{count}_session{'s' if count > 1 else ''}": measured[-1]
                for count, measured in runs.items()
            },
            **{f"infer_calls_per_s_{count}": rates[count] for count in SESSION_COUNTS},
            "ratio_4_over_1": round(many / single, 2),
        }
    report = {
        "benchmark": "server_throughput",
        "cpus": os.cpu_count(),
        "processes": args.processes,
        "python": platform.python_version(),
        "seconds_per_case": args.seconds,
        "load_average_1min_before": round(load_before, 2),
        "results": results,
        "target": "192x128: 4 sessions >= 1.7x one session with 2 processes",
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
