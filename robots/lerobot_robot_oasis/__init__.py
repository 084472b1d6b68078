"""LeRobot robot plugin ``lerobot_robot_oasis``: one Oasis world-model session as a robot,
type ``oasis``.

LeRobot imports every installed distribution named ``lerobot_robot_*`` before parsing the flags of
its tools; importing this package registers ``--robot.type=oasis``.

>>> from lerobot.robots import RobotConfig
>>> "oasis" in RobotConfig.get_known_choices()
True
"""

from lerobot_robot_oasis.config_oasis import ROBOT_TYPE, OasisRobotConfig
from lerobot_robot_oasis.robot_oasis import OasisRobot

__all__ = ["ROBOT_TYPE", "OasisRobot", "OasisRobotConfig"]
