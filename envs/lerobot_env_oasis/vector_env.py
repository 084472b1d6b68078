"""``OasisVectorEnv``: N world-model sessions as one Gymnasium vector env in LeRobot's format.

Observations are LeRobot's gym convention, ``{"pixels": {camera: uint8 [N, H, W, 3]},
"agent_pos": float32 [N, 2]}`` (``lerobot-eval`` turns them into ``observation.images.<camera>``
and ``observation.state``, the project's dataset names); actions are ``[N, 2]`` (``throttle``,
``steering``), one per frame. Four frames make one world-model call for every session at once,
by sample and hold (:mod:`oasis_torchrl.envs.per_frame`): the observation is the newest frame and
the state the previous action, exactly what ``oasis-torchrl eval`` shows a LeRobot policy.

Episodes and metrics. A reset with seeds ``[s, s+1, ..., s+N-1]`` (what ``lerobot-eval`` passes
for a batch) seeds the batch with ``s``: session ``i`` gets the ``i``-th world of seed ``s``, as
``oasis-torchrl eval seeds=[s] episodes=N`` does. The reward and an episode's end come on a
chunk's 4th frame. An episode ends at a collision (``terminated``) or after ``episode_length``
frames (``truncated``); it is a *success* when it ran its full length without colliding. With
``reward=distance`` (the default) a frame's reward is the metres driven, so LeRobot's
``avg_sum_reward`` is the mean distance before collision and ``pc_success`` is 100 x (1 -
collision rate): the driving metrics of ``oasis-torchrl eval``. ``info["final_info"]`` also
carries, for every session ending at that frame, ``distance``, ``collided``, ``episode_return``
(the project's reward) and ``episode_seed``. A finished session is frozen (no reward, no new
end) until the next reset.

``render()`` gives, per session, the three cameras side by side; each world frame is shown once,
three frames after the action that completed its chunk, so videos play at the world's 20 fps.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any, Protocol

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from gymnasium.vector.utils import batch_space
from tensordict import TensorDictBase

from lerobot_env_oasis.keys import AGENT_POS, PIXELS
from oasis_torchrl.config import EnvConfig as OasisSettings
from oasis_torchrl.envs import make_env
from oasis_torchrl.envs.per_frame import FrameObservation, FrameStepper
from oasis_torchrl.protocol import ACTION_DIM, CAMERAS

logger = logging.getLogger(__name__)

NEXT = "next"


class VectorEnvSettings(Protocol):
    """What the vector env reads of its config, :class:`~lerobot_env_oasis.OasisEnvConfig` (an
    interface of its own, so the config can build the env without the two importing each other).
    """

    task: str | None
    fps: int
    episode_length: int
    observation_height: int
    observation_width: int
    reward: str
    render_mode: str

    @property
    def cameras(self) -> tuple[str, ...]:
        """The cameras each observation holds."""
        ...

    def settings(self, num_envs: int) -> OasisSettings:
        """The project's env settings of ``num_envs`` sessions."""
        ...


def batch_seed(seed: int | Sequence[int] | None) -> int | None:
    """The seed of a batch from ``reset(seed=...)``: an int, or consecutive per-env seeds
    (their first).

    Example:
        >>> batch_seed([1000, 1001, 1002]), batch_seed(7), batch_seed(None)
        (1000, 7, None)
        >>> batch_seed([3, 9])
        Traceback (most recent call last):
        ...
        ValueError: per-env seeds must be consecutive (s, s+1, ...); got [3, 9]
    """
    if seed is None or isinstance(seed, int | np.integer):
        return None if seed is None else int(seed)
    seeds = [int(s) for s in seed]
    if seeds != list(range(seeds[0], seeds[0] + len(seeds))):
        raise ValueError(f"per-env seeds must be consecutive (s, s+1, ...); got {seeds}")
    return seeds[0]


