"""What the oasis teleoperators share: the robot's action names, no feedback, no calibration."""

from __future__ import annotations

from oasis_torchrl.data.features import ACTION_NAMES

THROTTLE, STEERING = ACTION_NAMES


class CarControls:
    """Mixed into a LeRobot ``Teleoperator`` (listed first) that drives the oasis robot.

    Example:
        >>> CarControls().action_features
        {'throttle.vel': <class 'float'>, 'steering.vel': <class 'float'>}
    """

    @property
    def action_features(self) -> dict[str, type]:
        """The oasis robot's action names."""
        return dict.fromkeys(ACTION_NAMES, float)

    @property
    def feedback_features(self) -> dict:
        """No feedback."""
        return {}

    @property
    def is_calibrated(self) -> bool:
        """Nothing to calibrate."""
        return True
