"""The ego car inside a scene: physics steps, collisions and per-frame ground truth.

A collision is real: when the car's box overlaps an obstacle footprint, or its centre leaves the
road surface (``|d| > road_half_width + OFF_ROAD_MARGIN``), the car stops and stays stopped
(``collided`` stays true) until the world is rebuilt.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from oasis_torchrl.proto import sim_pb2
from oasis_torchrl.sim.scene import Scene
from oasis_torchrl.sim.vehicle import VehicleParams, VehicleState, step_vehicle

#: How far the car's centre may go past the road edge before it counts as off the road.
OFF_ROAD_MARGIN = 0.5
#: Length of the corridor ahead of the car in which obstacles are reported, metres.
CORRIDOR_LENGTH = 60.0
#: Obstacles whose centre is further along the road than this cannot touch the car, metres.
COLLISION_REACH = 12.0
#: Obstacles whose centre is within this many metres of the car's along the road are searched for
#: the distances ahead (the corridor plus room for long obstacles on curves), metres.
CORRIDOR_REACH = CORRIDOR_LENGTH + 15.0


@dataclass(frozen=True, slots=True)
class FrameTruth:
    """Ground truth of one frame (same fields and meaning as ``sim.proto`` ``FrameTruth``).

    Example:
        >>> truth = FrameTruth(0, 0, 0, 0, 0, 0, 0, 0, False, math.inf, False, 5.0, math.inf,
        ...                    0.2, 1, 0, 40.0, 5.0, 0.0)
        >>> message = truth.to_proto()
        >>> message.obstacle_distance_left, message.lanes_left, message.lane_obstacle_distance
        (5.0, 1, 40.0)
    """

    x: float
    y: float
    heading: float
    speed: float
    distance: float
    progress: float
    lateral_offset: float
    heading_error: float
    collided: bool
    obstacle_distance: float
    off_road: bool
    obstacle_distance_left: float
    obstacle_distance_right: float
    lane_offset: float
    lanes_left: int
    lanes_right: int
    lane_obstacle_distance: float
    lane_obstacle_distance_left: float
    lane_obstacle_distance_right: float

    def to_proto(self) -> sim_pb2.FrameTruth:
        """The protobuf message of this truth."""
        return sim_pb2.FrameTruth(
            x=self.x,
            y=self.y,
            heading=self.heading,
            speed=self.speed,
            distance=self.distance,
            progress=self.progress,
            lateral_offset=self.lateral_offset,
            heading_error=self.heading_error,
            collided=self.collided,
            obstacle_distance=self.obstacle_distance,
            off_road=self.off_road,
            obstacle_distance_left=self.obstacle_distance_left,
            obstacle_distance_right=self.obstacle_distance_right,
            lane_offset=self.lane_offset,
            lanes_left=self.lanes_left,
            lanes_right=self.lanes_right,
            lane_obstacle_distance=self.lane_obstacle_distance,
            lane_obstacle_distance_left=self.lane_obstacle_distance_left,
            lane_obstacle_distance_right=self.lane_obstacle_distance_right,
        )


@dataclass(frozen=True, slots=True)
class Box:
    """An oriented rectangle on the ground: centre, heading, full length (along) and width.

    Example:
        >>> Box(0.0, 0.0, 0.0, 4.0, 2.0).length
        4.0
    """

    x: float
    y: float
    heading: float
    length: float
    width: float


def boxes_overlap(
    box: Box,
    x: np.ndarray,
    y: np.ndarray,
    heading: np.ndarray,
    length: np.ndarray,
    width: np.ndarray,
) -> np.ndarray:
    """Which of many oriented rectangles overlap ``box`` (separating-axis test, vectorised).

    Rectangles whose bounding circle misses ``box`` are ruled out first, so the full test runs
    only on the few near ones.

    Example:
        >>> hits = boxes_overlap(
        ...     Box(0, 0, 0, 4, 2), np.array([3.0, 6.0]), np.zeros(2), np.zeros(2),
        ...     np.full(2, 4.0), np.full(2, 2.0))
        >>> hits.tolist()
        [True, False]
    """
    cos, sin = math.cos(box.heading), math.sin(box.heading)
    dx, dy = np.asarray(x) - box.x, np.asarray(y) - box.y
    along, across = dx * cos + dy * sin, dy * cos - dx * sin
    radius = np.hypot(length, width) / 2
    gap_along = np.maximum(np.abs(along) - box.length / 2, 0.0)
    gap_across = np.maximum(np.abs(across) - box.width / 2, 0.0)
    overlap = np.hypot(gap_along, gap_across) <= radius
    near = np.flatnonzero(overlap)
    if near.size:
        overlap[near] = _separating_axes_overlap(
            box, along[near], across[near], heading[near] - box.heading, length[near], width[near]
        )
    return overlap


def _separating_axes_overlap(
    box: Box,
    along: np.ndarray,
    across: np.ndarray,
    relative_heading: np.ndarray,
    length: np.ndarray,
    width: np.ndarray,
) -> np.ndarray:
    """Separating-axis test of rectangles given in ``box``'s frame (centre and heading)."""
    cos, sin = np.abs(np.cos(relative_heading)), np.abs(np.sin(relative_heading))
    half_length, half_width = length / 2, width / 2
    # Axes of the box: the rectangles' reach along them.
    separated = np.abs(along) > box.length / 2 + half_length * cos + half_width * sin
    separated |= np.abs(across) > box.width / 2 + half_length * sin + half_width * cos
    # Axes of each rectangle: the box's reach along them.
    signed_cos, signed_sin = np.cos(relative_heading), np.sin(relative_heading)
    own_along = np.abs(along * signed_cos + across * signed_sin)
    own_across = np.abs(across * signed_cos - along * signed_sin)
    separated |= own_along > half_length + box.length / 2 * cos + box.width / 2 * sin
    separated |= own_across > half_width + box.length / 2 * sin + box.width / 2 * cos
    return ~separated


