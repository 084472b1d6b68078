"""RemotePolicy: LeRobot-style inference, action queues and their reset, typed errors, and
driving the world model exactly as the same policy does in-process."""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from pathlib import Path

import pytest
import torch
from torchrl.envs import TransformedEnv
from torchrl.envs.utils import ExplorationType, set_exploration_type

from oasis_torchrl.client.retry import RetryPolicy
from oasis_torchrl.commands import eval as eval_command
from oasis_torchrl.config import load_config
from oasis_torchrl.drivers import PolicyDriver, load_driver
from oasis_torchrl.envs import ChunkFrameStack, OasisEnv
from oasis_torchrl.remote import (
    AuthError,
    InvalidInputError,
    RateLimitError,
    RemotePolicy,
    UnavailableError,
)
from oasis_torchrl.remote.features import as_tensordict
from oasis_torchrl.serving.server import PolicyServer
from oasis_torchrl.sim.config import ServerConfig

from .conftest import KEYS


def test_select_action_serves_each_rows_chunk_and_reset_starts_a_new_one(
    policy_server: PolicyServer,
) -> None:
    with RemotePolicy(policy_server.endpoint, api_key=KEYS[0]) as policy:
        first, second = policy.sample_input(3, seed=1), policy.sample_input(3, seed=2)
        chunks = {1: policy.predict_action_chunk(first), 2: policy.predict_action_chunk(second)}
        assert not torch.equal(chunks[1], chunks[2])
        # The queue serves the chunk of the observation that started it, whatever comes next.
        served = [policy.select_action(first if step == 0 else second) for step in range(4)]
        assert torch.equal(torch.stack(served, dim=1), chunks[1])
        assert torch.equal(policy.select_action(second), chunks[2][:, 0])  # queue ran out
        policy.reset(rows=[1])
        mixed = policy.select_action(first)
        # Row 1 restarted from `first` (in a forward pass of its own: equal up to rounding).
        torch.testing.assert_close(mixed[1], chunks[1][1, 0], rtol=0, atol=1e-6)
        assert torch.equal(mixed[[0, 2]], chunks[2][[0, 2], 1])  # the others went on
        policy.reset()
        assert torch.equal(policy.select_action(first), chunks[1][:, 0])

        # Sessions are per client and per key: neither touches this client's queues.
        with RemotePolicy(policy_server.endpoint, api_key=KEYS[0]) as other:
            assert torch.equal(other.select_action(second), chunks[2][:, 0])
        same_id_other_key = RemotePolicy(
            policy_server.endpoint, api_key=KEYS[1], session_id=policy.session_id
        )
        with same_id_other_key:
            assert torch.equal(same_id_other_key.select_action(second), chunks[2][:, 0])
        assert torch.equal(policy.select_action(second), chunks[1][:, 1])


def test_as_a_torchrl_module_rows_starting_an_episode_drop_their_queue(
    policy_server: PolicyServer,
) -> None:
    policy = RemotePolicy(policy_server.endpoint, api_key=KEYS[0], actions=2)
    observation = policy.sample_input(3, seed=4)
    chunk = policy.predict_action_chunk(observation)
    td = as_tensordict(observation, rows=3)
    td["episode_seed"] = torch.tensor([[10], [11], [12]])
    assert torch.equal(policy(td.clone())["action"], chunk[:, :2])
    assert torch.equal(policy(td.clone())["action"], chunk[:, 2:])  # the queues go on
    policy(td.clone())  # new chunks, half served
    td["episode_seed"][1] = 21  # row 1 starts an episode: it plans afresh
    action = policy(td.clone())["action"]
    assert torch.equal(action[[0, 2]], chunk[[0, 2], 2:])
    torch.testing.assert_close(action[1], chunk[1, :2], rtol=0, atol=1e-6)
    td["step_count"] = torch.tensor([[0], [5], [5]])  # a step counter decides instead
    action = policy(td.clone())["action"]
    torch.testing.assert_close(action[0], chunk[0, :2], rtol=0, atol=1e-6)
    torch.testing.assert_close(action[1], chunk[1, 2:], rtol=0, atol=1e-6)  # planned alone
    one = RemotePolicy(policy_server.endpoint, api_key=KEYS[0], actions=None)
    assert one(td.clone())["action"].shape == (3, 2)