class OasisVectorEnv(gym.vector.VectorEnv):
    """``num_envs`` concurrent world-model sessions, one action per frame (see module docs).

    Args:
        config: the ``--env.*`` settings.
        num_envs: sessions (``--eval.batch_size``).

    Example:
        >>> from lerobot_env_oasis import OasisEnvConfig
        >>> env = OasisVectorEnv(OasisEnvConfig(episode_length=8), num_envs=2)
        >>> observation, info = env.reset(seed=[5, 6])
        >>> observation["pixels"]["front"].shape, observation["agent_pos"].shape
        ((2, 64, 96, 3), (2, 2))
        >>> for _ in range(8):
        ...     observation, reward, terminated, truncated, info = env.step(np.ones((2, 2)))
        >>> truncated.tolist(), info["final_info"]["is_success"].tolist()
        ([True, True], [True, True])
        >>> env.render().shape, env.call("task_description")
        ((2, 64, 288, 3), ('urban', 'urban'))
        >>> env.close()
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(self, config: VectorEnvSettings, num_envs: int) -> None:
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        self.config = config
        self.num_envs = num_envs
        self.render_mode = config.render_mode
        self.metadata = {**self.metadata, "render_fps": config.fps}
        self._max_episode_steps = config.episode_length
        self.task = config.task
        self.task_description = config.task
        frame = (config.observation_height, config.observation_width, 3)
        self.single_observation_space = spaces.Dict(
            {
                PIXELS: spaces.Dict(
                    {c: spaces.Box(0, 255, frame, dtype=np.uint8) for c in config.cameras}
                ),
                AGENT_POS: spaces.Box(-1.0, 1.0, (ACTION_DIM,), dtype=np.float32),
            }
        )
        self.single_action_space = spaces.Box(-1.0, 1.0, (ACTION_DIM,), dtype=np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._stepper = FrameStepper(make_env(config.settings(num_envs)))
        self._terminated = np.zeros(num_envs, dtype=bool)
        self._truncated = np.zeros(num_envs, dtype=bool)
        self._odometer = np.zeros(num_envs)
        self._return = np.zeros(num_envs)

    # -- the gym API -------------------------------------------------------------------------

    def reset(
        self, *, seed: int | Sequence[int] | None = None, options: dict | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        """Start every session's next episode (seeded as in the module docs)."""
        observation = self._stepper.reset(seed=batch_seed(seed))
        self._terminated[:] = False
        self._truncated[:] = False
        self._odometer = self._truth("distance", self._stepper.last)
        self._return[:] = 0.0
        return self._observe(observation), {}

    def step(
        self, actions: np.ndarray
    ) -> tuple[dict[str, Any], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """One frame: every session's ``[throttle, steering]`` (clipped to ``[-1, 1]``)."""
        step = self._stepper.step(np.asarray(actions, dtype=np.float32))
        reward, info = np.zeros(self.num_envs), {}
        if step.chunk is not None:
            reward, info = self._score(step.chunk.get(NEXT))
        observation = self._observe(step.observation)
        return observation, reward, self._terminated.copy(), self._truncated.copy(), info

    def render(self) -> np.ndarray:
        """Per session, the three cameras side by side: ``[N, H, 3 W, 3]`` uint8."""
        frames = self._stepper.last.get(PIXELS)
        shown = []
        for camera in CAMERAS:
            pixels = frames.get(camera)
            pixels = pixels[:, self._stepper.tick] if pixels.dim() == 5 else pixels
            shown.append(pixels.cpu().numpy())
        return np.concatenate(shown, axis=2)

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """Every session's ``name`` (called if callable): what LeRobot's loop asks for."""
        if name == "render":
            return tuple(self.render())
        value = getattr(self, name)
        value = value(*args, **kwargs) if callable(value) else value
        return (value,) * self.num_envs

    def get_attr(self, name: str) -> tuple[Any, ...]:
        """Every session's attribute ``name``."""
        return (getattr(self, name),) * self.num_envs

    def close_extras(self, **kwargs: Any) -> None:
        """Finish the sessions (and stop the embedded server)."""
        self._stepper.close()

    # -- internals ---------------------------------------------------------------------------

    def _observe(self, observation: FrameObservation) -> dict[str, Any]:
        return {PIXELS: dict(observation.pixels), AGENT_POS: observation.state}

    @staticmethod
    def _truth(field: str, td: TensorDictBase) -> np.ndarray:
        """Ground truth ``field`` at each session's newest frame (NaN without ground truth)."""
        truth = td.get("truth", None)
        if truth is None:
            return np.full(td.batch_size[0], np.nan)
        return truth.get(field)[:, -1].to(torch.float64).cpu().numpy()

    def _score(self, td: TensorDictBase) -> tuple[np.ndarray, dict[str, Any]]:
        """Reward and final info of a chunk that just completed; records the sessions that end
        with it. Ended sessions are frozen."""
        odometer = self._truth("distance", td)
        env_reward = td.get("reward").reshape(-1).to(torch.float64).cpu().numpy()
        live = ~(self._terminated | self._truncated)
        if self.config.reward == "distance":
            reward = np.where(live, odometer - self._odometer, 0.0)
        else:
            reward = np.where(live, env_reward, 0.0)
        self._odometer = odometer
        self._return += np.where(live, env_reward, 0.0)
        collided = td.get("terminated").reshape(-1).cpu().numpy()
        if "truth" in td.keys():
            collided = collided | (self._truth("collided", td) > 0.5)
        ending = live & (td.get("done").reshape(-1).cpu().numpy() | collided)
        self._terminated |= ending & collided
        self._truncated |= ending & ~collided
        info = {}
        if ending.any():
            info["final_info"] = {
                "is_success": ending & ~collided,
                "_is_success": ending,
                "distance": odometer,
                "collided": ending & collided,
                "episode_return": self._return.copy(),
                "episode_seed": td.get("episode_seed").reshape(-1).cpu().numpy(),
            }
        return reward, info
