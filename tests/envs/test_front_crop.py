"""The narrow forward crop (``env.front_crop``): the centre of the front frame decoded at the
server's full size, as a fourth camera through the env, the hosted-like VP9 path, datasets, BC
and saved policies."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

from oasis_torchrl.client import SessionPool
from oasis_torchrl.client.decoding import FrontCrop, RawRgbDecoder, RgbResizer
from oasis_torchrl.config import EmbeddedServerConfig, EnvConfig, load_config
from oasis_torchrl.data import LeRobotRecorder
from oasis_torchrl.drivers import Autopilot, ScriptedDriver, load_driver
from oasis_torchrl.envs import OasisGymEnv, make_env
from oasis_torchrl.envs.embedded import embedded_server
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.train.bc import BCTrainer

# Frames of 24x32 cut from a 48x64 render: a crop of half the front frame has the cameras' size,
# so it must be the centre of the full-size frame pixel for pixel.
CROP_ENV = EnvConfig(
    num_envs=1,
    max_steps=3,
    image_size=(24, 32),
    front_crop=0.5,
    server=EmbeddedServerConfig(width=32, height=24),
)


def test_the_crop_is_the_centre_of_the_full_size_frame() -> None:
    full = np.random.default_rng(0).integers(0, 256, (48, 64, 3), np.uint8)
    wide, narrow = np.empty((24, 32, 3), np.uint8), np.empty((24, 32, 3), np.uint8)
    FrontCrop(0.5).decode_into(RawRgbDecoder("front", (48, 64)), full.tobytes(), wide, narrow)
    np.testing.assert_array_equal(narrow, full[12:36, 16:48])
    expected = np.empty_like(wide)
    RgbResizer().resize_into(full, expected)
    np.testing.assert_array_equal(wide, expected)


def test_the_env_adds_the_crop_of_the_front_rendered_large_enough() -> None:
    env = make_env(CROP_ENV)
    large = EmbeddedServerConfig(width=64, height=48)
    full_size = make_env(replace(CROP_ENV, front_crop=None, image_size=None, server=large))
    try:
        assert env.base_env.server.config.width == 64  # 32 pixels / 0.5: the crop's detail
        check_env_specs(env)
        for each in (env, full_size):
            each.set_seed(4)
        drive = ScriptedDriver.from_spec("throttle=0.7")
        td = env.rollout(3, drive)
        reference = full_size.rollout(3, drive)
    finally:
        env.close()
        full_size.close()
    crop = td["next", "pixels", "front_crop"]
    assert crop.shape == (1, 3, 4, 24, 32, 3)
    assert td["next", "frame_stack", "front_crop"].shape == (1, 3, 2, 24, 32, 3)
    front = reference["next", "pixels", "front"]  # the same world at the server's full size
    torch.testing.assert_close(crop, front[..., 12:36, 16:48, :])
    assert not crop.equal(td["next", "pixels", "front"])


def test_the_hosted_like_vp9_front_is_decoded_once_for_both_views() -> None:
    server = embedded_server(ServerConfig(width=64, height=48, hosted=True), 1)
    with SessionPool(server, 1, front_crop=0.5) as pool:
        pool.prompt(["urban"])
        step = pool.infer(np.full((1, 4, 2), 0.5, np.float32))
        assert pool.camera_names == ("left_forward", "front", "right_forward", "front_crop")
    front, crop = step.frames["front"][0, -1], step.frames["front_crop"][0, -1]
    assert crop.shape == front.shape == (48, 64, 3)
    expected = np.empty_like(crop)
    RgbResizer().resize_into(front[12:36, 16:48], expected)
    np.testing.assert_array_equal(crop, expected)


def test_a_crop_dataset_trains_a_policy_that_needs_the_crop(tmp_path: Path) -> None:
    env = make_env(CROP_ENV, expert=True, frame_stack=None)
    try:
        with LeRobotRecorder(tmp_path / "drives", privileged=True) as recorder:
            recorder.write(env.rollout(3, Autopilot(), break_when_any_done=False))
    finally:
        env.close()
    args = [
        f"dataset.root={tmp_path / 'drives'}",
        "policy.image_size=[24,32]",
        "train.steps=1",
        "train.batch_size=4",
        "eval.episodes=0",
        "progress=false",
    ]
    with pytest.raises(ValueError, match=r"set policy\.front_crop"):
        BCTrainer(load_config("bc", [*args, f"output_dir={tmp_path / 'refused'}"]))
    three = "dataset.cameras=[left_forward,front,right_forward]"
    without = BCTrainer(load_config("bc", [*args, three, f"output_dir={tmp_path / 'three'}"]))
    assert without.policy.model.config.cameras == ("left_forward", "front", "right_forward")
    trainer = BCTrainer(
        load_config("bc", [*args, "policy.front_crop=0.5", f"output_dir={tmp_path / 'crop'}"])
    )
    folder = trainer.run().policy_dir
    driver = load_driver(str(folder))
    assert driver.front_crop == 0.5
    assert driver.observation_spec["frame_stack", "front_crop"].shape[-3:] == (24, 32, 3)
    plain = make_env(replace(CROP_ENV, front_crop=None), frame_stack=driver.frame_stack)
    try:
        with pytest.raises(ValueError, match=r"reads the front crop .*env\.front_crop=0\.5$"):
            driver(plain.reset())
    finally:
        plain.close()


def test_the_gymnasium_env_observes_the_crop() -> None:
    envs = {
        crop: OasisGymEnv(server=ServerConfig(width=width, height=height), front_crop=crop)
        for crop, (height, width) in ((0.5, (24, 32)), (None, (48, 64)))
    }
    try:
        assert envs[0.5].observation_space["front_crop"].shape == (24, 32, 3)
        observations = {crop: env.reset(seed=4)[0] for crop, env in envs.items()}
    finally:
        for env in envs.values():
            env.close()
    np.testing.assert_array_equal(
        observations[0.5]["front_crop"], observations[None]["front"][12:36, 16:48]
    )
