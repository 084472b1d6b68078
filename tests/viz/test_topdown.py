"""Top-down map geometry, the path buffer, and the local scene source against the real server."""

from __future__ import annotations

import numpy as np
import pytest

from oasis_torchrl.proto import sim_pb2
from oasis_torchrl.viz.topdown import RoadMap, Trail, box_outlines, local_scene, to_view


def test_local_scene_is_what_the_embedded_server_answers(stubs) -> None:
    session = stubs.open_session(prompt="urban street at night", seed=7)
    answered = stubs.sim.GetScene(
        sim_pb2.SceneRequest(session_id=session.session_id), metadata=session.metadata, timeout=10
    )
    assert local_scene("urban street at night", 7) == answered
    assert local_scene("urban street at night", 8) != answered


def test_road_edges_obstacles_and_the_patch_near_the_car() -> None:
    scene = local_scene("urban street", 1)
    road = RoadMap.from_scene(scene)
    width = np.linalg.norm(road.left - road.right, axis=-1)
    np.testing.assert_allclose(width, 2 * scene.road_half_width, rtol=1e-9)
    assert len(road.obstacle_outlines) == len(scene.obstacles)

    car = road.centre[len(road.centre) // 3]
    patch = road.near(car, radius=40.0)
    assert patch.road and len(patch.road) == len(patch.road_colors)
    centre_points = np.concatenate(patch.road[2::3])
    assert np.linalg.norm(centre_points - car, axis=-1).max() <= 40.0
    assert len(patch.obstacles) == len(patch.obstacle_colors) < len(scene.obstacles)
    far = road.near(np.array([1e6, 1e6]), radius=40.0)
    assert far.road == [] and len(far.obstacles) == 0


def test_box_outlines_turn_with_the_heading_and_view_flips_north_up() -> None:
    outline = box_outlines(
        np.array([10.0]), np.array([5.0]), np.array([np.pi / 2]), np.array([4.0]), np.array([2.0])
    )[0]
    assert outline.shape == (5, 2) and (outline[0] == outline[-1]).all()  # closed
    np.testing.assert_allclose(outline[:, 0].min(), 9.0)  # across the heading: width 2
    np.testing.assert_allclose(outline[:, 1].max(), 7.0)  # along the heading: length 4
    np.testing.assert_allclose(to_view(outline)[:, 1].min(), -7.0)


def test_trail_is_bounded_and_keeps_the_newest_stretch() -> None:
    trail = Trail(capacity=5)
    trail.extend(np.array([[float(x), 0.0] for x in range(8)]))
    trail.extend(np.array([[np.nan, 0.0]]))
    np.testing.assert_array_equal(trail.points()[:, 0], [3, 4, 5, 6, 7])
    np.testing.assert_array_equal(trail.recent_within(2.5)[:, 0], [5, 6, 7])
    trail.clear()
    assert len(trail.points()) == 0
    with pytest.raises(ValueError, match="capacity of at least 2"):
        Trail(capacity=1)
