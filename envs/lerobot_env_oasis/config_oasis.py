"""Configuration of the oasis env (``--env.type=oasis``), the features it gives a policy and the
vector env it builds."""

from __future__ import annotations

from dataclasses import dataclass, field

from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE

from lerobot_env_oasis.keys import AGENT_POS, PIXELS
from oasis_torchrl.client.decoding import validate_front_crop
from oasis_torchrl.config import EmbeddedServerConfig
from oasis_torchrl.config import EnvConfig as OasisSettings
from oasis_torchrl.config.env import LOCAL, RewardConfig
from oasis_torchrl.protocol import ACTION_DIM, CAMERAS, CHUNK, FPS, with_front_crop

ENV_TYPE = "oasis"
REWARDS = ("distance", "return")

_SETTINGS = OasisSettings()
_SERVER = EmbeddedServerConfig()


@EnvConfig.register_subclass(ENV_TYPE)
@dataclass
class OasisEnvConfig(EnvConfig):
    """The world model as a LeRobot env: one world-model session per env of the batch
    (``--eval.batch_size``), all stepped at once, one action per frame (20 fps).

    Args:
        task: the scene prompt of every episode (``urban``, ``rainy highway at night``, ...).
        episode_length: frames per episode (a multiple of 4; 600 = 30 s, the project's 150
            evaluation steps).
        endpoint: ``local`` (an embedded simulator server started with the env) or an A2V
            endpoint (the hosted model's key comes from ``DECART_API_KEY``).
        observation_height, observation_width: camera frame size (the policy's input size).
        server_width, server_height: frame size the embedded server renders (at least what
            ``front_crop`` needs).
        front_crop: add the narrow forward camera ``observation.images.front_crop``, this
            fraction of the front frame's centre (what a policy trained with
            ``env.front_crop`` reads; its card names the fraction); None: the three cameras.
        reward: ``distance`` (metres driven this frame: an episode's sum is the distance before
            collision; needs the embedded server's ground truth) or ``return`` (the project's
            env reward, as ``oasis-torchrl eval`` sums it).

    Example:
        >>> config = OasisEnvConfig(task="rural road")
        >>> sorted(config.features_map.values())[:2]
        ['action', 'observation.images.front']
        >>> config.gym_kwargs["max_episode_steps"]
        600
    """

    task: str | None = _SETTINGS.prompts[0]
    fps: int = int(FPS)
    episode_length: int = CHUNK * _SETTINGS.max_steps
    endpoint: str = _SETTINGS.endpoint
    observation_height: int = _SETTINGS.image_size[0]
    observation_width: int = _SETTINGS.image_size[1]
    server_width: int = _SERVER.width
    server_height: int = _SERVER.height
    front_crop: float | None = None
    reward: str = REWARDS[0]
    render_mode: str = "rgb_array"
    features: dict[str, PolicyFeature] = field(default_factory=dict)
    features_map: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.task or not self.task.strip():
            raise ValueError("env.task is the scene prompt: give a non-empty one, e.g. urban")
        if self.episode_length < CHUNK or self.episode_length % CHUNK:
            raise ValueError(
                f"env.episode_length counts frames in whole world-model calls of {CHUNK}: "
                f"a positive multiple of {CHUNK}, got {self.episode_length}"
            )
        if self.fps != FPS:
            raise ValueError(f"the world model runs at {FPS:g} fps, got env.fps={self.fps}")
        if self.reward not in REWARDS:
            raise ValueError(f"env.reward must be one of {REWARDS}, got {self.reward!r}")
        if self.reward == "distance" and self.endpoint != LOCAL:
            raise ValueError(
                "env.reward=distance needs the embedded server's ground truth (env.endpoint="
                "local); on another endpoint use env.reward=return"
            )
        validate_front_crop(self.front_crop)
        frame = (self.observation_height, self.observation_width, 3)
        self.features = {
            ACTION: PolicyFeature(FeatureType.ACTION, (ACTION_DIM,)),
            AGENT_POS: PolicyFeature(FeatureType.STATE, (ACTION_DIM,)),
            **{f"{PIXELS}/{c}": PolicyFeature(FeatureType.VISUAL, frame) for c in self.cameras},
        }
        self.features_map = {
            ACTION: ACTION,
            AGENT_POS: OBS_STATE,
            **{f"{PIXELS}/{camera}": f"{OBS_IMAGES}.{camera}" for camera in self.cameras},
        }

    @property
    def cameras(self) -> tuple[str, ...]:
        """The cameras each observation holds: the three streams, then the crop if set."""
        return with_front_crop(CAMERAS, self.front_crop)

    @property
    def gym_kwargs(self) -> dict:
        """What the vector env is built with besides the config itself."""
        return {"render_mode": self.render_mode, "max_episode_steps": self.episode_length}

    def settings(self, num_envs: int) -> OasisSettings:
        """The project's env settings of ``num_envs`` sessions of this env."""
        return OasisSettings(
            endpoint=self.endpoint,
            prompts=[self.task],
            num_envs=num_envs,
            max_steps=self.episode_length // CHUNK,
            image_size=(self.observation_height, self.observation_width),
            front_crop=self.front_crop,
            server=EmbeddedServerConfig(
                width=self.server_width, height=self.server_height, fps=float(self.fps)
            ),
            reward=RewardConfig() if self.endpoint == LOCAL else RewardConfig(kind="depth"),
        )

    def create_envs(self, n_envs: int, use_async_envs: bool = False) -> dict:
        """``{"oasis": {0: OasisVectorEnv}}``: one vector env of ``n_envs`` sessions stepped
        concurrently from this process (``use_async_envs`` is not needed and is ignored: the
        world-model calls of all sessions are in flight at once already)."""
        from lerobot_env_oasis.vector_env import OasisVectorEnv

        return {ENV_TYPE: {0: OasisVectorEnv(self, n_envs)}}
