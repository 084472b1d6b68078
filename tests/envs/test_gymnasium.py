"""Gymnasium conventions: the registered id, the env checker, the vector env (shapes, next-step
autoreset, seeding, partial reset, close) and Gymnasium's own vector wrappers on top."""

from __future__ import annotations

import subprocess
import sys

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode
from gymnasium.wrappers.vector import RecordEpisodeStatistics

from oasis_torchrl import GYMNASIUM_ID
from oasis_torchrl.envs import OasisGymEnv, OasisVectorEnv
from oasis_torchrl.sim.config import ServerConfig

SMALL = ServerConfig(width=48, height=32, processes=0)
CAMERAS = {"left_forward", "front", "right_forward"}
FULL_THROTTLE = np.tile(np.array([1.0, 0.0], np.float32), (4, 1))


def test_gymnasium_make_builds_an_env_that_passes_the_checker() -> None:
    env = gymnasium.make(GYMNASIUM_ID, prompt="rural road", server=SMALL, max_steps=5)
    try:
        assert isinstance(env.unwrapped, OasisGymEnv) and env.spec.id == GYMNASIUM_ID
        check_env(env.unwrapped, skip_render_check=True)
        obs, info = env.reset(seed=0)
        assert set(obs) == CAMERAS and obs["front"].shape == (32, 48, 3)
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert isinstance(reward, float) and not terminated and not truncated
        assert info["truth"]["speed"].shape == (4,) and info["session_restarts"] == 0
    finally:
        env.close()


def test_the_module_form_imports_the_package_itself() -> None:
    script = (
        "import gymnasium; "
        "env = gymnasium.make('oasis_torchrl:oasis_torchrl/Oasis-v0', prompt='highway'); "
        "print(type(env.unwrapped).__name__, env.observation_space['front'].shape)"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=False
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split("\n")[-2] == "OasisGymEnv (512, 768, 3)"  # the hosted layout


@pytest.fixture
def vector_env() -> OasisVectorEnv:
    envs = gymnasium.make_vec(GYMNASIUM_ID, num_envs=2, server=SMALL, max_steps=2)
    yield envs
    envs.close()


def test_make_vec_steps_the_sessions_of_one_pool(vector_env: OasisVectorEnv) -> None:
    assert isinstance(vector_env, OasisVectorEnv) and vector_env.num_envs == 2
    assert vector_env.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert vector_env.action_space.shape == (2, 4, 2)
    obs, info = vector_env.reset(seed=3)
    assert obs in vector_env.observation_space and set(obs) == CAMERAS
    assert info["truth"]["x"].shape == (2, 4) and info["_truth"].all()
    actions = np.stack([FULL_THROTTLE] * 2)
    obs, rewards, terminated, truncated, info = vector_env.step(actions)
    assert obs["front"].shape == (2, 32, 48, 3) and obs in vector_env.observation_space
    assert rewards.shape == (2,) and rewards.dtype == np.float64
    assert terminated.shape == truncated.shape == (2,) and terminated.dtype == bool
    assert (info["truth"]["speed"][:, -1] > 0).all()


def test_next_step_autoreset(vector_env: OasisVectorEnv) -> None:
    actions = np.stack([FULL_THROTTLE] * 2)
    vector_env.reset(seed=0)
    distances = []
    for _ in range(4):
        _, rewards, terminated, truncated, info = vector_env.step(actions)
        distances.append(info["truth"]["distance"][:, -1].copy())
        if len(distances) == 2:
            assert truncated.all() and not terminated.any()  # max_steps=2
        if len(distances) == 3:  # the step after the end: the actions were ignored, new episodes
            assert not (terminated | truncated).any() and (rewards == 0).all()
            np.testing.assert_array_equal(distances[-1], 0.0)  # standing still since the reset
    assert (distances[1] > distances[0]).all() and (distances[3] > 0).all()


def test_rows_out_of_step_autoreset_alone(vector_env: OasisVectorEnv) -> None:
    actions = np.stack([FULL_THROTTLE] * 2)
    vector_env.reset(seed=0)
    vector_env.step(actions)
    vector_env.reset(options={"reset_mask": np.array([False, True])})  # row 1 starts over
    _, _, _, truncated, info = vector_env.step(actions)
    assert truncated.tolist() == [True, False]
    before = info["truth"]["distance"][:, -1].copy()
    _, rewards, _, truncated, info = vector_env.step(actions)
    after = info["truth"]["distance"][:, -1]
    assert after[0] == 0.0 and rewards[0] == 0.0  # row 0 reset, its action ignored
    assert after[1] > before[1] and truncated.tolist() == [False, True]  # row 1 drove on


def test_seeding_and_partial_reset(vector_env: OasisVectorEnv) -> None:
    first, _ = vector_env.reset(seed=11)
    again, _ = vector_env.reset(seed=11)
    other, _ = vector_env.reset(seed=12)
    np.testing.assert_array_equal(first["front"], again["front"])
    assert not np.array_equal(first["front"], other["front"])
    with pytest.raises(gymnasium.error.Error, match="python integer"):
        vector_env.reset(seed=[1, 2])

    vector_env.reset(seed=11)
    stepped, *_ = vector_env.step(np.stack([FULL_THROTTLE] * 2))
    obs, _ = vector_env.reset(options={"reset_mask": np.array([False, True])})
    np.testing.assert_array_equal(obs["front"][0], stepped["front"][0])  # row 0 kept its frame
    assert not np.array_equal(obs["front"][1], stepped["front"][1])


def test_gymnasium_vector_wrappers_and_close() -> None:
    envs = RecordEpisodeStatistics(OasisVectorEnv(2, server=SMALL, max_steps=2))
    envs.reset(seed=0)
    for _ in range(2):
        *_, info = envs.step(envs.action_space.sample())
    assert info["_episode"].all() and (info["episode"]["l"] == 2).all()
    envs.close()
    assert envs.closed and envs.unwrapped.env.is_closed
    envs.close()  # closing twice is harmless
