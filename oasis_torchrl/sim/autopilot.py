"""The embedded simulator's privileged expert driver (it reads the scene and the car's true state).

Lane keeping is pure pursuit on the centre line of a target lane; speed follows the layout's
speed cap, slowed for curves ahead. Obstacles in the target lane within braking range make it
change to the nearest lane that is free well past them, or brake to a stop in front of them when
no lane is free. Each chunk of 4 actions is planned by stepping the (known, deterministic)
vehicle model, so every action is closed-loop on the state it will act on.

Demonstrations execute its actions with noise (DART), so it must recover from being pushed off
its line: a short pursuit look-ahead steers back within a second or so, and when the car is
pushed towards an obstacle while its target lane is clear it slows to a crawl instead of
stopping (a stopped car cannot steer back, and noisy drives would end stalled).
"""

from __future__ import annotations

import math

import numpy as np

from oasis_torchrl.protocol import CHUNK
from oasis_torchrl.sim.scene import Scene
from oasis_torchrl.sim.simulator import Simulator
from oasis_torchrl.sim.vehicle import VehicleState, clamp, step_vehicle

#: Fraction of the layout's speed cap the autopilot cruises at.
CRUISE_FRACTION = 0.85
#: Lateral acceleration allowed in curves, m/s^2.
CURVE_ACCELERATION = 2.5
#: Deceleration planned for stopping before an obstacle, m/s^2.
PLANNED_BRAKING = 4.0
#: Distance (car centre to obstacle edge) to stop at before a blocked lane, metres.
STOP_GAP = 6.0
#: Closest the car may get to an obstacle right in its path, metres (centre to edge).
MIN_GAP = 3.5
#: Road an intermediate lane must be free for when crossing it, short of the obstacle, metres.
CROSSING_MARGIN = 10.0
#: Lateral clearance kept on each side of the car when judging a lane free, metres.
CLEARANCE = 0.4
#: Speed kept when only the car's actual position is blocked and its target lane is clear, m/s:
#: a stopped car cannot steer back into its lane, so a full stop there never ends.
CRAWL_SPEED = 1.5
SPEED_GAIN = 0.6
#: Pure-pursuit look-ahead: this many seconds of driving plus 5 m.
PURSUIT_TIME = 0.4
#: Obstacles are looked for this many seconds of driving ahead (plus 15 m), at least
#: MIN_LOOK_AHEAD metres.
LOOK_AHEAD_TIME = 3.0
MIN_LOOK_AHEAD = 25.0
#: Reach of the check right in front of the car's actual lateral position, metres.
IMMEDIATE_REACH = 12.0
#: A lane to change to must be free from CHANGE_BEHIND metres behind the car to PASSING_MARGIN
#: metres past the obstacle.
CHANGE_BEHIND = 8.0
PASSING_MARGIN = 25.0


def _stopping_speed(distance: float, gap: float) -> float:
    """The highest speed that can still stop ``gap`` metres short of ``distance`` ahead."""
    return math.sqrt(2 * PLANNED_BRAKING * max(distance - gap, 0.0))


