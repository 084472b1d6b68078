"""``OasisVectorEnv``: N Oasis sessions as one ``gymnasium.vector.VectorEnv``, for CleanRL-style
scripts.

The N sessions are the rows of one :class:`~oasis_torchrl.envs.OasisEnv`, so a step sends the N
Infer calls concurrently through its session pool (no subprocess per env, as Gymnasium's
``AsyncVectorEnv`` would need). Importing ``oasis_torchrl`` registers it as the vector entry
point of ``"oasis_torchrl/Oasis-v0"``: ``gymnasium.make_vec("oasis_torchrl/Oasis-v0",
num_envs=8)``.

Autoreset: ``AutoresetMode.NEXT_STEP``, Gymnasium's default. A row whose episode ended at step
``t`` is reset at step ``t + 1``: its action there is ignored, and it returns the new episode's
first observation with reward 0 and neither terminated nor truncated. ``reset(options=
{"reset_mask": mask})`` resets only the rows in ``mask``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from tensordict import TensorDict, TensorDictBase

from oasis_torchrl.envs.episodes import Prompts
from oasis_torchrl.envs.gym_adapter import (
    RENDER_MODES,
    batch_info,
    batch_observation,
    camera_space,
    chunk_space,
    session_env,
)
from oasis_torchrl.envs.oasis_env import LOCAL, OasisEnv
from oasis_torchrl.protocol import FPS

RENDER_CAMERA = "front"


class OasisVectorEnv(VectorEnv):
    """``num_envs`` Oasis sessions stepped concurrently: batched Box ``(N, 4, 2)`` actions, a
    Dict of camera frames ``(N, H, W, 3)``.

    Args:
        num_envs: sessions (rows).
        endpoint: ``"local"`` or an A2V endpoint (see :class:`~oasis_torchrl.envs.OasisEnv`).
        prompts: one prompt, one per row, or a sampler ``sampler(row, rng) -> str``.
        reward: reward module or callable (see :class:`~oasis_torchrl.envs.OasisEnv`).
        max_steps: steps (chunks) before an episode is truncated.
        render_mode: ``"rgb_array"``: :meth:`render` returns each row's front frame.
        **env_kwargs: further :class:`~oasis_torchrl.envs.OasisEnv` arguments (``server``,
            ``frame_size``, ...).

    Example:
        >>> from oasis_torchrl.sim.config import ServerConfig
        >>> envs = OasisVectorEnv(2, server=ServerConfig(width=48, height=32))
        >>> obs, info = envs.reset(seed=0)
        >>> obs["front"].shape, envs.action_space.shape
        ((2, 32, 48, 3), (2, 4, 2))
        >>> obs, rewards, terminated, truncated, info = envs.step(envs.action_space.sample())
        >>> rewards.shape, terminated.dtype
        ((2,), dtype('bool'))
        >>> envs.close()
    """

    metadata = {
        "render_modes": list(RENDER_MODES),
        "render_fps": FPS,
        "autoreset_mode": AutoresetMode.NEXT_STEP,
    }

    def __init__(
        self,
        num_envs: int = 1,
        endpoint: str = LOCAL,
        prompts: Prompts = "urban street",
        *,
        reward: Any = None,
        max_steps: int = 512,
        render_mode: str | None = None,
        **env_kwargs: Any,
    ) -> None:
        self._env = session_env(
            num_envs,
            endpoint,
            prompts,
            render_mode,
            reward=reward,
            max_steps=max_steps,
            **env_kwargs,
        )
        self.render_mode = render_mode
        self.num_envs = num_envs
        self.single_action_space = chunk_space()
        self._cameras = self._env.layout.cameras
        self.single_observation_space = camera_space(self._cameras, self._env.layout.frame_size)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self._autoreset = np.zeros(num_envs, dtype=bool)
        self._td: TensorDictBase | None = None
        self._last: dict[str, np.ndarray] | None = None

    @property
    def env(self) -> OasisEnv:
        """The batched TorchRL env underneath (e.g. ``envs.env.scene_source()``)."""
        return self._env

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Reset every row (or those of ``options["reset_mask"]``); ``seed`` re-seeds the
        episodes of all rows (one int: rows get independent worlds from it)."""
        super().reset(seed=seed)  # refuses anything but one int (or None)
        if seed is not None:
            self._env.set_seed(int(seed))
        mask = np.ones(self.num_envs, dtype=bool)
        if options and "reset_mask" in options:
            mask = np.asarray(options["reset_mask"], dtype=bool).reshape(self.num_envs)
        td = self._reset_rows(mask, self._td)
        self._autoreset &= ~mask
        return self._observe(td), self._info(td)

    def step(
        self, actions: np.ndarray
    ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every row with its chunk; rows that ended at the previous step are reset
        instead (their actions are ignored)."""
        chunk = torch.as_tensor(np.asarray(actions, dtype=np.float32))
        td = self._env.step(TensorDict(action=chunk, batch_size=[self.num_envs]))["next"]
        rewards = td["reward"].numpy().reshape(-1).astype(np.float64)
        terminated = td["terminated"].numpy().reshape(-1).copy()
        truncated = td["truncated"].numpy().reshape(-1).copy()
        restarting = self._autoreset
        if restarting.any():
            td = self._reset_rows(restarting, td)
            rewards[restarting] = 0.0
            terminated[restarting] = truncated[restarting] = False
        self._autoreset = terminated | truncated
        return self._observe(td), rewards, terminated, truncated, self._info(td)

    def render(self) -> tuple[np.ndarray, ...] | None:
        """Each row's last front frame (``render_mode="rgb_array"``)."""
        if self.render_mode != "rgb_array" or self._last is None:
            return None
        camera = RENDER_CAMERA if RENDER_CAMERA in self._last else self._cameras[0]
        return tuple(self._last[camera])

    def close_extras(self, **kwargs: Any) -> None:
        """Finish the sessions and stop the embedded server, if any."""
        if not self._env.is_closed:
            self._env.close()

    def _reset_rows(self, mask: np.ndarray, current: TensorDictBase | None) -> TensorDictBase:
        """Reset the rows of ``mask``; the others keep their observation in ``current``
        (TorchRL's partial reset takes them from the tensordict it is given)."""
        if mask.all() or current is None:
            return self._env.reset()
        reset = torch.as_tensor(mask).unsqueeze(-1)
        return self._env.reset(current.clone(False).set("_reset", reset))

    def _observe(self, td: TensorDictBase) -> dict[str, np.ndarray]:
        self._td = td
        self._last = batch_observation(td, self._cameras)
        return self._last

    def _info(self, td: TensorDictBase) -> dict[str, Any]:
        """Gymnasium's vector info: every key holds all rows, with its ``_key`` mask."""
        info = batch_info(td)
        every_row = np.ones(self.num_envs, dtype=bool)
        return {**info, **{f"_{key}": every_row for key in info}}
