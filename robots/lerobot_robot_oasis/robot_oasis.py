"""The oasis robot: one world-model session driven by LeRobot's tools, one action per tick.

Features (the names of the project's datasets, :mod:`oasis_torchrl.data.features`):

- observation: the three cameras ``left_forward``, ``front``, ``right_forward`` (``(H, W, 3)``
  frames, recorded as ``observation.images.<camera>``; with ``--robot.front_crop`` also the
  narrow forward ``front_crop``) and ``throttle.vel``, ``steering.vel``,
  the previous action (recorded as ``observation.state``);
- action: ``throttle.vel``, ``steering.vel`` in ``[-1, 1]`` (recorded as ``action``).

LeRobot's rover teleoperators (``--teleop.type=keyboard_rover``) drive it too: their
``linear_velocity`` (+ forward) is the throttle, and their ``angular_velocity`` (+ turns left,
counter-clockwise, as ``keyboard_rover``'s A key does) is the steering negated (the world's
steering + turns right), both clipped to ``[-1, 1]`` (:func:`rover_to_oasis`).

The cameras are virtual: the session produces the frames, so ``robot.cameras`` is empty (as for
LeRobot's ``earthrover_mini_plus``). LeRobot's tools tick at the dataset's fps, which must be the
world's 20 (``--dataset.fps=20``). Four ticks make one world-model call, by sample and hold
(:mod:`oasis_torchrl.envs.per_frame`): a tick observes the newest frames and the action sent
before it, and its action is buffered until the chunk's 4th. A recorded row's action is the one
applied next, its state the one before, as in the project's own datasets.

Episodes. ``connect`` prompts the world with ``seed``. When ``lerobot-record`` (or
``lerobot-rollout``'s episodic strategy) starts dataset episode ``N``, the world is re-prompted
with ``seed + N`` (a re-recorded episode gets its seed again), so every episode starts from a
fresh scene that ``lerobot-replay --robot.seed=<seed + N>`` rebuilds. Elsewhere (``lerobot-replay``,
``-teleoperate``, DAgger, the async robot client) one connection drives one world;
:meth:`OasisRobot.start_episode` re-prompts it from code.
"""

from __future__ import annotations

import logging
from functools import cached_property
from typing import Any

import numpy as np
from lerobot.robots import Robot
from lerobot.utils.decorators import check_if_already_connected, check_if_not_connected

from lerobot_robot_oasis.config_oasis import ROBOT_TYPE, OasisRobotConfig
from oasis_torchrl.compat import on_lerobot_episode_start
from oasis_torchrl.data.features import ACTION_NAMES
from oasis_torchrl.envs.per_frame import FrameStepper

logger = logging.getLogger(__name__)

ROVER_ACTION_NAMES = ("linear_velocity", "angular_velocity")
"""The action of LeRobot's rover teleoperators (``keyboard_rover``)."""


def rover_to_oasis(action: dict[str, Any]) -> dict[str, Any]:
    """Add ``throttle.vel`` and ``steering.vel`` to a rover teleoperator's action, in place.

    In place because ``lerobot-record`` builds the dataset row from the very dict it sends to
    the robot: the row then records the action the world applied. An action that already has
    the oasis names, or lacks the rover's, is returned untouched.

    Example:
        >>> rover_to_oasis({"linear_velocity": 1.2, "angular_velocity": 0.6})
        {'linear_velocity': 1.2, 'angular_velocity': 0.6, 'throttle.vel': 1.0, 'steering.vel': -0.6}
    """
    if all(name in action for name in ACTION_NAMES) or not all(
        name in action for name in ROVER_ACTION_NAMES
    ):
        return action
    linear, angular = (float(action[name]) for name in ROVER_ACTION_NAMES)
    throttle, steering = ACTION_NAMES
    action[throttle] = float(np.clip(linear, -1.0, 1.0))
    action[steering] = float(np.clip(-angular, -1.0, 1.0))
    return action


