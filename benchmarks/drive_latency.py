"""Key-to-frame latency of the drive page (``oasis-torchrl play``) on loopback, and the page
server's CPU per driven chunk, against the world's chunk period (4 frames at 20 fps: 200 ms).

For each frame size, ``oasis-torchrl play`` runs in a process of its own on the embedded server
(no recording) and this script connects to its WebSocket as the page does. At random moments
(uncorrelated with the chunk slots) it sends a new input, as a key press does, and times the
arrival of the first frame of the first chunk driven with it: the wait for the next chunk slot,
the world's step, the frame encoding and the transfer. The page's own JPEG decoding and drawing
(a few milliseconds in a browser) is not included.

CPU: user + system seconds per driven chunk of the page server's process (decoding the world's
VP9, encoding 12 JPEGs, the socket) and, apart, of the embedded world's processes (the
simulator and its encoder, which the hosted model replaces), each also as a fraction of the
chunk period (1.0: one core busy full time).

Usage: ``python benchmarks/drive_latency.py [--sizes 192x128 768x512 --presses 40]``; prints JSON.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import random
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import aiohttp
import numpy as np
from _process_cpu import process_cpu_seconds

from oasis_torchrl.web.frames import unpack_frames

PERIOD_MS = 200.0
WARMUP_CHUNKS = 10
STARTUP_S = 300.0


def start_page(width: int, height: int, log: Path) -> tuple[subprocess.Popen, str]:
    """``oasis-torchrl play`` on a free loopback port; returns the process and its socket URL."""
    args = ["play", "port=0", f"env.server.width={width}", f"env.server.height={height}"]
    with log.open("w") as out:
        process = subprocess.Popen(
            [sys.executable, "-m", "oasis_torchrl", *args], stdout=out, stderr=subprocess.STDOUT
        )
    deadline = time.monotonic() + STARTUP_S
    while (found := re.search(r"drive the world model at (\S+)", log.read_text())) is None:
        if process.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"the page did not start:\n{log.read_text()[-2000:]}")
        time.sleep(0.2)
    return process, found[1].replace("http", "ws", 1) + "ws"


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (the embedded server and its workers), whichever thread
    started it (the page's world opens on a thread of its own)."""
    found = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        children = task / "children"
        for child in map(int, children.read_text().split() if children.exists() else ()):
            found += [child, *descendants(child)]
    return found


def cpu_seconds(pid: int) -> tuple[float, float]:
    """CPU seconds so far of the page server's process and of its descendants (the world)."""
    world = sum(process_cpu_seconds(child) or 0.0 for child in descendants(pid))
    return process_cpu_seconds(pid) or 0.0, world


async def drive(url: str, presses: int, pid: int, seed: int) -> dict[str, float]:
    """Press ``presses`` times at random moments; latencies and CPU per chunk."""
    rng = random.Random(seed)
    latencies, seq, status = [], 0, {}
    async with aiohttp.ClientSession() as client, client.ws_connect(url, max_msg_size=0) as ws:

        async def next_header(kind: str) -> dict:
            """The next frame header (``"frame"``) or status (``"status"``); the latest status
            is kept either way."""
            nonlocal status
            while True:
                message = await ws.receive(timeout=60)
                if message.type == aiohttp.WSMsgType.BINARY:
                    if kind == "frame":
                        return unpack_frames(message.data)[0]
                    continue
                status = json.loads(message.data)
                if kind == "status":
                    return status

        await ws.send_json({"type": "control", "throttle": 0.0, "steering": 0.0, "seq": 0})
        while (await next_header("status"))["chunk"] < WARMUP_CHUNKS:
            pass
        cpu_start, chunk_start, late_start = cpu_seconds(pid), status["chunk"], status["late"]
        for _ in range(presses):
            await asyncio.sleep(rng.uniform(0.25, 0.65))
            seq += 1
            throttle = round(rng.uniform(0.1, 0.6), 2)
            await ws.send_json(
                {"type": "control", "throttle": throttle, "steering": 0.0, "seq": seq}
            )
            sent = time.perf_counter()
            while (await next_header("frame"))["seq"] < seq:
                pass
            latencies.append(1000 * (time.perf_counter() - sent))
        await next_header("status")
        page_cpu, world_cpu = np.subtract(cpu_seconds(pid), cpu_start)
        chunks = max(status["chunk"] - chunk_start, 1)
    p50, p95 = np.percentile(latencies, [50, 95])
    return {
        "key_to_frame_p50_ms": round(float(p50), 1),
        "key_to_frame_p95_ms": round(float(p95), 1),
        "p50_over_period": round(float(p50) / PERIOD_MS, 2),
        "p95_over_period": round(float(p95) / PERIOD_MS, 2),
        "page_server_cpu_ms_per_chunk": round(1000 * page_cpu / chunks, 1),
        "page_server_cpu_over_period": round(1000 * page_cpu / chunks / PERIOD_MS, 3),
        "world_cpu_ms_per_chunk": round(1000 * world_cpu / chunks, 1),
        "chunks": chunks,
        "late_chunks": status["late"] - late_start,
        "presses": presses,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", nargs="+", default=["192x128", "768x512"], metavar="WxH")
    parser.add_argument("--presses", type=int, default=40)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    results = {"chunk_period_ms": PERIOD_MS}
    with tempfile.TemporaryDirectory() as scratch:
        for size in args.sizes:
            width, height = (int(part) for part in size.split("x"))
            process, url = start_page(width, height, Path(scratch) / f"{size}.log")
            try:
                results[size] = asyncio.run(drive(url, args.presses, process.pid, args.seed))
            finally:
                process.terminate()
                process.wait(timeout=60)
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
