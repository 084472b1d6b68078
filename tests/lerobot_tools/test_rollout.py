"""A person takes over from a policy with ``lerobot-rollout --strategy.type=dagger`` (real key
events), and LeRobot's async robot client drives the oasis robot with a policy served by
LeRobot's policy server."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from ._cli import STREAMING, Display, background, cli_env
from ._policies import act_folder

STARTUP_S = 300.0
ASYNC = "lerobot.async_inference"


@pytest.fixture(scope="module")
def act(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return act_folder(tmp_path_factory.mktemp("act") / "pretrained_model", n_action_steps=8)


@pytest.mark.timeout(1500)
def test_dagger_records_and_marks_a_takeover(act: Path, tmp_path: Path, display: Display) -> None:
    root = tmp_path / "dagger"
    args = [
        "--strategy.type=dagger",
        "--strategy.record_autonomous=true",
        "--robot.type=oasis",
        "--teleop.type=oasis_keyboard",
        f"--policy.path={act}",
        "--dataset.repo_id=local/rollout_dagger",
        f"--dataset.root={root}",
        "--dataset.single_task=urban",
        "--dataset.fps=20",
        "--dataset.push_to_hub=false",
        *STREAMING,
        "--fps=20",
        "--play_sounds=false",
    ]
    env = cli_env(tmp_path / "hf", DISPLAY=display.name)
    with background("lerobot-rollout", args, env, tmp_path / "rollout.log") as rollout:
        rollout.wait_for("DAgger continuous recording started", STARTUP_S)
        time.sleep(1.0)  # the policy drives
        display.keys("key", "space")
        rollout.wait_for("autonomous -> paused", STARTUP_S)
        display.keys("key", "Tab")
        rollout.wait_for("paused -> correcting", STARTUP_S)
        display.keys("keydown", "w")
        time.sleep(1.0)  # the person drives
        display.keys("key", "Tab")
        rollout.wait_for("correcting -> paused", STARTUP_S)
        display.keys("keyup", "w", "key", "space")
        rollout.wait_for("paused -> autonomous", STARTUP_S)
        time.sleep(0.5)
        display.keys("key", "Escape")
        rollout.finish(STARTUP_S)

    dataset = LeRobotDataset("local/rollout_dagger", root=root, video_backend="pyav")
    rows = dataset.hf_dataset
    intervention = torch.stack(list(rows["intervention"])).reshape(-1).numpy()
    action = torch.stack(list(rows["action"])).numpy()
    # policy frames, then the takeover, then the policy again
    changes = np.flatnonzero(np.diff(intervention.astype(int)))
    assert not intervention[0] and len(changes) == 2, intervention.tolist()
    taken_over = action[intervention]
    assert (taken_over == [1.0, 0.0]).all(-1).any()  # W held: full throttle, straight
    assert not (action[~intervention] == [1.0, 0.0]).all(-1).all()


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.mark.timeout(1500)
def test_lerobots_robot_client_drives_the_robot_with_a_served_policy(
    act: Path, tmp_path: Path
) -> None:
    from viz._readback import Readback

    port = _free_port()
    env = cli_env(tmp_path / "hf")
    server_args = ["--host=127.0.0.1", f"--port={port}", "--fps=20"]
    recording = tmp_path / "client.rrd"
    client_args = [
        "--robot.type=oasis",
        f"--robot.rerun={recording}",
        "--task=urban",
        f"--server_address=127.0.0.1:{port}",
        "--policy_type=act",
        f"--pretrained_name_or_path={act}",
        "--policy_device=cpu",
        "--actions_per_chunk=8",
        "--fps=20",
    ]
    server_log, client_log = tmp_path / "server.log", tmp_path / "client.log"
    server = background(f"{ASYNC}.policy_server", server_args, env, server_log)
    client = background(f"{ASYNC}.robot_client", client_args, env, client_log)
    with server as serving:
        serving.wait_for("PolicyServer started", STARTUP_S)
        with client as driving:
            driving.wait_for("Control loop thread starting", STARTUP_S)
            deadline = time.monotonic() + STARTUP_S
            while server_log.read_text().count("generated") < 3:  # action chunks served
                assert time.monotonic() < deadline, driving.tail()
                time.sleep(0.5)
            time.sleep(2.0)  # the client drives with the chunks
    _, throttle = Readback(recording).scalars("env/0/action/throttle")
    assert len(throttle) >= 8 and any(value != 0 for value in throttle)  # the policy drove
