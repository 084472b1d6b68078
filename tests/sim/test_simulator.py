"""The simulator facade: determinism, steering, validation, collisions, scene and depth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from oasis_torchrl.protocol import CAMERAS
from oasis_torchrl.sim.simulator import Simulator

WIDTH, HEIGHT = 64, 48
FORWARD = np.array([[0.8, 0.0]] * 4, np.float32)


def drive(prompt: str, seed: int, chunks: list[np.ndarray]) -> tuple[list, list]:
    simulator = Simulator(WIDTH, HEIGHT)
    simulator.reset(prompt, seed)
    results = [simulator.step(chunk) for chunk in chunks]
    return [result.rgb for result in results], [result.truth for result in results]


def test_step_before_reset_raises() -> None:
    with pytest.raises(RuntimeError, match="reset"):
        Simulator(WIDTH, HEIGHT).step(FORWARD)


def test_same_prompt_and_seed_give_identical_frames_and_truth() -> None:
    chunks = [FORWARD, np.array([[0.5, -0.4]] * 4, np.float32)]
    first, again, other = (drive("urban dusk", seed, chunks) for seed in (7, 7, 8))
    for frames, repeated in zip(first[0], again[0], strict=True):
        for name in CAMERAS:
            assert np.array_equal(frames[name], repeated[name])
    assert first[1] == again[1]
    assert not np.array_equal(first[0][-1]["front"], other[0][-1]["front"])


def test_frames_layout() -> None:
    simulator = Simulator(WIDTH, HEIGHT)
    simulator.reset("highway", 0)
    result = simulator.step(FORWARD)
    assert set(result.rgb) == set(CAMERAS) and len(result.truth) == 4
    for frames in result.rgb.values():
        assert frames.shape == (4, HEIGHT, WIDTH, 3) and frames.dtype == np.uint8
        assert frames.flags["C_CONTIGUOUS"]
    assert result.truth[0].distance < result.truth[-1].distance
    physics_only = simulator.step(FORWARD, render=False)
    assert physics_only.rgb["front"].shape == (0, HEIGHT, WIDTH, 3)


def test_steering_left_and_right_diverge() -> None:
    frames, truth = {}, {}
    for name, steering in (("left", -0.7), ("right", 0.7)):
        simulator = Simulator(WIDTH, HEIGHT)
        simulator.reset("rural", 3)
        for _ in range(4):
            result = simulator.step(np.array([[0.8, steering]] * 4, np.float32))
        frames[name], truth[name] = result.rgb["front"][-1], result.truth[-1]
    assert np.abs(frames["left"].astype(int) - frames["right"]).mean() > 10
    assert truth["left"].heading_error > 0 > truth["right"].heading_error


@pytest.mark.parametrize(
    ("actions", "message"),
    [
        (np.zeros((3, 2)), "shape"),
        (np.zeros((4, 2, 1)), "shape"),
        (np.array([[0.0, math.nan]] * 4), "finite"),
        (np.array([[1.5, 0.0]] * 4), r"\[-1, 1\]"),
        ("fast", "numeric"),
    ],
)
def test_bad_actions_are_rejected_by_name(actions: object, message: str) -> None:
    simulator = Simulator(WIDTH, HEIGHT)
    simulator.reset("urban", 0)
    with pytest.raises(ValueError, match=f"actions.*{message}"):
        simulator.step(actions)


def test_bad_settings_are_rejected_by_name() -> None:
    with pytest.raises(ValueError, match="width"):
        Simulator(width=4, height=64)
    with pytest.raises(ValueError, match="fps"):
        Simulator(WIDTH, HEIGHT, fps=0.0)
    simulator = Simulator(WIDTH, HEIGHT)
    with pytest.raises(ValueError, match="seed"):
        simulator.reset("urban", seed=-1)
    with pytest.raises(TypeError, match="prompt"):
        simulator.reset(None)  # type: ignore[arg-type]


def test_after_a_crash_frames_keep_coming_from_the_stopped_car() -> None:
    simulator = Simulator(WIDTH, HEIGHT)
    simulator.reset("rural", 0)
    while not simulator.truth.collided:
        simulator.step(np.array([[0.7, 1.0]] * 4, np.float32), render=False)
    crashed = simulator.truth
    result = simulator.step(FORWARD)
    assert all(truth.collided and truth.speed == 0.0 for truth in result.truth)
    assert (result.truth[-1].x, result.truth[-1].y) == (crashed.x, crashed.y)
    assert np.array_equal(result.rgb["front"][0], result.rgb["front"][-1])
    assert crashed.off_road


def test_scene_proto_and_depth() -> None:
    simulator = Simulator(WIDTH, HEIGHT)
    simulator.reset("city", 9)
    scene = simulator.scene_proto()
    assert (scene.prompt, scene.seed, scene.lanes) == ("city", 9, simulator.scene.style.lanes)
    steps = np.hypot(np.diff(scene.centerline_x), np.diff(scene.centerline_y))
    assert np.allclose(steps, 2.0, atol=0.05) and len(scene.centerline_x) > 1500
    assert len(scene.obstacles) == len(simulator.scene.obstacles)
    assert {obstacle.kind for obstacle in scene.obstacles} <= {"car", "barrier", "pedestrian"}
    simulator.step(FORWARD)
    depth = simulator.depth()
    assert set(depth) == set(CAMERAS)
    assert all(value.shape == (HEIGHT, WIDTH) for value in depth.values())
