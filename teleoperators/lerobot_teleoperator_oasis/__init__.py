"""LeRobot teleoperator plugin ``lerobot_teleoperator_oasis``: drive the oasis robot with a
keyboard (``--teleop.type=oasis_keyboard``) or, with the ``gamepad`` extra, the analog sticks and
triggers of a gamepad (``--teleop.type=oasis_gamepad``).

Both emit the oasis robot's action names, ``throttle.vel`` and ``steering.vel`` (LeRobot looks a
recorded row's action up in the teleoperator's output by the robot's names), so a person's
recordings share their features with the project's own datasets.

>>> from lerobot.teleoperators import TeleoperatorConfig
>>> {"oasis_keyboard", "oasis_gamepad"} <= set(TeleoperatorConfig.get_known_choices())
True
"""

from lerobot_teleoperator_oasis.config_oasis import (
    OasisGamepadTeleopConfig,
    OasisKeyboardTeleopConfig,
)
from lerobot_teleoperator_oasis.gamepad import OasisGamepadTeleop, gamepad_action
from lerobot_teleoperator_oasis.keyboard import OasisKeyboardTeleop, keyboard_action

__all__ = [
    "OasisGamepadTeleop",
    "OasisGamepadTeleopConfig",
    "OasisKeyboardTeleop",
    "OasisKeyboardTeleopConfig",
    "gamepad_action",
    "keyboard_action",
]
