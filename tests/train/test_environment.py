"""The training env: privileged critic inputs from ground truth, refused without it."""

from __future__ import annotations

import pytest
import torch

from oasis_torchrl.config import load_config
from oasis_torchrl.train.environment import PRIVILEGED_FIELDS, build_env

from .conftest import TINY_ENV


def test_privileged_state_follows_the_ground_truth() -> None:
    env = build_env(load_config("ppo", TINY_ENV).env, num_envs=2, privileged=True)
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
    cfg = load_config("ppo", [*TINY_ENV, "env.endpoint=http://127.0.0.1:9"]).env
    with pytest.raises(ValueError, match=r"loss.aux_coeff\) needs ground truth"):
        build_env(cfg, privileged=True)
