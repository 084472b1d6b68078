"""Running LeRobot's command-line tools as subprocesses, and a virtual X display to type into.

LeRobot's tools import the plugins by distribution name (``lerobot_robot_oasis``, ...), which
``make`` installs; the subprocesses inherit this process's environment, offline.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest

VENV_BIN = Path(sys.executable).parent
STREAMING = (
    "--dataset.rgb_encoder.vcodec=h264",
    "--dataset.streaming_encoding=true",
    "--dataset.encoder_threads=1",
    "--dataset.encoder_queue_maxsize=200",
)
"""Dataset flags: encode while recording (saving an episode otherwise starts a process per
camera, each importing torch) into h264, which encodes fast."""


def cli_env(home: Path, **extra: str) -> dict[str, str]:
    """The environment of a tool: offline, with its own Hugging Face home (datasets,
    calibration files), no sounds."""
    return {**os.environ, "HF_HUB_OFFLINE": "1", "HF_HOME": str(home), **extra}


def command(tool: str, *args: str) -> list[str]:
    """A console script of this environment (``lerobot-record``, ...) or ``python -m module``."""
    if "." in tool:
        return [sys.executable, "-m", tool, *args]
    return [str(VENV_BIN / tool), *args]


def run_tool(
    tool: str, args: Sequence[str], env: dict[str, str], timeout: float
) -> subprocess.CompletedProcess:
    """Run a tool to its end; fail the test with the end of its output unless it exits 0."""
    done = subprocess.run(
        command(tool, *args), env=env, capture_output=True, text=True, timeout=timeout
    )
    assert done.returncode == 0, f"{tool} exited {done.returncode}:\n{done.stderr[-4000:]}"
    return done


@dataclass
class Tool:
    """A tool running in the background, its output going to ``log``."""

    process: subprocess.Popen
    log: Path

    def wait_for(self, pattern: str, timeout: float) -> None:
        """Wait until the tool's output matches ``pattern`` (fail if it exits or times out)."""
        deadline = time.monotonic() + timeout
        while not re.search(pattern, self.log.read_text(errors="replace")):
            if self.process.poll() is not None:
                pytest.fail(f"exited {self.process.returncode} before {pattern!r}:\n{self.tail()}")
            if time.monotonic() > deadline:
                pytest.fail(f"no {pattern!r} within {timeout:.0f} s:\n{self.tail()}")
            time.sleep(0.05)

    def finish(self, timeout: float) -> None:
        """Wait for a normal exit (fail with the output's end otherwise)."""
        try:
            code = self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            pytest.fail(f"still running after {timeout:.0f} s:\n{self.tail()}")
        assert code == 0, f"exited {code}:\n{self.tail()}"

    def tail(self) -> str:
        return self.log.read_text(errors="replace")[-4000:]


@contextmanager
def background(tool: str, args: Sequence[str], env: dict[str, str], log: Path) -> Iterator[Tool]:
    """Start a tool in the log's folder (LeRobot's async tools write ``logs/`` where they run);
    it is stopped (interrupted, then killed) if still running at the end."""
    with log.open("w") as out:
        process = subprocess.Popen(
            command(tool, *args), env=env, stdout=out, stderr=subprocess.STDOUT, cwd=log.parent
        )
    try:
        yield Tool(process, log)
    finally:
        if process.poll() is None:
            process.send_signal(subprocess.signal.SIGINT)
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


@dataclass(frozen=True)
class Display:
    """A virtual X display (Xvfb) that tools read the keyboard from."""

    name: str

    def keys(self, *actions: str) -> None:
        """Real key events, e.g. ``keys("keydown", "w")`` or ``keys("key", "Tab")``."""
        subprocess.run(["xdotool", *actions], env={**os.environ, "DISPLAY": self.name}, check=True)
