"""Plain saved modules (TorchScript) served with declared inputs: a policy that raises fails
only the requests it raised on, and ``oasis-torchrl serve-policy`` runs as a command that
``record --driver policy --policy grpc://...`` drives with."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from oasis_torchrl.client.retry import RetryPolicy
from oasis_torchrl.commands import record as record_command
from oasis_torchrl.config import load_config
from oasis_torchrl.remote import PolicyError, RemotePolicy
from oasis_torchrl.remote.features import Feature
from oasis_torchrl.serving.served import load_served_policy
from oasis_torchrl.serving.server import PolicyServer

from .conftest import KEYS

ROOT = Path(__file__).resolve().parents[2]


class HalfState(torch.nn.Module):
    """Drives at half its previous action; refuses a state whose throttle is above 0.8."""

    def forward(self, state: torch.Tensor) -> torch.Tensor:
        if bool((state[:, 0] > 0.8).any()):
            raise ValueError("throttle above 0.8")
        return (0.5 * state + 0.2).unsqueeze(1).expand(-1, 4, 2)


@pytest.fixture(scope="module")
def scripted_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("plain") / "half_state.pt"
    torch.jit.save(torch.jit.script(HalfState()), str(path))
    return path


def test_a_policy_that_raises_fails_only_its_request(
    server_factory: Callable[..., PolicyServer], scripted_file: Path
) -> None:
    inputs = [Feature.parse("state:float32:2")]
    server = server_factory(
        lambda: load_served_policy(str(scripted_file), inputs), batch_wait_ms=300
    )
    policy = RemotePolicy(server.endpoint, api_key=KEYS[0], retry=RetryPolicy.never())
    assert [feature.describe() for feature in policy.description.inputs] == ["state: float32 [2]"]
    good, bad = {"state": torch.full((2, 2), 0.4)}, {"state": torch.full((1, 2), 0.9)}
    with ThreadPoolExecutor(3) as pool:  # at once: merged or not, only the bad one fails
        answers = [pool.submit(policy.predict_action_chunk, o) for o in (good, bad, good)]
    assert torch.allclose(answers[0].result(), torch.full((2, 4, 2), 0.4))
    assert torch.allclose(answers[2].result(), torch.full((2, 4, 2), 0.4))
    with pytest.raises(PolicyError, match="the policy raised") as caught:
        answers[1].result()
    assert "throttle above 0.8" in str(caught.value)
    assert server.host.stats["requests"] == 3
    assert torch.allclose(policy.select_action(good), torch.full((2, 2), 0.4))  # still serving


def test_serve_policy_command_drives_a_recording(
    scripted_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    port_file = tmp_path / "port"
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "policies")]),
        "OASIS_POLICY_SERVER_API_KEYS": KEYS[0],
    }
    command = [sys.executable, "-m", "oasis_torchrl", "serve-policy", str(scripted_file)]
    flags = ["--input", "state:float32:2", "--port-file", str(port_file), "--grace", "0"]
    server = subprocess.Popen([*command, *flags], env=env, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not port_file.exists():
            assert server.poll() is None, server.stderr.read()
            assert time.monotonic() < deadline, "the server did not start"
            time.sleep(0.1)
        endpoint = f"grpc://127.0.0.1:{port_file.read_text().strip()}"
        monkeypatch.setenv("OASIS_POLICY_API_KEY", KEYS[0])
        root = tmp_path / "drives"
        settings = [
            f"root={root}",
            "driver=policy",
            f"policy={endpoint}",
            "episodes=1",
            "rows=chunk",
            "env.num_envs=1",
            "env.max_steps=3",
            "env.server.width=64",
            "env.server.height=48",
        ]
        assert record_command.run(load_config("record", settings)) == 0
    finally:
        server.send_signal(signal.SIGTERM)
        assert server.wait(60) == 0, server.stderr.read()
    actions = LeRobotDataset("local/drives", root=root)[1]["action"]
    # One row per chunk: the second chunk is half the first one's last action, plus 0.2.
    assert torch.allclose(actions, torch.full((8,), 0.5 * 0.2 + 0.2))
