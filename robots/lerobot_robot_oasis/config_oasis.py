"""Configuration of the oasis robot (``--robot.type=oasis``): which world, scene and frames."""

from __future__ import annotations

from dataclasses import dataclass

from lerobot.robots import RobotConfig

from oasis_torchrl.client.decoding import validate_front_crop
from oasis_torchrl.config import EmbeddedServerConfig, EnvConfig
from oasis_torchrl.data.writer import ROBOT_TYPE
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.protocol import CAMERAS, with_front_crop
from oasis_torchrl.rewards import NoReward
from oasis_torchrl.sim.config import ServerConfig

_ENV = EnvConfig()
_SERVER = EmbeddedServerConfig()


@RobotConfig.register_subclass(ROBOT_TYPE)
@dataclass
class OasisRobotConfig(RobotConfig):
    """Settings of :class:`~lerobot_robot_oasis.OasisRobot`, each a ``--robot.<field>`` flag.

    Args:
        endpoint: ``local`` (an embedded simulator server, started with the robot), an A2V
            server's address (``http://host:port``) or the hosted model
            (``https://oasis-grpc.decart.ai``; the key comes from ``DECART_API_KEY``, never a
            flag).
        prompt: the scene of every episode (``urban``, ``rainy highway at night``, ...).
        seed: the world seed of dataset episode 0; episode ``N`` gets ``seed + N``. Replay
            episode ``N`` with ``--robot.seed=<seed + N>``.
        image_height, image_width: size the camera frames are decoded to (the policy's input
            size; the project's datasets default to 64x96).
        server_width, server_height: frame size the embedded server renders (``local`` only;
            at least what ``front_crop`` needs).
        front_crop: add the narrow forward camera ``front_crop`` (recorded as
            ``observation.images.front_crop``), this fraction of the front frame's centre:
            what a policy trained with ``env.front_crop`` reads. None: the three cameras.
        rerun: also log the session to rerun: an ``.rrd`` path, ``spawn`` or a viewer URL.

    Example:
        >>> OasisRobotConfig(prompt="rural road", seed=7).type
        'oasis'
    """

    endpoint: str = _ENV.endpoint
    prompt: str = _ENV.prompts[0]
    seed: int = 0
    image_height: int = _ENV.image_size[0]
    image_width: int = _ENV.image_size[1]
    server_width: int = _SERVER.width
    server_height: int = _SERVER.height
    front_crop: float | None = None
    rerun: str | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        sizes = (self.image_height, self.image_width, self.server_width, self.server_height)
        if min(sizes) <= 0:
            raise ValueError(f"frame sizes must be positive, got {sizes}")
        if not self.prompt.strip():
            raise ValueError("robot.prompt must be a non-empty scene description")
        validate_front_crop(self.front_crop)

    @property
    def camera_names(self) -> tuple[str, ...]:
        """The robot's virtual cameras: the three streams, then the crop if set (LeRobot's
        ``cameras`` is a robot's physical cameras, which this robot has none of)."""
        return with_front_crop(CAMERAS, self.front_crop)

    def world(self) -> OasisEnv:
        """The robot's world: a one-session env with all 4 frames of each chunk and no reward
        (a robot has none; it opens nothing before its first reset)."""
        return OasisEnv(
            self.endpoint,
            num_envs=1,
            prompts=self.prompt,
            server=ServerConfig(
                width=self.server_width, height=self.server_height, fps=_SERVER.fps
            ),
            frame_size=(self.image_height, self.image_width),
            front_crop=self.front_crop,
            all_frames=True,
            max_steps=2**31 - 1,  # the world ends only when the car collides
            reward=NoReward(),
        )
