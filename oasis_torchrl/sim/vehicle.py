"""Kinematic bicycle model of the ego car, one step per action.

Conventions: ``throttle`` in [-1, 1] (+ accelerates; - brakes, then reverses slowly once
stopped), ``steering`` in [-1, 1] (+ is right, i.e. the heading turns clockwise). The pose is the
centre of the car; the heading is counter-clockwise from +x.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class VehicleParams:
    """Geometry and limits of the car.

    Example:
        >>> VehicleParams(max_speed=25.0).wheelbase
        2.7
    """

    wheelbase: float = 2.7
    rear_to_centre: float = 1.35
    length: float = 4.5
    width: float = 1.9
    max_steer: float = 0.5
    accel: float = 4.0
    brake: float = 8.0
    reverse_accel: float = 1.5
    max_reverse_speed: float = 3.0
    drag: float = 0.0012
    rolling: float = 0.15
    max_speed: float = 14.0


@dataclass(frozen=True, slots=True)
class VehicleState:
    """Pose and signed speed (m/s, negative when reversing) of the car.

    Example:
        >>> VehicleState(0.0, 0.0, 0.0, 0.0).speed
        0.0
    """

    x: float
    y: float
    heading: float
    speed: float


def _drive_speed(speed: float, throttle: float, params: VehicleParams, dt: float) -> float:
    """Speed after the pedals: throttle, brakes (never past a stop) or reverse gear."""
    if throttle >= 0.0:
        return speed + throttle * params.accel * dt
    if speed > 0.05:
        return max(speed + throttle * params.brake * dt, 0.0)
    return speed + throttle * params.reverse_accel * dt


def _resisted_speed(speed: float, params: VehicleParams, dt: float) -> float:
    """Speed after drag and rolling resistance, which stop the car but never reverse it."""
    loss = (params.drag * speed * speed + params.rolling) * dt
    return math.copysign(max(abs(speed) - loss, 0.0), speed)


def clamp(value: float, low: float, high: float) -> float:
    """``value`` limited to ``[low, high]`` (for scalars: many times cheaper than ``np.clip``).

    Example:
        >>> clamp(1.5, -1.0, 1.0), clamp(-0.25, -1.0, 1.0)
        (1.0, -0.25)
    """
    return min(max(value, low), high)


def step_vehicle(
    state: VehicleState, throttle: float, steering: float, params: VehicleParams, dt: float
) -> VehicleState:
    """Advance the car by ``dt`` seconds under one action.

    Example:
        >>> params = VehicleParams()
        >>> state = VehicleState(0.0, 0.0, 0.0, 10.0)
        >>> right = step_vehicle(state, 0.0, 1.0, params, 0.05)
        >>> right.heading < 0.0 and right.x > 0.0  # steering + turns clockwise
        True
    """
    speed = _resisted_speed(_drive_speed(state.speed, throttle, params, dt), params, dt)
    speed = clamp(speed, -params.max_reverse_speed, params.max_speed)
    mean_speed = 0.5 * (state.speed + speed)
    steer_angle = -steering * params.max_steer
    slip = math.atan(params.rear_to_centre / params.wheelbase * math.tan(steer_angle))
    heading = state.heading + mean_speed / params.rear_to_centre * math.sin(slip) * dt
    direction = 0.5 * (state.heading + heading) + slip
    return VehicleState(
        x=state.x + mean_speed * math.cos(direction) * dt,
        y=state.y + mean_speed * math.sin(direction) * dt,
        heading=math.remainder(heading, math.tau),
        speed=speed,
    )
