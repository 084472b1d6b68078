"""The env factory: the configured env, privileged critic inputs from ground truth (refused
without it)."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch

from oasis_torchrl.config import EmbeddedServerConfig, EnvConfig
from oasis_torchrl.envs import PRIVILEGED_FIELDS, make_env

TINY = EnvConfig(image_size=(24, 32), server=EmbeddedServerConfig(width=48, height=32))


def test_privileged_state_follows_the_ground_truth() -> None:
    env = make_env(TINY, num_envs=2, privileged=True)
    try:
        env.set_seed(3)
        td = env.rollout(3, break_when_any_done=False)
    finally:
        env.close()
    inputs = td.get(("next", "critic_inputs"))
    assert inputs.shape == (2, 3, len(PRIVILEGED_FIELDS))
    speed = td.get(("next", "truth", "speed"))[..., -1]
    torch.testing.assert_close(inputs[..., 0], speed / 10.0)
    assert env.observation_spec["critic_inputs"].shape == (2, len(PRIVILEGED_FIELDS))


def test_privileged_state_needs_ground_truth() -> None:
    with pytest.raises(ValueError, match=r"loss.aux_coeff\) needs ground truth"):
        make_env(EnvConfig(endpoint="http://127.0.0.1:9"), privileged=True)


def test_make_env_builds_the_configured_env() -> None:
    env = make_env(EnvConfig(num_envs=2, max_steps=3, image_size=(24, 32), prompts=["a", "b"]))
    try:
        td = env.rollout(3)
    finally:
        env.close()
    assert td["next", "pixels", "front"].shape == (2, 3, 4, 24, 32, 3)
    assert td["next", "step_count"][:, -1].eq(3).all()
    assert set(td[:, 0]["prompt"]) <= {"a", "b"}
    last_only = make_env(replace(TINY, image_size=None), num_envs=1, all_frames=False)
    try:
        assert last_only.reset()["pixels", "front"].shape == (1, 32, 48, 3)  # the server's size
    finally:
        last_only.close()
