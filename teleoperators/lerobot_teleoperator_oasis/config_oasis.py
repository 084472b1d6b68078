"""Configurations of the oasis teleoperators (``--teleop.type=oasis_keyboard|oasis_gamepad``)."""

from __future__ import annotations

from dataclasses import dataclass

from lerobot.teleoperators import TeleoperatorConfig


def _check_levels(**levels: float) -> None:
    for name, level in levels.items():
        if not 0.0 <= level <= 1.0:
            raise ValueError(f"teleop.{name} must be within [0, 1], got {level}")


@TeleoperatorConfig.register_subclass("oasis_keyboard")
@dataclass
class OasisKeyboardTeleopConfig(TeleoperatorConfig):
    """Keyboard driving: W throttle, S brake (then reverse), A / D steer left / right.

    Args:
        throttle: ``throttle.vel`` while W is held.
        brake: ``-throttle.vel`` while S is held.
        steering: ``|steering.vel|`` while A or D is held (1 is the full lock).

    Example:
        >>> OasisKeyboardTeleopConfig(steering=0.3).type
        'oasis_keyboard'
    """

    throttle: float = 1.0
    brake: float = 1.0
    steering: float = 0.5

    def __post_init__(self) -> None:
        _check_levels(throttle=self.throttle, brake=self.brake, steering=self.steering)


@TeleoperatorConfig.register_subclass("oasis_gamepad")
@dataclass
class OasisGamepadTeleopConfig(TeleoperatorConfig):
    """Gamepad driving (pygame): a trigger for throttle, one for the brake, a stick to steer.

    Axis numbers are pygame's; the defaults fit an Xbox-layout pad on Linux (left stick X 0,
    left trigger 2, right trigger 5; triggers rest at -1).

    Args:
        joystick: which connected gamepad (pygame's index).
        steering_axis, throttle_axis, brake_axis: the axes read.
        trigger_rest: the value a released trigger reads (-1 on SDL, 0 on some pads).
        deadzone: stick and trigger travel ignored around rest.

    Example:
        >>> OasisGamepadTeleopConfig(deadzone=0.2).steering_axis
        0
    """

    joystick: int = 0
    steering_axis: int = 0
    throttle_axis: int = 5
    brake_axis: int = 2
    trigger_rest: float = -1.0
    deadzone: float = 0.08

    def __post_init__(self) -> None:
        if not 0.0 <= self.deadzone < 1.0:
            raise ValueError(f"teleop.deadzone must be within [0, 1), got {self.deadzone}")
        if self.trigger_rest not in (-1.0, 0.0):
            raise ValueError(f"teleop.trigger_rest must be -1 or 0, got {self.trigger_rest}")
