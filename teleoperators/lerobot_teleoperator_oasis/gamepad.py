"""Gamepad driving of the oasis robot (``--teleop.type=oasis_gamepad``): analog throttle, brake
and steering, read with pygame (the ``gamepad`` extra: ``pip install
'lerobot_teleoperator_oasis[gamepad]'``).

=========================  ============================================================
control (Xbox layout)      action
=========================  ============================================================
right trigger              ``throttle.vel`` from 0 (released) to +1 (pressed fully)
left trigger               subtracted from ``throttle.vel``: brakes, then reverses
left stick, sideways       ``steering.vel`` from -1 (full left) to +1 (full right)
=========================  ============================================================

Travel within ``deadzone`` of rest counts as rest; the rest of the travel is rescaled to the
full range, so the smallest push past the deadzone gives a small action, not a jump.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from lerobot.teleoperators import Teleoperator
from lerobot.utils.decorators import check_if_already_connected, check_if_not_connected
from lerobot.utils.errors import DeviceNotConnectedError

from lerobot_teleoperator_oasis.config_oasis import OasisGamepadTeleopConfig
from lerobot_teleoperator_oasis.controls import STEERING, THROTTLE, CarControls


def _beyond_deadzone(value: float, deadzone: float) -> float:
    """``value`` in ``[-1, 1]`` with ``|value| <= deadzone`` as 0 and the rest rescaled."""
    magnitude = max(abs(value) - deadzone, 0.0) / (1.0 - deadzone)
    return min(magnitude, 1.0) * (1.0 if value >= 0 else -1.0)


def _trigger(value: float, rest: float, deadzone: float) -> float:
    """How far a trigger is pressed, 0 to 1."""
    return max(_beyond_deadzone((value - rest) / (1.0 - rest), deadzone), 0.0)


def gamepad_action(axes: Sequence[float], config: OasisGamepadTeleopConfig) -> dict[str, float]:
    """The action of a gamepad's axis values (pygame's ``get_axis`` for every axis).

    Raises:
        ValueError: an axis of the config is not one of the pad's.

    Example:
        >>> config = OasisGamepadTeleopConfig(deadzone=0.0)
        >>> axes = [0.5, 0.0, -1.0, 0.0, 0.0, 0.0]  # steer half right, throttle half pressed
        >>> gamepad_action(axes, config)
        {'throttle.vel': 0.5, 'steering.vel': 0.5}
        >>> gamepad_action([0.05, 0.0, 1.0, 0.0, 0.0, -1.0], OasisGamepadTeleopConfig())
        {'throttle.vel': -1.0, 'steering.vel': 0.0}
    """
    used = {"steering": config.steering_axis, "throttle": config.throttle_axis}
    used["brake"] = config.brake_axis
    outside = {name: axis for name, axis in used.items() if not 0 <= axis < len(axes)}
    if outside:
        raise ValueError(
            f"the gamepad has {len(axes)} axes; teleop axes {outside} are not among them"
        )
    pressed = _trigger(axes[config.throttle_axis], config.trigger_rest, config.deadzone)
    braked = _trigger(axes[config.brake_axis], config.trigger_rest, config.deadzone)
    steering = _beyond_deadzone(axes[config.steering_axis], config.deadzone)
    return {THROTTLE: round(pressed - braked, 6), STEERING: round(steering, 6)}


class OasisGamepadTeleop(CarControls, Teleoperator):
    """Analog driving with a gamepad or joystick through pygame.

    Args:
        config: :class:`~lerobot_teleoperator_oasis.OasisGamepadTeleopConfig`.

    Example:
        >>> OasisGamepadTeleop(OasisGamepadTeleopConfig()).is_connected
        False
    """

    config_class = OasisGamepadTeleopConfig
    name = "oasis_gamepad"

    def __init__(self, config: OasisGamepadTeleopConfig) -> None:
        super().__init__(config)
        self.config = config
        self._pygame: Any = None
        self._joystick: Any = None

    @property
    def is_connected(self) -> bool:
        """Whether a gamepad is open."""
        return self._joystick is not None

    @check_if_already_connected
    def connect(self, calibrate: bool = True) -> None:
        """Open gamepad ``config.joystick``.

        Raises:
            ImportError: pygame is missing (the ``gamepad`` extra).
            DeviceNotConnectedError: no such gamepad is connected.
        """
        try:
            import pygame
        except ImportError as error:
            raise ImportError(
                "the oasis gamepad teleoperator reads pads with pygame: "
                "pip install 'lerobot_teleoperator_oasis[gamepad]'"
            ) from error
        pygame.init()
        pygame.joystick.init()
        count = pygame.joystick.get_count()
        if not 0 <= self.config.joystick < count:
            pygame.quit()
            raise DeviceNotConnectedError(
                f"gamepad {self.config.joystick} is not connected ({count} found)"
            )
        self._pygame = pygame
        self._joystick = pygame.joystick.Joystick(self.config.joystick)
        self._joystick.init()

    def calibrate(self) -> None:
        """Nothing to calibrate."""

    def configure(self) -> None:
        """Nothing to configure."""

    @check_if_not_connected
    def get_action(self) -> dict[str, float]:
        """The action of the pad's axes now."""
        self._pygame.event.pump()
        axes = [self._joystick.get_axis(axis) for axis in range(self._joystick.get_numaxes())]
        return gamepad_action(axes, self.config)

    def send_feedback(self, feedback: dict[str, Any]) -> None:
        """A pad takes no feedback."""

    @check_if_not_connected
    def disconnect(self) -> None:
        """Close the pad."""
        self._joystick.quit()
        self._joystick = None
        self._pygame.quit()
