"""Recording the real env on the embedded server: rollouts, a collector hook and the CLI."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from torchrl.collectors import Collector

from oasis_torchrl.cli import main
from oasis_torchrl.commands._signals import sigterm_as_interrupt
from oasis_torchrl.data import LeRobotRecorder
from oasis_torchrl.drivers import Autopilot
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.config import ServerConfig

from ._readback import episodes, open_dataset, psnr

SERVER_KEY = "server-key-never-in-datasets"
USER_KEY = "user-key-never-in-datasets"
PROMPTS = ["urban street", "rural road", "highway"]


@pytest.fixture
def small_server(monkeypatch: pytest.MonkeyPatch) -> ServerConfig:
    monkeypatch.setenv("DECART_API_KEY", USER_KEY)
    return ServerConfig(width=64, height=48, api_keys=(SERVER_KEY,))


def _split(rollout: torch.Tensor, row: int) -> list[tuple[int, int]]:
    """``(first, last + 1)`` steps of each episode of env row ``row`` (cut after done)."""
    done = rollout["next", "done"][row, :, 0].tolist()
    bounds, start = [], 0
    for step, flag in enumerate(done):
        if flag:
            bounds.append((start, step + 1))
            start = step + 1
    if start < len(done):
        bounds.append((start, len(done)))
    return bounds


def _assert_no_secrets(root: Path) -> None:
    for path in root.rglob("*"):
        if path.is_file():
            data = path.read_bytes()
            assert SERVER_KEY.encode() not in data and USER_KEY.encode() not in data, path


def test_rollout_round_trip_on_the_embedded_server(tmp_path: Path, small_server) -> None:
    env = OasisEnv(
        "local", 3, PROMPTS, server=small_server, all_frames=True, max_steps=3, expert=True
    )
    try:
        rollout = env.rollout(8, Autopilot(), break_when_any_done=False)
    finally:
        env.close()
    root = tmp_path / "rollouts"
    with LeRobotRecorder(root) as recorder:  # two batches: episodes continue across them
        recorder.write(rollout[:, :4])
        recorder.write(rollout[:, 4:])
    dataset = open_dataset(root)
    stored = episodes(dataset)
    ended = rollout["next", "done"][:, :, 0]
    expected = sorted(  # saved as they end (by step, then row), the unfinished ones at close
        ((end, row, start) for row in range(3) for start, end in _split(rollout, row)),
        key=lambda item: (not ended[item[1], item[0] - 1], item[0], item[1]),
    )
    assert len(stored) == len(expected) == dataset.num_episodes == 9
    scores = []
    for episode, (end, row, start) in zip(stored, expected, strict=True):
        steps = rollout[row, start:end]
        assert episode.task == PROMPTS[row]
        assert episode.stop - episode.start == 4 * (end - start)
        np.testing.assert_array_equal(episode.columns["action"], steps["action"].reshape(-1, 2))
        done = np.zeros(4 * (end - start), bool)
        done[3::4] = steps["next", "done"][:, 0].numpy()
        np.testing.assert_array_equal(episode.columns["next.done"], done)
        sample = dataset[episode.start + 2]  # row 2 shows f1 of the first chunk
        original = steps["next", "pixels", "front"][0, 1].numpy()
        scores.append(psnr(sample["observation.images.front"], original))
    # Frames arrive raw (exactly as rendered, sharper than VP9-decoded ones), so LeRobot's h264
    # at 96x64 keeps about 25-30 dB of them.
    assert min(scores) > 23.0, scores
    _assert_no_secrets(root)


def test_collector_hook_records_as_training_goes(tmp_path: Path, small_server) -> None:
    env = OasisEnv("local", 2, server=small_server, max_steps=3, expert=True)
    recorder = LeRobotRecorder(tmp_path / "collected", keep_unfinished=False)
    collector = Collector(
        env, Autopilot(), frames_per_batch=8, total_frames=24, post_collect_hook=recorder
    )
    try:
        for _ in collector:
            pass
    finally:
        collector.shutdown()
        recorder.close()
    dataset = open_dataset(tmp_path / "collected")
    assert dataset.fps == 5 and dataset.num_episodes == 8  # 12 steps per row, 3 per episode
    assert all(e.stop - e.start == 3 for e in episodes(dataset))
    assert dataset.meta.features["action"]["shape"] == (8,)


def test_record_cli_writes_and_appends(tmp_path: Path, small_server) -> None:
    root = tmp_path / "cli"
    common = ["--root", str(root), "--num-envs", "2", "--width", "64", "--height", "48"]
    scripted = ["--driver", "scripted", "--script", "throttle=0.6,steering=sine:0.3:16"]
    assert main(["record", *common, "--episodes", "3", "--max-steps", "2", *scripted]) == 0
    assert main(["record", *common, "--episodes", "1", "--max-steps", "2", "--append"]) == 0
    assert main(["record", *common, "--episodes", "1"]) == 2  # exists, no --append
    assert main(["record", *common, "--episodes", "1", "--append", "crf=60"]) == 2  # h264: 0-51
    dataset = open_dataset(root)
    assert dataset.num_episodes == 4 and dataset.num_frames == 4 * 8
    first = dataset[1]["action"]  # frame 1 of the scripted chunk: sin(2 pi / 16) * 0.3
    assert first.tolist() == pytest.approx([0.6, 0.3 * np.sin(2 * np.pi / 16)], abs=1e-6)
    _assert_no_secrets(root)


def _episodes_saved(root: Path) -> int:
    try:
        return json.loads((root / "meta" / "info.json").read_text())["total_episodes"]
    except (FileNotFoundError, json.JSONDecodeError):  # not there yet, or being rewritten
        return 0


def test_ctrl_c_while_recording_keeps_a_readable_dataset(tmp_path: Path) -> None:
    root = tmp_path / "interrupted"
    command = [sys.executable, "-m", "oasis_torchrl", "record", "--root", str(root)]
    command += ["--episodes", "1000", "--width", "64", "--height", "48", "--max-steps", "2"]
    process = subprocess.Popen(
        command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    deadline = time.monotonic() + 120
    while _episodes_saved(root) < 2:
        assert process.poll() is None and time.monotonic() < deadline, process.stderr.read()
        time.sleep(0.2)
    process.send_signal(signal.SIGINT)  # lands mid-episode or mid-save; both must be safe
    _, errors = process.communicate(timeout=180)  # finalizing under a loaded machine
    assert process.returncode == 130, errors[-3000:]
    dataset = open_dataset(root)
    assert dataset.num_episodes >= 2
    assert all(episode.stop - episode.start == 8 for episode in episodes(dataset))
    assert not list(tmp_path.glob(".interrupted-spill-*"))


def test_sigterm_stops_a_writing_command_like_ctrl_c() -> None:
    with pytest.raises(KeyboardInterrupt), sigterm_as_interrupt():
        os.kill(os.getpid(), signal.SIGTERM)
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL
