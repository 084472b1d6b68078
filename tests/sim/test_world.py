"""Physics and ground truth: collisions stop the car for good, truth signs and distances."""

from __future__ import annotations

import itertools
import math

import pytest

from oasis_torchrl.sim.scene import Scene, build_scene, obstacles_at
from oasis_torchrl.sim.vehicle import VehicleState
from oasis_torchrl.sim.world import FrameTruth, World


def scene_with_car_ahead(distance: float) -> Scene:
    """A rural scene whose only obstacle is a car ``distance`` metres ahead in the start lane."""
    scene = build_scene("rural", 0)
    lane = scene.style.lane_offset(scene.start_lane)
    return scene.with_obstacles(obstacles_at(scene.road, ["car"], [distance], [lane]))


def test_driving_into_an_obstacle_stops_the_car_for_good() -> None:
    world = World(scene_with_car_ahead(25.0), dt=0.05)
    distances = []
    for _ in range(200):
        truth = world.advance(1.0, 0.0)
        if truth.collided:
            break
        distances.append(truth.obstacle_distance)
    assert truth.collided and not truth.off_road and truth.speed == 0.0
    assert distances[0] == pytest.approx(25.0 - 2.2 - 2.25, abs=0.3)
    assert all(later <= earlier for earlier, later in itertools.pairwise(distances))
    for _ in range(10):
        after = world.advance(1.0, -1.0)
    assert after.collided and after.speed == 0.0
    assert (after.x, after.y, after.distance) == (truth.x, truth.y, truth.distance)


def test_leaving_the_road_is_an_off_road_collision() -> None:
    scene = build_scene("rural", 0)
    world = World(scene, dt=0.05)
    for _ in range(300):
        truth = world.advance(0.6, 1.0)
        if truth.collided:
            break
    assert truth.collided and truth.off_road and truth.speed == 0.0
    assert abs(truth.lateral_offset) > scene.style.road_half_width


@pytest.mark.parametrize(("steering", "sign"), [(-0.5, 1.0), (0.5, -1.0)])
def test_steering_sign_moves_heading_and_lateral_offset(steering: float, sign: float) -> None:
    world = World(scene_with_car_ahead(500.0), dt=0.05)
    start = world.truth
    for _ in range(20):
        truth = world.advance(0.8, steering)
    assert math.copysign(1.0, truth.heading_error) == sign
    assert math.copysign(1.0, truth.lateral_offset - start.lateral_offset) == sign
    assert truth.distance == pytest.approx(truth.progress, rel=0.05)


def test_truth_at_start() -> None:
    scene = build_scene("highway", 4)
    truth = World(scene, dt=0.05).truth
    assert truth.speed == 0.0 and truth.distance == 0.0 and truth.progress == pytest.approx(0.0)
    assert truth.lateral_offset == pytest.approx(scene.style.lane_offset(0))
    assert truth.obstacle_distance == math.inf and not truth.collided
    assert truth.to_proto().lateral_offset == pytest.approx(truth.lateral_offset)


def test_side_distances_report_the_lanes_beside_the_car() -> None:
    scene = build_scene("rural", 0)  # two lanes: the car starts in the right one
    left_lane = scene.style.lane_offset(scene.start_lane + 1)
    scene = scene.with_obstacles(obstacles_at(scene.road, ["car"], [30.0], [left_lane]))
    world = World(scene, dt=0.05)
    truth = world.advance(0.0, 0.0)
    assert truth.obstacle_distance == math.inf
    assert truth.obstacle_distance_left == pytest.approx(30.0 - 2.2 - 2.25, abs=0.3)
    assert truth.obstacle_distance_right == 0.0  # one lane to the right is off the road
    for _ in range(200):
        truth = world.advance(1.0, 0.0)
        if truth.progress > 40.0:
            break
    assert truth.obstacle_distance_left == math.inf and not truth.collided


def test_lane_distances_follow_the_lanes_not_the_car() -> None:
    scene = build_scene("rural", 0)  # two lanes: the car starts in the right one
    style = scene.style
    right_lane, left_lane = style.lane_offset(0), style.lane_offset(1)
    scene = scene.with_obstacles(obstacles_at(scene.road, ["car"], [30.0], [left_lane]))
    world = World(scene, dt=0.05)
    ahead = 30.0 - 2.2 - 2.25  # obstacle centre minus its half length and the car's

    def standing_at(lateral: float) -> FrameTruth:
        x, y, heading = scene.road.pose_at(0.0, lateral)
        world.state = VehicleState(float(x), float(y), float(heading), 0.0)
        return world.advance(0.0, 0.0)

    start = standing_at(right_lane)
    assert (start.lanes_left, start.lanes_right, start.lane_offset) == (1, 0, pytest.approx(0))
    assert start.lane_obstacle_distance == math.inf
    assert start.lane_obstacle_distance_left == pytest.approx(ahead, abs=0.3)
    assert start.lane_obstacle_distance_right == 0.0  # no lane there
    # Most of the way to the lane line: the car's path grazes the obstacle, its lane is clear and
    # the lane to the left is still the one with the obstacle.
    shifted = standing_at(right_lane + 0.45 * style.lane_width)
    assert shifted.lane_offset == pytest.approx(0.45 * style.lane_width)
    assert shifted.obstacle_distance == pytest.approx(ahead, abs=0.3)
    assert shifted.lane_obstacle_distance == math.inf
    assert shifted.lane_obstacle_distance_left == pytest.approx(ahead, abs=0.3)
    # Past the line the car is in the left lane: the obstacle is in its own lane now.
    crossed = standing_at(right_lane + 0.55 * style.lane_width)
    assert (crossed.lanes_left, crossed.lanes_right) == (0, 1)
    assert crossed.lane_offset == pytest.approx(-0.45 * style.lane_width)
    assert crossed.lane_obstacle_distance == pytest.approx(ahead, abs=0.3)
    assert crossed.lane_obstacle_distance_left == 0.0
    assert crossed.lane_obstacle_distance_right == math.inf
    message = crossed.to_proto()
    assert (message.lanes_right, message.lane_obstacle_distance) == (
        1,
        crossed.lane_obstacle_distance,
    )