def test_features_status_and_typed_errors(
    policy_server: PolicyServer,
    server_factory: Callable[..., PolicyServer],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    policy = RemotePolicy(policy_server.endpoint, api_key=KEYS[0])
    assert policy.status().state == "ready" and policy.ping()
    assert policy.input_features["state"].shape == (2,)
    assert policy.output_features["action"].names == ("throttle", "steering")
    assert (policy.image_size, policy.description.chunk_size) == ((64, 96), 4)

    observation = policy.sample_input(2)
    bad = {**observation, "state": observation["state"].clone()}
    bad["state"][0, 1] = float("inf")
    with pytest.raises(InvalidInputError, match=r"feature 'state' holds inf at \[0, 1\]"):
        policy.predict_action_chunk(bad)
    with pytest.raises(AuthError, match="API key rejected"):
        RemotePolicy(policy_server.endpoint, api_key="guess")
    monkeypatch.delenv("OASIS_POLICY_API_KEY", raising=False)
    with pytest.raises(AuthError, match="OASIS_POLICY_API_KEY"):
        RemotePolicy(policy_server.endpoint)

    limited = server_factory(rate_per_key=0.01, burst_per_key=4)
    assert limited.wait_until_loaded(120)
    no_retry = RemotePolicy(limited.endpoint, api_key=KEYS[0], retry=RetryPolicy.never())
    no_retry.ping()  # the constructor made 2 calls (Status, Describe): this is the 3rd
    no_retry.ping()
    with pytest.raises(RateLimitError, match="rate limit"):
        no_retry.ping()

    port = policy_server.port
    policy_server.stop(grace=0)
    quick = RetryPolicy(max_attempts=3, base_delay=0.01, max_delay=0.02)
    policy.retry = quick
    with pytest.raises(UnavailableError) as caught:
        policy.predict_action_chunk(observation)
    assert caught.value.attempts == 3, caught.value
    assert str(port) in str(caught.value)


def test_a_failed_load_and_a_slow_one_are_reported(
    server_factory: Callable[..., PolicyServer],
) -> None:
    broken = server_factory(lambda: (_ for _ in ()).throw(OSError("disk gone")))
    with pytest.raises(UnavailableError, match="failed: OSError: disk gone"):
        RemotePolicy(broken.endpoint, api_key=KEYS[0], wait=30)
    release = threading.Event()
    slow = server_factory(lambda: release.wait(60))
    try:
        with pytest.raises(UnavailableError, match=r"not ready in 0\.3 s"):
            RemotePolicy(slow.endpoint, api_key=KEYS[0], wait=0.3)
    finally:
        release.set()


def _rollout(env: OasisEnv, policy: Callable, steps: int) -> dict[str, torch.Tensor]:
    env.set_seed(7)
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        rollout = env.rollout(steps, policy, break_when_any_done=False, trust_policy=True)
    return {
        "action": rollout["action"],
        "front": rollout["next", "pixels", "front"],
        "x": rollout["next", "truth", "x"],
    }


def test_a_rollout_driven_remotely_equals_the_in_process_one(
    policy_server: PolicyServer, policy_folder: Path
) -> None:
    env = OasisEnv(
        "local", num_envs=4, prompts="urban", server=ServerConfig(width=96, height=64),
        all_frames=True, max_steps=50,
    )  # fmt: skip
    env = TransformedEnv(env, ChunkFrameStack(env.layout.cameras))  # what the network reads
    try:
        local = _rollout(env, PolicyDriver.load(policy_folder), steps=12)
        with RemotePolicy(policy_server.endpoint, api_key=KEYS[0]) as remote:
            served = _rollout(env, remote, steps=12)
    finally:
        env.close()
    assert torch.equal(served["action"], local["action"])
    assert torch.equal(served["front"], local["front"])
    assert torch.equal(served["x"], local["x"])
    spread = local["action"].flatten(0, 1).std(dim=0)
    assert (spread > 0.01).all(), "the policy must react to what it sees for this to mean much"


def test_eval_names_a_policy_server_like_a_saved_policy(
    policy_server: PolicyServer,
    policy_folder: Path,
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.setenv("OASIS_POLICY_API_KEY", KEYS[1])
    driver = load_driver(policy_server.endpoint)
    assert isinstance(driver.module, RemotePolicy) and driver.image_size == (64, 96)
    settings = ["episodes=2", "max_steps=6", "env.server.width=96", "env.server.height=64"]
    reports = {}
    for name, policy in (("served", policy_server.endpoint), ("local", str(policy_folder))):
        output = tmp_path / f"{name}.json"
        cfg = load_config("eval", [f"policy={policy}", f"output={output}", *settings])
        assert eval_command.run(cfg) == 0
        reports[name] = json.loads(output.read_text())
    capsys.readouterr()
    assert reports["served"]["per_episode"] == reports["local"]["per_episode"]
    assert reports["served"]["policy"] == policy_server.endpoint
