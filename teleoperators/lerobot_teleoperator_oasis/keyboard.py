"""Keyboard driving of the oasis robot (``--teleop.type=oasis_keyboard``).

Held keys give the action every tick (LeRobot's arrow keys and Esc stay free for its own episode
controls):

=====  =======================================  =============================================
key    action                                   keyboard_rover equivalent
=====  =======================================  =============================================
W      ``throttle.vel = +throttle`` (1.0)       ``linear_velocity = +linear_speed``
S      ``throttle.vel = -brake`` (-1.0: brakes,  ``linear_velocity = -linear_speed``
       then reverses slowly once stopped)
A      ``steering.vel = -steering`` (-0.5)       ``angular_velocity = +angular_speed`` (left)
D      ``steering.vel = +steering`` (+0.5)       ``angular_velocity = -angular_speed`` (right)
none   ``0, 0`` (coasting: drag slows the car)  ``0, 0``
=====  =======================================  =============================================

W with S, or A with D, cancel out. The names are the oasis robot's (and the project's
datasets'): LeRobot's stock ``keyboard_rover`` emits ``linear_velocity`` / ``angular_velocity``
instead, which the robot maps itself (``throttle.vel = linear_velocity``, ``steering.vel =
-angular_velocity``; the car has no turn in place).
"""

from __future__ import annotations

import queue
from collections.abc import Collection

from lerobot.teleoperators.keyboard import KeyboardTeleop
from lerobot.utils.decorators import check_if_not_connected

from lerobot_teleoperator_oasis.config_oasis import OasisKeyboardTeleopConfig
from lerobot_teleoperator_oasis.controls import STEERING, THROTTLE, CarControls


def keyboard_action(
    held: Collection[object], config: OasisKeyboardTeleopConfig
) -> dict[str, float]:
    """The action of the ``held`` keys (characters, any case; other keys are ignored).

    Example:
        >>> keyboard_action({"w", "D"}, OasisKeyboardTeleopConfig())
        {'throttle.vel': 1.0, 'steering.vel': 0.5}
        >>> keyboard_action({"s", "a", "d"}, OasisKeyboardTeleopConfig(brake=0.5))
        {'throttle.vel': -0.5, 'steering.vel': 0.0}
    """
    keys = {key.lower() for key in held if isinstance(key, str)}
    throttle = config.throttle * ("w" in keys) - config.brake * ("s" in keys)
    steering = config.steering * (("d" in keys) - ("a" in keys))
    return {THROTTLE: float(throttle), STEERING: float(steering)}


class OasisKeyboardTeleop(CarControls, KeyboardTeleop):
    """WASD driving through LeRobot's keyboard listener (pynput: an X11 session, Windows or
    macOS with input monitoring allowed).

    Args:
        config: :class:`~lerobot_teleoperator_oasis.OasisKeyboardTeleopConfig`.

    Example:
        >>> teleop = OasisKeyboardTeleop(OasisKeyboardTeleopConfig())
        >>> teleop.action_features
        {'throttle.vel': <class 'float'>, 'steering.vel': <class 'float'>}
    """

    config_class = OasisKeyboardTeleopConfig
    name = "oasis_keyboard"

    def __init__(self, config: OasisKeyboardTeleopConfig) -> None:
        super().__init__(config)
        self.config = config
        self._held: set[object] = set()

    @check_if_not_connected
    def get_action(self) -> dict[str, float]:
        """The action of the keys held now."""
        while True:
            try:
                key, pressed = self.event_queue.get_nowait()
            except queue.Empty:
                break
            key = key.lower() if isinstance(key, str) else key
            if pressed:
                self._held.add(key)
            else:
                self._held.discard(key)
        return keyboard_action(self._held, self.config)
