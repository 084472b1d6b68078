"""The env factory: the configured env, the policies' frame stack (one chunk apart, partial
resets), privileged critic inputs from ground truth (refused without it)."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch
from torchrl.envs.utils import check_env_specs, step_mdp

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
        make_env(EnvConfig(server=EmbeddedServerConfig(hosted=True)), privileged=True)


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


@pytest.mark.parametrize("all_frames", [True, False])
def test_the_frame_stack_holds_the_last_frame_of_each_chunk(all_frames: bool) -> None:
    env = make_env(TINY, num_envs=2, all_frames=all_frames, frame_stack=3)
    try:
        check_env_specs(env)
        env.set_seed(5)
        td = env.rollout(4, break_when_any_done=False)
    finally:
        env.close()
    pixels = td["next", "pixels", "front"]
    last = pixels[:, :, -1] if all_frames else pixels  # [rows, steps, H, W, 3]
    stack = td["next", "frame_stack", "front"]  # [rows, steps, 3, H, W, 3]
    assert stack.shape == (2, 4, 3, 24, 32, 3) and stack.dtype == torch.uint8
    for step in range(2, 4):
        torch.testing.assert_close(stack[:, step], last[:, step - 2 : step + 1])
    reset_frame = td["frame_stack", "front"][:, 0]  # the reset frame, repeated
    assert reset_frame.eq(reset_frame[:, -1:]).all()
    torch.testing.assert_close(stack[:, 0, :2], reset_frame[:, 1:])
    assert not stack[:, 3, 0].equal(stack[:, 3, 2])  # the car moved: frames differ


def test_a_partial_reset_restarts_only_the_reset_rows_stack() -> None:
    env = make_env(TINY, num_envs=2, all_frames=False)
    try:
        td = env.reset()
        for _ in range(2):
            td = step_mdp(env.step(td.set("action", torch.full((2, 4, 2), 0.8))))
        before = td["frame_stack", "front"].clone()
        td = env.reset(td.set("_reset", torch.tensor([[True], [False]])))
    finally:
        env.close()
    after = td["frame_stack", "front"]
    torch.testing.assert_close(after[1], before[1])  # row 1 runs on
    assert after[0, 0].equal(after[0, 1]) and not before[0, 0].equal(before[0, 1])
