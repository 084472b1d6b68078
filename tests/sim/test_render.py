"""What the cameras show: lighting and weather looks, depth, odd sizes, palette conversion,
and batched rendering of several poses (byte for byte the frames of one pose at a time)."""

from __future__ import annotations

import os
import threading

import numpy as np
import pytest

from oasis_torchrl.protocol import CAMERAS, CHUNK
from oasis_torchrl.sim.autopilot import Autopilot
from oasis_torchrl.sim.render import OBSTACLE_FAR, Renderer
from oasis_torchrl.sim.render.quad_palette import QuadPalette
from oasis_torchrl.sim.scene import build_scene, obstacles_at
from oasis_torchrl.sim.simulator import Simulator
from oasis_torchrl.sim.vehicle import VehicleState
from oasis_torchrl.sim.world import World

WIDTH, HEIGHT = 96, 64


def render(prompt: str, seed: int = 0, steps: int = 0, scene=None) -> dict[str, np.ndarray]:
    """Frames of every camera after ``steps`` frames of gentle throttle."""
    scene = scene or build_scene(prompt, seed)
    world = World(scene, dt=0.05)
    for _ in range(steps):
        world.advance(0.5, 0.0)
    renderer = Renderer(WIDTH, HEIGHT)
    renderer.prepare(scene)
    frames = {name: np.zeros((HEIGHT, WIDTH, 3), np.uint8) for name in CAMERAS}
    renderer.render(world.state, steps, frames)
    return frames


def test_night_is_darker_than_day_and_sunset_warmer() -> None:
    day, night, sunset = (
        render(prompt)["front"] for prompt in ("rural", "rural night", "rural sunset")
    )
    assert night.mean() < 0.5 * day.mean()

    def warmth(frame: np.ndarray) -> float:
        return float(frame[..., 0].mean() - frame[..., 2].mean())

    assert warmth(sunset) > warmth(day) + 20