class World:
    """One car driving in one scene, starting at rest in the rightmost lane at ``s = 0``.

    Args:
        scene: The static world.
        dt: Seconds per step (one action).
        params: Car geometry and limits (default: speed cap of the scene's layout).

    Example:
        >>> from oasis_torchrl.sim.scene import build_scene
        >>> world = World(build_scene("highway", 0), dt=0.05)
        >>> for _ in range(20):
        ...     truth = world.advance(1.0, 0.0)
        >>> truth.speed > 3.0 and truth.progress > 1.0 and not truth.collided
        True
    """

    def __init__(self, scene: Scene, dt: float, params: VehicleParams | None = None) -> None:
        self.scene = scene
        self.dt = dt
        self.params = params or VehicleParams(max_speed=scene.style.speed_limit)
        x, y, heading = scene.road.pose_at(0.0, scene.style.lane_offset(scene.start_lane))
        self.state = VehicleState(float(x), float(y), float(heading), 0.0)
        self.steps = 0
        self._distance = 0.0
        self._collided = False
        self._off_road = False
        self._road_position = self._locate()
        self.truth = self._measure()

    def car_box(self) -> Box:
        """The car's footprint now."""
        state = self.state
        return Box(state.x, state.y, state.heading, self.params.length, self.params.width)

    def advance(self, throttle: float, steering: float) -> FrameTruth:
        """Apply one action for ``dt`` seconds and return the truth of the new frame."""
        self.steps += 1
        if not self._collided:
            previous = self.state
            self.state = step_vehicle(previous, throttle, steering, self.params, self.dt)
            self._distance += math.hypot(self.state.x - previous.x, self.state.y - previous.y)
            self._road_position = self._locate()
            self._check_collisions()
        self.truth = self._measure()
        return self.truth

    def _locate(self) -> tuple[float, float]:
        """Road coordinates ``(s, d)`` of the car's centre."""
        s, lateral = self.scene.road.locate(self.state.x, self.state.y, iterations=2)
        return float(s), float(lateral)

    def _nearby(self, reach: float) -> slice:
        """Obstacles whose ``s`` is within ``reach`` metres of the car's."""
        s = self._road_position[0]
        return self.scene.obstacles.between(s - reach, s + reach)

    def _overlapping(self, box: Box, near: slice) -> np.ndarray:
        """Which of the obstacles in ``near`` overlap ``box``."""
        obstacles = self.scene.obstacles
        return boxes_overlap(
            box,
            obstacles.x[near],
            obstacles.y[near],
            obstacles.heading[near],
            obstacles.length[near],
            obstacles.width[near],
        )

    def _check_collisions(self) -> None:
        """Stop the car for good if it hits an obstacle or leaves the road surface."""
        lateral = self._road_position[1]
        self._off_road = bool(self._beyond_road(lateral))
        near = self._nearby(COLLISION_REACH)
        if self._off_road or bool(self._overlapping(self.car_box(), near).any()):
            self._collided = True
            self.state = VehicleState(self.state.x, self.state.y, self.state.heading, 0.0)

    def _beyond_road(self, lateral: float | np.ndarray) -> bool | np.ndarray:
        """Whether lateral offsets ``d`` lie off the road surface (a collision for the car)."""
        return np.abs(lateral) > self.scene.style.road_half_width + OFF_ROAD_MARGIN

    def _obstacle_distance(self, near: slice) -> float:
        """Distance from the front bumper to the nearest obstacle in the corridor ahead, among
        the obstacles in ``near``."""
        state, obstacles = self.state, self.scene.obstacles
        forward = np.array([math.cos(state.heading), math.sin(state.heading)])
        half_length = self.params.length / 2
        centre = np.array([state.x, state.y]) + forward * (half_length + CORRIDOR_LENGTH / 2)
        corridor = Box(*centre, state.heading, CORRIDOR_LENGTH, self.params.width)
        index = np.flatnonzero(self._overlapping(corridor, near)) + near.start
        if index.size == 0:
            return math.inf
        along = (obstacles.x[index] - state.x) * forward[0]
        along += (obstacles.y[index] - state.y) * forward[1]
        relative = obstacles.heading[index] - state.heading
        reach = 0.5 * (
            obstacles.length[index] * np.abs(np.cos(relative))
            + obstacles.width[index] * np.abs(np.sin(relative))
        )
        return float(max(np.min(along - reach) - half_length, 0.0))

    def _side_distances(self, near: slice) -> tuple[float, float]:
        """Road distance from the front bumper to the nearest obstacle ahead in the strips one
        lane width to the left and to the right of the car (0 where the strip is off the road),
        among the obstacles in ``near``.

        Measured along the road (``s``, ``d``), not the car's heading: the question is whether
        the next lane over is open, whichever way the car points right now.
        """
        lateral, width = self._road_position[1], self.scene.style.lane_width
        left, right = self._strip_distances(np.array([lateral + width, lateral - width]), near)
        return float(left), float(right)

    def _lane_distances(self, lane: int, near: slice) -> tuple[float, float, float]:
        """The same distances in the lanes themselves: the car's lane ``lane``, the lane to its
        left and the one to its right (0 where there is no such lane).

        Lane-centred, they say what a driver decides on (is my lane blocked, is the next one
        open) the same way whatever the car's position within its lane: a clone of the autopilot
        fed these (with the lanes on each side and the offset in the lane) drives much farther
        than one fed the car-centred strips (docs/experiments/2026-11-25-state-clone.md).
        """
        style = self.scene.style
        lanes = np.array([lane, lane + 1, lane - 1])
        centres = np.array([style.lane_offset(int(index)) for index in lanes])
        distances = self._strip_distances(centres, near)
        own, left, right = np.where((lanes >= 0) & (lanes < style.lanes), distances, 0.0)
        return float(own), float(left), float(right)

    def _strip_distances(self, centres: np.ndarray, near: slice) -> np.ndarray:
        """Road distance from the front bumper to the nearest obstacle ahead (within
        ``CORRIDOR_LENGTH``) in a strip of the car's width around each lateral offset of
        ``centres``; 0 for a strip off the road, ``inf`` for a clear one."""
        s = self._road_position[0]
        obstacles = self.scene.obstacles
        half_length = self.params.length / 2
        in_strip = np.abs(obstacles.d[near] - centres[:, None]) < obstacles.half_across[near] + (
            self.params.width / 2
        )
        gaps = obstacles.s[near] - obstacles.half_along[near] - s - half_length
        not_behind = obstacles.s[near] + obstacles.half_along[near] > s - half_length
        in_reach = in_strip & not_behind & (gaps < CORRIDOR_LENGTH)
        ahead = np.where(in_reach, np.maximum(gaps, 0.0), math.inf)
        distances = ahead.min(axis=1, initial=math.inf)
        return np.where(self._beyond_road(centres), 0.0, distances)

    def _measure(self) -> FrameTruth:
        """Truth of the current state."""
        state = self.state
        s, lateral = self._road_position
        _, _, road_heading = self.scene.road.pose_at(s)
        near = self._nearby(CORRIDOR_REACH)
        left, right = self._side_distances(near)
        lane = self.scene.style.nearest_lane(lateral)
        in_lane, lane_left, lane_right = self._lane_distances(lane, near)
        lanes = self.scene.style.lanes
        return FrameTruth(
            x=state.x,
            y=state.y,
            heading=state.heading,
            speed=state.speed,
            distance=self._distance,
            progress=s,
            lateral_offset=lateral,
            heading_error=math.remainder(state.heading - float(road_heading), math.tau),
            collided=self._collided,
            obstacle_distance=self._obstacle_distance(near),
            off_road=self._off_road,
            obstacle_distance_left=left,
            obstacle_distance_right=right,
            lane_offset=lateral - self.scene.style.lane_offset(lane),
            lanes_left=lanes - 1 - lane,
            lanes_right=lane,
            lane_obstacle_distance=in_lane,
            lane_obstacle_distance_left=lane_left,
            lane_obstacle_distance_right=lane_right,
        )
