"""A single-session Gymnasium env with the reference env's interface, for Stable-Baselines3 users,
and the spaces, observations and infos it shares with the vector env
(:mod:`oasis_torchrl.envs.gym_vector`).

It is a one-row :class:`~oasis_torchrl.envs.OasisEnv` underneath, so rewards, seeding, session
recovery and the embedded server behave exactly as in the batched env. Importing
``oasis_torchrl`` registers it as ``gymnasium.make("oasis_torchrl/Oasis-v0", ...)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from tensordict import TensorDict, TensorDictBase

from oasis_torchrl.envs.episodes import Prompts
from oasis_torchrl.envs.oasis_env import LOCAL, OasisEnv
from oasis_torchrl.protocol import ACTION_DIM, CHUNK, FPS

RENDER_MODES = ("rgb_array",)
"""What ``render()`` can return: the front camera's last frame (each row's, in a vector env)."""


def chunk_space() -> spaces.Box:
    """One action: a ``(4, 2)`` chunk of ``[throttle, steering]`` in [-1, 1].

    Example:
        >>> chunk_space().shape
        (4, 2)
    """
    return spaces.Box(-1.0, 1.0, (CHUNK, ACTION_DIM), dtype=np.float32)


def camera_space(cameras: Sequence[str], frame_size: tuple[int, int]) -> spaces.Dict:
    """One observation: the last frame of each camera, uint8 ``(H, W, 3)``.

    Example:
        >>> camera_space(("front", "front_crop"), (512, 768))["front_crop"].shape
        (512, 768, 3)
    """
    height, width = frame_size
    return spaces.Dict(
        {camera: spaces.Box(0, 255, (height, width, 3), dtype=np.uint8) for camera in cameras}
    )


def session_env(
    num_envs: int, endpoint: str, prompts: Prompts, render_mode: str | None, **kwargs: Any
) -> OasisEnv:
    """The OasisEnv under a Gymnasium env, after checking ``render_mode``.

    Example:
        >>> session_env(1, LOCAL, "rural road", render_mode="human")
        Traceback (most recent call last):
        ...
        ValueError: render_mode must be None or 'rgb_array', got 'human'
    """
    if render_mode not in (None, *RENDER_MODES):
        raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
    return OasisEnv(endpoint, num_envs, prompts, **kwargs)


def batch_observation(td: TensorDictBase, cameras: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The frames of every row, camera -> uint8 ``[N, H, W, 3]`` (no copy)."""
    return {camera: td["pixels", camera].numpy() for camera in cameras}


def batch_info(td: TensorDictBase) -> dict[str, Any]:
    """What Gymnasium's info holds for every row: ground truth of the 4 frames
    (``truth[field]`` ``[N, 4]``, embedded server), the reward terms ``[N]`` and
    ``session_restarts`` ``[N]``."""
    info: dict[str, Any] = {}
    if "truth" in td.keys():
        info["truth"] = {name: value.numpy() for name, value in td["truth"].items()}
    if "reward_terms" in td.keys():
        info["reward_terms"] = {
            name: value.numpy().reshape(-1) for name, value in td["reward_terms"].items()
        }
    info["session_restarts"] = td["info", "session_restarts"].numpy().reshape(-1)
    return info


class OasisGymEnv(gym.Env):
    """One Oasis session as a ``gymnasium.Env``: Box ``(4, 2)`` actions, Dict of camera frames.

    Args:
        endpoint: ``"local"`` or an A2V endpoint (see :class:`OasisEnv`).
        prompt: the scene prompt of every episode.
        reward: reward module or callable (see :class:`OasisEnv`).
        max_steps: steps before truncation (512, as the reference env).
        render_mode: ``"rgb_array"`` returns the front camera's last frame.
        **env_kwargs: further :class:`OasisEnv` arguments (``server``, ``frame_size``, ...).

    Example:
        >>> from oasis_torchrl.sim.config import ServerConfig
        >>> env = OasisGymEnv(prompt="rural road", server=ServerConfig(width=96, height=64))
        >>> obs, info = env.reset(seed=0)
        >>> obs["front"].shape
        (64, 96, 3)
        >>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        >>> env.close()
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": FPS}

    def __init__(
        self,
        endpoint: str = LOCAL,
        prompt: str = "urban street",
        *,
        reward: Any = None,
        max_steps: int = 512,
        render_mode: str | None = None,
        **env_kwargs: Any,
    ) -> None:
        self._env = session_env(
            1, endpoint, prompt, render_mode, reward=reward, max_steps=max_steps, **env_kwargs
        )
        self.render_mode = render_mode
        self.action_space = chunk_space()
        self.observation_space = camera_space(self._cameras, self._env.layout.frame_size)
        self._last: dict[str, np.ndarray] | None = None

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        if seed is not None:
            self._env.set_seed(seed)
        td = self._env.reset()
        return self._observe(td), self._info(td)

    def step(
        self, action: np.ndarray
    ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        chunk = torch.as_tensor(np.asarray(action, dtype=np.float32)).unsqueeze(0)
        td = self._env.step(TensorDict(action=chunk, batch_size=[1]))["next"]
        return (
            self._observe(td),
            float(td["reward"].item()),
            bool(td["terminated"].item()),
            bool(td["truncated"].item()),
            self._info(td),
        )

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array" or self._last is None:
            return None
        return self._last["front"]

    def close(self) -> None:
        if not self._env.is_closed:
            self._env.close()

    def _observe(self, td: TensorDictBase) -> dict[str, np.ndarray]:
        self._last = {
            camera: frames[0] for camera, frames in batch_observation(td, self._cameras).items()
        }
        return self._last

    @property
    def _cameras(self) -> tuple[str, ...]:
        return self._env.layout.cameras

    @staticmethod
    def _info(td: TensorDictBase) -> dict[str, Any]:
        info = batch_info(td)
        for group in ("truth", "reward_terms"):
            if group in info:
                info[group] = {k: v[0] for k, v in info[group].items()}
        info["session_restarts"] = int(info["session_restarts"][0])
        return info
