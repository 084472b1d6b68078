"""OasisEnv against the real embedded server on loopback."""

from __future__ import annotations

import os
import pickle
import signal
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import check_env_specs

from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.launcher import LocalServer

SMALL = ServerConfig(width=64, height=48)
CAMERAS = ("left_forward", "front", "right_forward")


@pytest.fixture
def env():
    env = OasisEnv("local", num_envs=3, prompts="urban street", server=SMALL, max_steps=5)
    yield env
    if not env.is_closed:
        env.close()


def straight(env: OasisEnv, throttle: float = 0.5) -> TensorDict:
    action = torch.zeros(env.action_spec.shape)
    action[..., 0] = throttle
    return TensorDict(action=action, batch_size=env.batch_size)


def test_check_env_specs(env: OasisEnv) -> None:
    check_env_specs(env, seed=0)


def test_layout_and_reset_observation(env: OasisEnv) -> None:
    td = env.reset()
    for camera in CAMERAS:
        assert td["pixels", camera].shape == (3, 48, 64, 3)
        assert td["pixels", camera].dtype == torch.uint8
    assert torch.equal(td["state"], torch.zeros(3, 2))
    assert td["truth", "speed"].shape == (3, 4)
    assert not td["done"].any()


def test_rollout_truncates_at_max_steps(env: OasisEnv) -> None:
    td = env.rollout(5, break_when_any_done=False)
    assert td.batch_size == (3, 5)
    assert td["next", "truncated"][:, -1].all()
    assert not td["next", "truncated"][:, :-1].any()
    # the previous action is observed at the next step
    assert torch.allclose(td["next", "state"][:, 0], td["action"][:, 0, -1])


def test_partial_reset_reprompts_only_masked_rows(env: OasisEnv) -> None:
    env.set_seed(1)
    env.reset()
    for _ in range(3):
        out = env.step(straight(env))["next"]
    before = out["truth", "distance"][:, -1].clone()
    assert (before > 0).all()
    reset = torch.tensor([[False], [True], [False]])
    td = out.clone().set("_reset", reset)
    after = env.reset(td)
    assert after["truth", "distance"][1, -1] == 0
    assert torch.equal(after["truth", "distance"][[0, 2], -1], before[[0, 2]])
    assert torch.equal(after["pixels", "front"][0], out["pixels", "front"][0])


def test_same_seed_same_rollout() -> None:
    def run(seed: int) -> TensorDict:
        env = OasisEnv("local", num_envs=2, prompts="rural road", server=SMALL, max_steps=4)
        try:
            env.set_seed(seed)
            torch.manual_seed(0)
            return env.rollout(4, break_when_any_done=False)
        finally:
            env.close()

    a, b, c = run(3), run(3), run(4)
    assert torch.equal(a["next", "pixels", "front"], b["next", "pixels", "front"])
    assert torch.equal(a["next", "reward"], b["next", "reward"])
    assert not torch.equal(a["next", "pixels", "front"], c["next", "pixels", "front"])


@pytest.mark.parametrize(
    ("value", "message"),
    [(float("nan"), "not finite"), (1.5, "outside"), (None, "shape")],
)
def test_bad_actions_rejected_before_any_request(env: OasisEnv, value, message) -> None:
    env.reset()
    zeros = torch.zeros(3, 4, 2).numpy()
    seq_before = env.pool.infer(zeros).sequence_nums
    if value is None:
        action = torch.zeros(3, 2)
    else:
        action = torch.zeros(env.action_spec.shape)
        action[1, 2, 0] = value
    with pytest.raises(ValueError, match=message):
        env.step(TensorDict(action=action, batch_size=[3]))
    # nothing was sent: the next Infer of every session has the next sequence number
    assert (env.pool.infer(zeros).sequence_nums == seq_before + 1).all()


def test_single_action_mode_and_all_frames() -> None:
    env = OasisEnv(
        "local", num_envs=2, server=SMALL, chunk_actions=False, all_frames=True, max_steps=3
    )
    try:
        assert env.action_spec.shape == (2, 2)
        td = env.rollout(2)
        assert td["next", "pixels", "front"].shape == (2, 2, 4, 48, 64, 3)
    finally:
        env.close()


def test_env_opens_nothing_until_used_and_pickles_unopened(env: OasisEnv) -> None:
    remote = OasisEnv("http://127.0.0.1:1", num_envs=2)  # nothing listens there
    assert pickle.loads(pickle.dumps(remote)).observation_spec["pixels", "front"].shape == (
        2, 512, 768, 3,
    )  # fmt: skip
    env.reset()
    clone = pickle.loads(pickle.dumps(env))
    assert clone._env.streams == ()  # the copy arrives unopened and opens its own sessions
    try:
        assert clone.reset()["pixels", "front"].shape == (3, 48, 64, 3)
    finally:
        clone.close()


def test_a_server_streaming_another_layout_is_named_at_the_first_reset() -> None:
    with LocalServer(SMALL) as server:
        env = OasisEnv(server.endpoint, 1, api_key=server.api_key)  # built for the hosted size
        with pytest.raises(ValueError, match=r"streams .* at \(48, 64\).*pass frame_size"):
            env.reset()
        sized = OasisEnv(server.endpoint, 1, api_key=server.api_key, frame_size=(24, 32))
        try:
            assert sized.reset()["pixels", "front"].shape == (1, 24, 32, 3)
        finally:
            sized.close()


def test_local_world_runs_out_of_process_and_a_dead_worker_restarts_only_its_rows() -> None:
    server = ServerConfig(width=96, height=64, processes=2)
    env = OasisEnv("local", num_envs=4, prompts="urban street", server=server)
    try:
        env.set_seed(0)
        td = env.reset()
        assert env.server is not None and env.server.pid != os.getpid()  # the world runs apart
        children = Path(f"/proc/{env.server.pid}/task/{env.server.pid}/children").read_text()
        workers = [int(pid) for pid in children.split()]
        assert len(workers) == 2
        zero = torch.zeros(4, 4, 2)
        td = env.step(td.set("action", zero))["next"]
        os.kill(workers[0], signal.SIGKILL)  # during the rollout
        td = env.step(td.set("action", zero))["next"]
        restarts = td["info", "session_restarts"].flatten()
        assert sorted(restarts.tolist()) == [0, 0, 1, 1]  # only the dead worker's two rows
        assert torch.equal(td["truncated"].flatten(), restarts.bool())
        for _ in range(3):  # every row keeps stepping
            td = env.step(td.set("action", zero))["next"]
        assert torch.equal(td["info", "session_restarts"].flatten(), restarts)
    finally:
        env.close()
