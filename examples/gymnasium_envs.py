"""Gymnasium: one session through ``gymnasium.make`` (Stable-Baselines3 style) and N sessions
stepped concurrently through ``gymnasium.make_vec`` (CleanRL style).

    python examples/gymnasium_envs.py
    OASIS_EXAMPLE_SMOKE=1 python examples/gymnasium_envs.py   # a few steps (what the tests run)
"""

from __future__ import annotations

import os

import gymnasium
from gymnasium.wrappers.vector import RecordEpisodeStatistics

import oasis_torchrl  # noqa: F401  (registers "oasis_torchrl/Oasis-v0")
from oasis_torchrl.sim.config import ServerConfig

SMOKE = os.environ.get("OASIS_EXAMPLE_SMOKE") == "1"
STEPS = 3 if SMOKE else 200
SERVER = ServerConfig(width=96, height=64)  # any OasisEnv argument passes through make


def single_env() -> None:
    env = gymnasium.make(
        "oasis_torchrl/Oasis-v0", prompt="rural road", server=SERVER, max_steps=STEPS
    )
    obs, info = env.reset(seed=0)
    total = 0.0
    for _ in range(STEPS):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        total += reward
        if terminated or truncated:
            obs, _ = env.reset()
    env.close()
    speed = info["truth"]["speed"][-1]  # ground truth of the embedded server, metres/second
    print(f"single env: front camera {obs['front'].shape}, return {total:.2f}, speed {speed:.1f}")


def vector_env() -> None:
    # The vector entry point: one batched env whose sessions step concurrently (autoreset
    # NEXT_STEP); Gymnasium's vector wrappers work on top.
    envs = gymnasium.make_vec("oasis_torchrl/Oasis-v0", num_envs=4, server=SERVER, max_steps=STEPS)
    envs = RecordEpisodeStatistics(envs)
    obs, info = envs.reset(seed=0)
    for _ in range(STEPS + 1):
        obs, _, _, _, info = envs.step(envs.action_space.sample())
        if "episode" in info:
            finished = info["_episode"]
            print("episodes ended, returns:", info["episode"]["r"][finished].round(2))
    envs.close()
    print(f"vector env: {envs.num_envs} rows, front camera {obs['front'].shape}")


if __name__ == "__main__":
    single_env()
    vector_env()
