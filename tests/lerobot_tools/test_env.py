"""The oasis LeRobot env in-process: episodes, metrics, seeds, and agreement with the project's
own evaluation."""

from __future__ import annotations

import numpy as np
import pytest
from lerobot.envs.factory import make_env as make_lerobot_env
from lerobot.envs.utils import env_to_policy_features
from lerobot_env_oasis import OasisEnvConfig, OasisVectorEnv

from oasis_torchrl.config import load_config
from oasis_torchrl.drivers import ScriptedDriver
from oasis_torchrl.evaluation import Evaluator
from oasis_torchrl.protocol import CAMERAS

SCRIPT = "throttle=1.0"  # straight on: some of these worlds have an obstacle ahead
SEED = 11
ROWS = 3
CHUNKS = 32


def _drive_to_the_end(env: OasisVectorEnv) -> tuple[np.ndarray, np.ndarray, list[dict]]:
    """Constant actions until every session ended: summed rewards, success, final infos."""
    total, success, finals = np.zeros(env.num_envs), np.zeros(env.num_envs, bool), []
    done = np.zeros(env.num_envs, bool)
    action = np.tile(np.array([1.0, 0.0], np.float32), (env.num_envs, 1))
    for _ in range(env.call("_max_episode_steps")[0]):
        _, reward, terminated, truncated, info = env.step(action)
        total += reward
        if "final_info" in info:
            ending = info["final_info"]["_is_success"]
            success |= info["final_info"]["is_success"] & ending
            finals.append(info["final_info"])
        done |= terminated | truncated
        if done.all():
            break
    return total, success, finals


def test_metrics_match_oasis_torchrl_eval_on_the_same_seeds() -> None:
    cfg = load_config("eval", [f"episodes={ROWS}", f"seeds=[{SEED}]", f"max_steps={CHUNKS}"])
    with Evaluator(cfg.env, cfg, progress=False) as evaluator:
        report = evaluator.evaluate(ScriptedDriver.from_spec(SCRIPT))
    envs = make_lerobot_env(OasisEnvConfig(episode_length=4 * CHUNKS), n_envs=ROWS)
    env = envs["oasis"][0]
    try:
        env.reset(seed=list(range(SEED, SEED + ROWS)))
        distance, success, finals = _drive_to_the_end(env)
    finally:
        env.close()
        env.close()  # LeRobot closes its envs twice
    expected = report.episodes
    assert distance == pytest.approx([e.distance for e in expected], rel=1e-6)
    assert success.tolist() == [not e.collided for e in expected]
    seeds = {int(s) for info in finals for s in info["episode_seed"]}
    assert seeds == {e.episode_seed for e in expected}
    assert any(e.collided for e in expected)  # the script crashes some worlds: both kinds seen


def test_observations_features_and_rendering() -> None:
    config = OasisEnvConfig(task="rural road", episode_length=8)
    features = env_to_policy_features(config)
    assert features["observation.images.front"].shape == (3, 64, 96)
    assert features["observation.state"].shape == (2,) and features["action"].shape == (2,)
    env = OasisVectorEnv(config, num_envs=2)
    try:
        observation, _ = env.reset(seed=3)
        assert env.observation_space["pixels"]["left_forward"].shape == (2, 64, 96, 3)
        assert set(observation["pixels"]) == set(CAMERAS)
        renders = []
        for tick in range(1, 9):
            observation, reward, terminated, truncated, info = env.step(np.full((2, 2), 0.5))
            renders.append(env.render())
            if tick % 4 == 3:  # the chunk's last frame is both rendered and observed now
                front = renders[-1][:, :, 96:192]
                np.testing.assert_array_equal(front, observation["pixels"]["front"])
        assert renders[0].shape == (2, 64, 3 * 96, 3)
        assert observation["agent_pos"].tolist() == [[0.5, 0.5], [0.5, 0.5]]
        assert truncated.all() and not terminated.any()
        # an ended session is frozen: no reward, no second end
        _, reward, _, truncated, info = env.step(np.zeros((2, 2)))
        for _ in range(3):
            _, reward, _, truncated, info = env.step(np.zeros((2, 2)))
        assert reward.tolist() == [0.0, 0.0] and truncated.all() and "final_info" not in info
        assert env.call("task") == ("rural road", "rural road")
    finally:
        env.close()


def test_bad_settings_are_named() -> None:
    with pytest.raises(ValueError, match="multiple of 4"):
        OasisEnvConfig(episode_length=10)
    with pytest.raises(ValueError, match="ground truth"):
        OasisEnvConfig(endpoint="http://127.0.0.1:1")
    with pytest.raises(ValueError, match="20 fps"):
        OasisEnvConfig(fps=30)
    env = OasisVectorEnv(OasisEnvConfig(episode_length=8), num_envs=2)
    try:
        with pytest.raises(ValueError, match="consecutive"):
            env.reset(seed=[4, 2])
        env.reset()
        with pytest.raises(ValueError, match="shape \\(2, 2\\)"):
            env.step(np.zeros((3, 2)))
    finally:
        env.close()
