"""The top-down view: scenes through the protocol, the window that follows the car, and the
picture a live rollout draws (rendered to a PNG and checked pixel by pixel)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from oasis_torchrl.client import DecartRoboticsError, SceneSource, SessionPool
from oasis_torchrl.drivers import Autopilot
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.proto import sim_pb2
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.launcher import LocalServer
from oasis_torchrl.viz import LogOptions, RerunTransform, RolloutLogger
from oasis_torchrl.viz.topdown import (
    CAR_COLOR,
    DASH,
    EDGE_COLOR,
    EDGE_RADIUS,
    LANE_RADIUS,
    OBSTACLE_COLORS,
    PATH_COLOR,
    ROAD_COLOR,
    RoadMap,
    Trail,
    Window,
)

from ._raster import draw, layer_at
from ._readback import Readback

PIXELS_PER_METRE = 8


def test_scene_source_answers_what_the_server_says(stubs, local_server: LocalServer) -> None:
    session = stubs.open_session(prompt="urban street at night", seed=7)
    answered = stubs.sim.GetScene(
        sim_pb2.SceneRequest(session_id=session.session_id), metadata=session.metadata, timeout=10
    )
    scenes = SceneSource(local_server.endpoint, local_server.api_key)
    scene = scenes("urban street at night", 7)
    assert scene == answered
    assert scene.ego_length > scene.ego_width > 0 and scene.lane_width > 0
    assert scenes("urban street at night", 7) is scene  # asked once
    assert scenes("urban street at night", 8) != scene


def test_a_pools_scene_source_needs_its_server_started() -> None:
    pool = SessionPool(LocalServer(width=64, height=48), 1)
    scenes = SceneSource(pool)
    with pytest.raises(DecartRoboticsError, match="has not started"):
        scenes("rural road", 1)
    with pool:
        assert scenes("rural road", 1).prompt == "rural road"


def test_an_env_at_its_servers_session_limit_still_finds_its_scenes() -> None:
    # Every row holds a session of the key's limit; the scene lookup needs one more.
    server = ServerConfig(width=48, height=32, processes=0, max_sessions_per_key=2)
    env = OasisEnv("local", 2, "rural road", server=server)
    try:
        env.set_seed(1)
        env.reset()
        assert env.scene_source()("rural road", 1).prompt == "rural road"
    finally:
        env.close()


def _straight_north_scene(obstacles: list[tuple[float, float]]) -> sim_pb2.SceneResponse:
    """A straight road along +y (north), 10 m wide, two 3.5 m lanes and 1.5 m shoulders."""
    y = np.arange(-100.0, 300.0, 2.0)
    return sim_pb2.SceneResponse(
        centerline_x=np.zeros_like(y),
        centerline_y=y,
        road_half_width=5.0,
        lanes=2,
        lane_width=3.5,
        ego_length=4.5,
        ego_width=1.9,
        obstacles=[
            sim_pb2.Obstacle(kind="car", x=x, y=y, heading=np.pi / 2, length=4.5, width=1.9)
            for x, y in obstacles
        ],
    )


def test_the_window_follows_the_car_heading_up() -> None:
    # The car drives north at y = 50: one car 30 m ahead in the right lane, one 10 m behind,
    # one 150 m ahead (out of the window).
    road = RoadMap.from_scene(_straight_north_scene([(1.75, 80.0), (0.0, 40.0), (0.0, 200.0)]))
    window = Window()
    view = road.view(np.array([0.0, 50.0]), heading=np.pi / 2, window=window)

    (band,) = view.road
    np.testing.assert_allclose(band[:, 0], 0.0, atol=1e-9)  # the road runs straight up
    assert band[:, 1].min() <= window.y_range[0] and band[:, 1].max() >= window.y_range[1]
    assert view.road_radius == 5.0
    marked = list(zip(view.markings, view.marking_radii, strict=True))
    solid = [line for line, radius in marked if radius == EDGE_RADIUS]
    assert sorted(round(float(line[0, 0]), 6) for line in solid) == [-5.0, -3.5, 3.5, 5.0]
    dashes = [line for line, radius in marked if radius == LANE_RADIUS]
    lengths = np.linalg.norm(np.array([d[1] - d[0] for d in dashes]), axis=-1)
    assert len(dashes) > 5 and np.allclose([d[:, 0] for d in dashes], 0.0, atol=1e-9)
    assert np.allclose(lengths[1:-1], DASH[0])
    for car_y in (50.0, 51.3):  # the dashes are painted on the road: they stay put as it moves
        moved = road.view(np.array([0.0, car_y]), heading=np.pi / 2, window=window)
        marked = zip(moved.markings, moved.marking_radii, strict=True)
        starts = [car_y - line[0, 1] for line, radius in marked if radius == LANE_RADIUS]
        painted_from = (np.array(starts[1:]) + 100.0) % sum(DASH)  # the road starts at y=-100
        np.testing.assert_allclose(np.minimum(painted_from, sum(DASH) - painted_from), 0, atol=1e-6)

    centres = view.obstacles.ends.mean(axis=1)
    np.testing.assert_allclose(centres, [[1.75, -30.0], [0.0, 10.0]], atol=1e-9)
    np.testing.assert_allclose(view.obstacles.radii, 0.95)
    along = np.abs(view.obstacles.ends[:, 0, 1] - view.obstacles.ends[:, 1, 1])
    np.testing.assert_allclose(along + 2 * 0.95, 4.5)  # caps end at the box ends

    turned = road.view(np.array([0.0, 50.0]), heading=np.pi / 2 - 0.2, window=window)
    (band,) = turned.road
    ahead = band[np.argmin(np.abs(band[:, 1] + 40.0))]  # the point about 40 m ahead
    assert ahead[0] < -5.0  # heading right of the road: the road ahead bends to the left


def test_window_and_trail_checks() -> None:
    assert Window().contains(np.array([[0.0, -59.0], [0.0, -61.0], [16.0, 0.0]])).tolist() == [
        True,
        False,
        False,
    ]
    with pytest.raises(ValueError, match="non-negative extents"):
        Window(half_width=0.0)
    trail = Trail(capacity=5)
    trail.extend(np.array([[float(x), 0.0] for x in range(8)]))
    trail.extend(np.array([[np.nan, 0.0]]))
    np.testing.assert_array_equal(trail.points()[:, 0], [3, 4, 5, 6, 7])
    trail.clear()
    assert len(trail.points()) == 0
    with pytest.raises(ValueError, match="capacity of at least 2"):
        Trail(capacity=1)


def _has(image: np.ndarray, color: tuple[int, int, int]) -> np.ndarray:
    return (image == np.array(color, np.uint8)).all(-1)


def test_a_live_rollout_draws_a_readable_view(tmp_path: Path) -> None:
    """The autopilot drives 30 steps (6 s) through an urban street; the last step's view is
    drawn as rerun would and saved as ``topdown.png``."""
    env = OasisEnv(
        "local",
        1,
        "urban street",
        server=ServerConfig(width=48, height=32, processes=0),
        expert=True,
    )
    env.set_seed(3)
    path = tmp_path / "topdown.rrd"
    with RolloutLogger(path, LogOptions(background=False)) as rerun_logger:
        logged = env.append_transform(RerunTransform(rerun_logger))
        rollout = logged.rollout(30, Autopilot())
    env.close()
    assert not rollout["next", "done"].any()
    readback = Readback(path)
    last = max(readback.column("env/0/topdown/car", "LineStrips2D:strips")[0])
    layers = {
        name: layer_at(readback, f"env/0/topdown/{name}", last)
        for name in ("road", "lanes", "obstacles", "path", "car")
    }
    image = draw(layers, Window(), PIXELS_PER_METRE)
    Image.fromarray(image).save(tmp_path / "topdown.png")

    height, width = image.shape[:2]
    assert (height, width) == (80 * PIXELS_PER_METRE, 30 * PIXELS_PER_METRE)
    car_row, car_column = 60 * PIXELS_PER_METRE, 15 * PIXELS_PER_METRE  # 20 m from the bottom
    car = _has(image, CAR_COLOR)
    rows, columns = np.nonzero(car)
    assert car[car_row, car_column]
    assert (rows.max() - rows.min()) / PIXELS_PER_METRE == pytest.approx(4.5, abs=0.3)
    assert (columns.max() - columns.min()) / PIXELS_PER_METRE == pytest.approx(1.9, abs=0.3)
    assert _has(image, ROAD_COLOR).mean() > 0.15  # the road band fills a good part of the view
    edges = np.flatnonzero(_has(image[car_row], EDGE_COLOR))
    assert edges.min() < car_column < edges.max()  # road edges or lane lines on both sides
    assert _has(image[car_row + 3 * PIXELS_PER_METRE :], PATH_COLOR).any()  # the path behind
    assert any(_has(image, color).any() for color in OBSTACLE_COLORS.values())