def test_fog_flattens_the_far_view() -> None:
    horizon_band = slice(HEIGHT // 2 - 6, HEIGHT // 2 + 6)
    clear, foggy = (
        render(p, seed=1)["front"][horizon_band].astype(float) for p in ("urban", "urban fog")
    )
    assert foggy.std() < 0.6 * clear.std()


def test_rain_streaks_fall_frame_by_frame() -> None:
    first, second = render("rural rain", steps=3)["front"], render("rural rain", steps=4)["front"]
    dry_first, dry_second = render("rural", steps=3)["front"], render("rural", steps=4)["front"]
    rain_change = np.abs(first.astype(int) - second).mean()
    assert rain_change > 2 * np.abs(dry_first.astype(int) - dry_second).mean()


def test_depth_is_metric_and_occludes() -> None:
    scene = build_scene("highway", 0)
    lane = scene.style.lane_offset(0)
    scene = scene.with_obstacles(obstacles_at(scene.road, ["car"], [15.0], [lane]))
    renderer = Renderer(WIDTH, HEIGHT)
    renderer.prepare(scene)
    depth = renderer.depth(World(scene, dt=0.05).state)["front"]
    assert depth.shape == (HEIGHT, WIDTH) and depth.dtype == np.float32
    assert np.isinf(depth[0]).mean() > 0.5  # sky
    ground = depth[HEIGHT // 2 + 12 :, 5]
    assert np.all(np.diff(ground) < 0)  # nearer towards the bottom
    column = depth[:, WIDTH // 2]
    car_rows = np.flatnonzero(np.isclose(column, 15.0 - 1.0 - 2.2, atol=1.0))
    assert car_rows.size > 2
    behind = column[car_rows.min() - 1]
    assert behind > column[car_rows.min()]


@pytest.mark.parametrize(("width", "height"), [(97, 61), (33, 17)])
def test_odd_sizes_render(width: int, height: int) -> None:
    scene = build_scene("city rain", 2)
    renderer = Renderer(width, height)
    renderer.prepare(scene)
    frames = {name: np.zeros((height, width, 3), np.uint8) for name in CAMERAS}
    renderer.render(World(scene, dt=0.05).state, 0, frames)
    for frame in frames.values():
        assert frame.std() > 5.0
    assert renderer.depth(World(scene, dt=0.05).state)["front"].shape == (height, width)


def test_quad_palette_matches_a_plain_lookup() -> None:
    rng = np.random.default_rng(0)
    palette = rng.integers(0, 256, (256, 3)).astype(np.uint8)
    converter = QuadPalette(palette)
    for size in (1, 2, 3, 4, 5, 7, 8, 1001):
        indices = rng.integers(0, 256, size).astype(np.uint8)
        out = np.empty((size, 3), np.uint8)
        converter.convert(indices, out)
        assert np.array_equal(out, palette[indices])


@pytest.mark.parametrize(
    ("prompt", "width", "height", "chunks"),
    [
        ("urban", 96, 64, 8),
        ("highway at night", 96, 64, 8),
        ("city in the rain", 96, 64, 8),
        ("rural snow at sunset", 96, 64, 8),
        ("rural fog", 192, 128, 6),
        ("urban snow", 192, 128, 6),
        ("highway rain", 768, 512, 2),  # large: drawn in parallel parts per view
    ],
)
def test_batched_steps_match_one_pose_at_a_time(
    prompt: str, width: int, height: int, chunks: int
) -> None:
    simulator = Simulator(width, height)
    simulator.reset(prompt, seed=1)
    pilot = Autopilot(simulator)
    renderer = Renderer(width, height)
    renderer.prepare(simulator.scene)
    rng = np.random.default_rng(0)
    one_pose = {name: np.empty((height, width, 3), np.uint8) for name in CAMERAS}
    for _ in range(chunks):
        actions = pilot.act()
        # Weave, so the cameras sweep across walls, obstacles and lane lines.
        actions[:, 1] = np.clip(actions[:, 1] + rng.normal(0.0, 0.3, CHUNK), -1.0, 1.0)
        result = simulator.step(actions)  # the four poses in one pass
        first_frame = simulator.world.steps - CHUNK + 1
        for index, truth in enumerate(result.truth):
            pose = VehicleState(truth.x, truth.y, truth.heading, truth.speed)
            renderer.render(pose, first_frame + index, one_pose)
            for name in CAMERAS:
                assert np.array_equal(result.rgb[name][index], one_pose[name]), (name, index)


def test_batched_poses_keep_their_own_obstacle_range() -> None:
    # A car just beyond OBSTACLE_FAR along the road, seen by a camera turned off the road (so
    # nearer than OBSTACLE_FAR along its axis): cut for the first pose, drawn for a pose 20 m on.
    width, height = 768, 512
    scene = build_scene("highway", 0)
    road = scene.road
    poses = []
    for s in (100.0, 120.0):
        x, y, heading = road.pose_at(s)
        poses.append(VehicleState(float(x), float(y), float(heading) + 0.3, 0.0))
    far_car = obstacles_at(road, ["car"], [100.0 + OBSTACLE_FAR + 4.0], [0.0])
    renderer = Renderer(width, height)
    frames = {}
    for name, obstacles in (("empty", obstacles_at(road, [], [], [])), ("far car", far_car)):
        renderer.prepare(scene.with_obstacles(obstacles))
        frames[name] = {camera: np.empty((2, height, width, 3), np.uint8) for camera in CAMERAS}
        renderer.render_many(poses, [0, 0], frames[name])
    assert not np.array_equal(frames["far car"]["front"][1], frames["empty"]["front"][1])
    one_pose = {camera: np.empty((height, width, 3), np.uint8) for camera in CAMERAS}
    renderer.render(poses[0], 0, one_pose)
    for camera in CAMERAS:
        assert np.array_equal(frames["far car"][camera][0], one_pose[camera])


def test_render_many_rejects_mismatched_arguments() -> None:
    scene = build_scene("rural", 0)
    renderer = Renderer(WIDTH, HEIGHT)
    renderer.prepare(scene)
    state = World(scene, dt=0.05).state
    frames = {name: np.zeros((2, HEIGHT, WIDTH, 3), np.uint8) for name in CAMERAS}
    with pytest.raises(ValueError, match="frames must have one entry per car"):
        renderer.render_many([state, state], [0], frames)
    frames["front"] = np.zeros((2, HEIGHT, WIDTH), np.uint8)
    with pytest.raises(ValueError, match="out\\['front'\\]"):
        renderer.render_many([state, state], [0, 1], frames)


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="one core: large images render in one thread")
def test_a_large_renderer_stops_its_threads_on_close() -> None:
    scene = build_scene("highway", 0)
    state = World(scene, dt=0.05).state
    before = set(threading.enumerate())
    renderer = Renderer(768, 512)
    renderer.prepare(scene)
    first = {name: np.empty((512, 768, 3), np.uint8) for name in CAMERAS}
    renderer.render(state, 0, first)
    threads = [t for t in set(threading.enumerate()) - before if t.name.startswith("oasis-render")]
    assert threads
    renderer.close()
    assert not any(thread.is_alive() for thread in threads)
    again = {name: np.empty((512, 768, 3), np.uint8) for name in CAMERAS}
    renderer.render(state, 0, again)  # still renders, in the calling thread
    for name in CAMERAS:
        assert np.array_equal(first[name], again[name])
