"""A killed ``oasis-torchrl play`` keeps every episode saved before: the dataset reads back."""

from __future__ import annotations

import asyncio
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import aiohttp
import pytest
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from ._socket import next_json

STARTUP_S = 300.0


def _url(log: Path, process: subprocess.Popen) -> str:
    deadline = time.monotonic() + STARTUP_S
    while (found := re.search(r"drive the world model at (\S+)", log.read_text())) is None:
        assert process.poll() is None, log.read_text()[-3000:]
        assert time.monotonic() < deadline, "the page did not start"
        time.sleep(0.2)
    return found[1]


async def _record(url: str) -> None:
    """Save one episode, then start another and leave it running."""
    async with aiohttp.ClientSession() as client, client.ws_connect(url) as socket:

        async def command(name: str, statuses: int) -> None:
            await socket.send_json({"type": "record", "command": name})
            seen, done = 0, False
            while not done or seen < statuses:
                message = await next_json(socket)
                assert message["type"] != "error", message
                done = done or message["type"] == "done"
                seen += message["type"] == "status" and done

        await socket.send_json({"type": "control", "throttle": 0.5, "steering": 0.0, "seq": 1})
        await command("start", statuses=3)
        await command("stop", statuses=1)
        await command("start", statuses=3)


@pytest.mark.timeout(900)
def test_a_killed_page_server_keeps_the_saved_episodes(tmp_path: Path) -> None:
    root, log = tmp_path / "drives", tmp_path / "play.log"
    args = ["play", f"root={root}", "port=0", "env.server.width=96", "env.server.height=64"]
    with log.open("w") as out:
        process = subprocess.Popen(
            [sys.executable, "-m", "oasis_torchrl", *args], stdout=out, stderr=subprocess.STDOUT
        )
    try:
        url = _url(log, process)  # loopback: no token
        asyncio.run(_record(url.replace("http", "ws", 1) + "ws"))
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait(timeout=60)
    dataset = LeRobotDataset("local/drives", root=root, video_backend="pyav")
    assert dataset.num_episodes == 1
    assert dataset[dataset.num_frames - 1]["observation.images.front"].shape == (3, 64, 96)