class OasisRobot(Robot):
    """A world-model session as a LeRobot robot (``--robot.type=oasis``).

    Args:
        config: :class:`~lerobot_robot_oasis.OasisRobotConfig`.

    Example:
        >>> robot = OasisRobot(OasisRobotConfig(seed=3))
        >>> robot.connect()
        >>> observation = robot.get_observation()
        >>> observation["front"].shape, observation["throttle.vel"]
        ((64, 96, 3), 0.0)
        >>> robot.send_action({"throttle.vel": 1.5, "steering.vel": -0.25})
        {'throttle.vel': 1.0, 'steering.vel': -0.25}
        >>> robot.get_observation()["steering.vel"]
        -0.25
        >>> robot.disconnect()
    """

    config_class = OasisRobotConfig
    name = ROBOT_TYPE

    def __init__(self, config: OasisRobotConfig) -> None:
        super().__init__(config)
        self.config = config
        self.cameras: dict[str, Any] = {}  # virtual: the session produces the frames
        self._stepper: FrameStepper | None = None
        self._rerun: Any = None
        self._stop_listening: Any = None
        self._episode = 0
        self._requested: int | None = None
        self._untouched = False

    @cached_property
    def observation_features(self) -> dict[str, type | tuple[int, int, int]]:
        """The cameras' ``(H, W, 3)`` frames and the previous action."""
        frame = (self.config.image_height, self.config.image_width, 3)
        cameras = dict.fromkeys(self.config.camera_names, frame)
        return {**cameras, **dict.fromkeys(ACTION_NAMES, float)}

    @cached_property
    def action_features(self) -> dict[str, type]:
        """``throttle.vel`` and ``steering.vel`` in ``[-1, 1]``."""
        return dict.fromkeys(ACTION_NAMES, float)

    @property
    def is_connected(self) -> bool:
        """Whether the session is open."""
        return self._stepper is not None

    @property
    def is_calibrated(self) -> bool:
        """A world model needs no calibration."""
        return True

    @property
    def episode(self) -> int:
        """The dataset episode the world was last prompted for (its seed: ``seed + episode``)."""
        return self._episode

    @check_if_already_connected
    def connect(self, calibrate: bool = True) -> None:
        """Open the session (starting the embedded server for ``endpoint=local``) and prompt
        episode 0."""
        self._stepper = FrameStepper(self.config.world())
        try:
            if self.config.rerun:
                from oasis_torchrl.viz import RolloutLogger

                # LeRobot's tools end a session by a signal as often as by disconnect(): the
                # recording takes what is logged as it comes, as a viewer would.
                name = self.config.id or self.name  # the robot's: it names no policy
                self._rerun = RolloutLogger(self.config.rerun, live=True, name=name)
            self._begin(0)
        except Exception:
            self.disconnect()
            raise
        self._stop_listening = on_lerobot_episode_start(self.start_episode)
        logger.info("oasis robot connected to %s: %r", self.config.endpoint, self.config.prompt)

    def calibrate(self) -> None:
        """Nothing to calibrate."""

    def configure(self) -> None:
        """Nothing to configure."""

    def start_episode(self, index: int) -> None:
        """Re-prompt the world for dataset episode ``index`` (seed ``seed + index``) before the
        next observation; a world prompted for it and not driven yet is kept."""
        self._requested = int(index)

    @check_if_not_connected
    def get_observation(self) -> dict[str, Any]:
        """The newest frame of each camera and the last action sent."""
        if self._requested is not None:
            if self._requested != self._episode or not self._untouched:
                self._begin(self._requested)
            self._requested = None
        observation = self._stepper.observation
        frames = {camera: observation.pixels[camera][0] for camera in self.config.camera_names}
        state = dict(zip(ACTION_NAMES, observation.state[0].tolist(), strict=True))
        return {**frames, **state}

    @check_if_not_connected
    def send_action(self, action: dict[str, Any]) -> dict[str, float]:
        """Apply one action (clipped to ``[-1, 1]``; a rover teleoperator's is mapped by
        :func:`rover_to_oasis`); returns it as applied.

        Raises:
            KeyError: a component is missing, naming what the robot takes.
        """
        rover_to_oasis(action)
        missing = [name for name in ACTION_NAMES if name not in action]
        if missing:
            raise KeyError(
                f"the oasis robot takes {list(ACTION_NAMES)}, the action lacks {missing} (got "
                f"{sorted(action)}): drive it with the oasis or rover teleoperators or map names"
            )
        values = np.array([[float(action[name]) for name in ACTION_NAMES]], dtype=np.float32)
        step = self._stepper.step(values)
        self._untouched = False
        if step.chunk is not None and self._rerun is not None:
            self._rerun.log_step(step.chunk.get("next"), step.chunk.get("action"))
        return dict(zip(ACTION_NAMES, step.observation.state[0].tolist(), strict=True))

    @check_if_not_connected
    def disconnect(self) -> None:
        """Close the session (and the embedded server, the rerun recording)."""
        if self._stop_listening is not None:
            self._stop_listening()
            self._stop_listening = None
        try:
            if self._rerun is not None:
                self._rerun.close()
        finally:
            self._rerun = None
            stepper, self._stepper = self._stepper, None
            stepper.close()

    def _begin(self, index: int) -> None:
        """Prompt the world for episode ``index``."""
        seed = self.config.seed + index
        self._stepper.reset(seed=seed)
        self._episode, self._untouched = index, True
        if self._rerun is not None:
            self._rerun.log_reset(self._stepper.last, episodes=[index])
        logger.info("episode %d: %r, seed %d", index, self.config.prompt, seed)