class Autopilot:
    """Lane following and obstacle avoidance with full knowledge of the simulator's world.

    The embedded server runs one per session (restarted at every Prompt) and sends its next
    chunk with the ground truth of every Infer.

    Args:
        simulator: A reset :class:`~oasis_torchrl.sim.simulator.Simulator`.

    Example:
        >>> simulator = Simulator(64, 48)
        >>> simulator.reset("highway", seed=0)
        >>> pilot = Autopilot(simulator)
        >>> for _ in range(25):
        ...     result = simulator.step(pilot.act(), render=False)
        >>> simulator.truth.progress > 30 and not simulator.truth.collided
        True
    """

    def __init__(self, simulator: Simulator) -> None:
        self._simulator = simulator
        self._scene: Scene | None = None
        self._lane = 0

    def act(self) -> np.ndarray:
        """The next 4 actions, ``float32 (4, 2)`` of ``[throttle, steering]``."""
        world = self._simulator.world
        if world.scene is not self._scene or world.steps == 0:
            self._scene = world.scene
            self._lane = self._scene.style.nearest_lane(world.truth.lateral_offset)
        state = world.state
        actions = np.zeros((CHUNK, 2), dtype=np.float32)
        for index in range(CHUNK):
            actions[index] = self._control(state)
            throttle, steering = (float(value) for value in actions[index])
            state = step_vehicle(state, throttle, steering, world.params, world.dt)
        return actions

    def _control(self, state: VehicleState) -> tuple[float, float]:
        """Throttle and steering for one frame from ``state``."""
        scene = self._require_scene()
        s, lateral = (float(value) for value in scene.road.locate(state.x, state.y, 2))
        reach = max(MIN_LOOK_AHEAD, LOOK_AHEAD_TIME * abs(state.speed) + 15.0)
        blocked = self._blocked_distance(scene.style.lane_offset(self._lane), s, reach)
        if blocked is not None:
            free_lane = self._free_lane(s, blocked)
            if free_lane is not None:
                self._lane = free_lane
                blocked = None
        # Right in front: the car's own footprint (no clearance), so passing close to an
        # obstacle in the next lane does not brake.
        ahead = self._blocked_distance(lateral, s, min(reach, IMMEDIATE_REACH), clearance=0.0)
        limits = [self._cruise_speed(), self._curve_speed(s, state.speed)]
        if blocked is not None:
            limits.append(_stopping_speed(blocked, STOP_GAP))
        if ahead is not None:
            floor = CRAWL_SPEED if blocked is None else 0.0
            limits.append(max(_stopping_speed(ahead, MIN_GAP), floor))
        throttle = clamp(SPEED_GAIN * (min(limits) - state.speed), -1.0, 1.0)
        return throttle, self._steering(state, s)

    def _steering(self, state: VehicleState, s: float) -> float:
        """Pure pursuit towards the target lane's centre line."""
        scene = self._require_scene()
        params = self._simulator.world.params
        look_ahead = clamp(PURSUIT_TIME * abs(state.speed) + 5.0, 6.0, 25.0)
        goal_x, goal_y, _ = scene.road.pose_at(s + look_ahead, scene.style.lane_offset(self._lane))
        dx, dy = float(goal_x) - state.x, float(goal_y) - state.y
        cos, sin = math.cos(state.heading), math.sin(state.heading)
        forward, left = dx * cos + dy * sin, -dx * sin + dy * cos
        curvature = 2.0 * left / max(forward * forward + left * left, 1e-6)
        steer_angle = math.atan(params.wheelbase * curvature)
        return clamp(-steer_angle / params.max_steer, -1.0, 1.0)

    def _cruise_speed(self) -> float:
        """The speed to hold on clear, straight road."""
        scene = self._require_scene()
        return CRUISE_FRACTION * scene.style.speed_limit

    def _curve_speed(self, s: float, speed: float) -> float:
        """The speed that keeps lateral acceleration bounded on the road ahead."""
        road = self._require_scene().road
        ahead = s + np.linspace(0.0, 2.0 * abs(speed) + 20.0, 12)
        curvature = float(np.max(np.abs(road.curvature_at(ahead))))
        return math.sqrt(CURVE_ACCELERATION / max(curvature, 1e-6))

    def _blocking(
        self, centre: float, s: float, behind: float, reach: float, clearance: float = CLEARANCE
    ) -> np.ndarray:
        """Distances (from the car's centre to their near edge) of obstacles overlapping the
        corridor of the car's width plus ``clearance`` a side around lateral ``centre``, from
        ``behind`` the car to ``reach`` ahead."""
        scene = self._require_scene()
        obstacles = scene.obstacles
        near = obstacles.between(s - behind - 10.0, s + reach + 10.0)
        half_width = self._simulator.world.params.width / 2 + clearance
        overlaps = np.abs(obstacles.d[near] - centre) < obstacles.half_across[near] + half_width
        edge = obstacles.s[near] - obstacles.half_along[near] - s
        far_edge = obstacles.s[near] + obstacles.half_along[near] - s
        ahead = overlaps & (far_edge > -behind) & (edge < reach)
        return edge[ahead]

    def _blocked_distance(
        self, centre: float, s: float, reach: float, clearance: float = CLEARANCE
    ) -> float | None:
        """Distance to the first obstacle within ``reach`` in a corridor of the car's width
        plus ``clearance`` a side around lateral ``centre`` (None: clear)."""
        edges = self._blocking(centre, s, behind=0.0, reach=reach, clearance=clearance)
        return float(max(edges.min(), 0.0)) if edges.size else None

    def _free_lane(self, s: float, obstacle: float) -> int | None:
        """The nearest lane free from just behind the car to well past an obstacle
        ``obstacle`` metres ahead, whose lanes on the way are free until shortly before it
        (None: no such lane)."""
        style = self._require_scene().style
        for lane in sorted(range(style.lanes), key=lambda lane: (abs(lane - self._lane), -lane)):
            if lane == self._lane:
                continue
            crossed = range(min(lane, self._lane) + 1, max(lane, self._lane))
            reaches = [(lane, obstacle + PASSING_MARGIN)]
            reaches += [(step, obstacle - CROSSING_MARGIN) for step in crossed]
            if all(
                self._blocking(style.lane_offset(step), s, CHANGE_BEHIND, reach).size == 0
                for step, reach in reaches
            ):
                return lane
        return None

    def _require_scene(self) -> Scene:
        if self._scene is None:
            raise RuntimeError("Autopilot.act() must be called first")
        return self._scene
