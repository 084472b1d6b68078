"""``OasisEnv``: N world-model sessions as one batched TorchRL environment.

Each row of the batch is one A2V session on one gRPC channel; a step sends the N Infer calls
concurrently through :class:`~oasis_torchrl.client.SessionPool` and returns the decoded frames as
uint8 tensors (layout in :mod:`oasis_torchrl.envs.specs`).

Episodes. A reset of a row (all rows, or those set in the ``"_reset"`` mask) re-prompts that
session with its next prompt and seed (:class:`~oasis_torchrl.envs.episodes.EpisodePlanner`) and
sends one all-zero action chunk, as the reference Gymnasium env does: the reset observation is
the world after standing still for 4 frames. ``truncated`` is set at ``max_steps`` steps (chunks)
and when a row's session was lost and re-opened mid-episode (counted in
``("info", "session_restarts")``); ``terminated`` comes from the reward module and, where the
server reports ground truth, from a collision (the car cannot move again).

Processes. The env is picklable and lazy: the channel (and, for ``endpoint="local"``, the embedded
server) opens in the process that first resets or steps it, so ``ParallelEnv`` and multi-process
collectors with the ``spawn`` start method each get their own.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch
from tensordict import NonTensorStack, TensorDict, TensorDictBase
from torchrl.envs import EnvBase

from oasis_torchrl.client import TRUTH_FIELDS, PoolStep, RetryPolicy, SessionPool, SessionStatus
from oasis_torchrl.envs.episodes import EpisodePlanner, Prompts
from oasis_torchrl.envs.specs import (
    EnvLayout,
    build_action_spec,
    build_done_spec,
    build_observation_spec,
    build_reward_spec,
)
from oasis_torchrl.protocol import CAMERAS, CHUNK, FPS
from oasis_torchrl.rewards import GroundTruthReward, RewardModule, as_reward_module
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.launcher import LocalServer

logger = logging.getLogger(__name__)

LOCAL = "local"


class OasisEnv(EnvBase):
    """A batched TorchRL env over ``num_envs`` concurrent Oasis (A2V) sessions.

    Args:
        endpoint: ``"local"`` (start the embedded simulator server on a free loopback port in
            the stepping process, stop it on close), or any A2V endpoint such as
            ``"https://oasis-grpc.decart.ai"`` or ``"http://127.0.0.1:50051"``.
        num_envs: rows of the batch, one session each.
        prompts: one prompt, one per row, or a sampler ``sampler(row, rng) -> str`` called at
            every reset of a row.
        api_key: key for a remote endpoint (defaults to ``DECART_API_KEY``); ignored for local.
        tls: force TLS on or off (default: from the endpoint's scheme).
        server: embedded-server settings for ``endpoint="local"`` (resolution, latency, ...).
        frame_size: ``(height, width)`` to resize frames to while decoding; default: what the
            server advertises.
        all_frames: return all 4 frames of each chunk instead of the last one.
        chunk_actions: actions are ``[N, 4, 2]`` chunks (default) or ``[N, 2]`` repeated 4 times.
        max_steps: steps (chunks) before an episode is truncated.
        reward: a :class:`~oasis_torchrl.rewards.RewardModule` or a callable ``fn(td) -> Tensor``;
            default: :class:`~oasis_torchrl.rewards.GroundTruthReward` with ground truth, zero
            elsewhere (pass :class:`~oasis_torchrl.rewards.DepthCollisionReward` for the
            reference depth reward).
        ground_truth: expose the embedded simulator's ground truth as ``("truth", field)``,
            and its expert's next chunk as ``"expert_action"`` (what
            :class:`~oasis_torchrl.drivers.Autopilot` drives with); default: only for
            ``endpoint="local"``. Set it for an ``oasis-torchrl serve`` server started elsewhere
            (a server that sends none yields NaN).
        depth_cameras: cameras whose ground-truth depth is fetched after each step (embedded
            server only), e.g. ``("front",)`` for ``GroundTruthDepth``.
        terminate_on_collision: end the episode when the ground truth reports a collision.
        retry: transient-failure policy of the session pool.
        timeout: per-call deadline in seconds.
        device: device of the returned tensors.

    Example:
        >>> from oasis_torchrl.envs import OasisEnv
        >>> from oasis_torchrl.sim.config import ServerConfig
        >>> env = OasisEnv("local", num_envs=2, prompts="urban street",
        ...                server=ServerConfig(width=96, height=64))
        >>> td = env.rollout(3)
        >>> td["next", "pixels", "front"].shape
        torch.Size([2, 3, 64, 96, 3])
        >>> env.close()
    """

    batch_locked = True

    def __init__(
        self,
        endpoint: str = LOCAL,
        num_envs: int = 1,
        prompts: Prompts = "urban street",
        *,
        api_key: str | None = None,
        tls: bool | None = None,
        server: ServerConfig | None = None,
        frame_size: tuple[int, int] | None = None,
        all_frames: bool = False,
        chunk_actions: bool = True,
        max_steps: int = 512,
        reward: RewardModule | Callable[[TensorDictBase], torch.Tensor] | None = None,
        ground_truth: bool | None = None,
        depth_cameras: Sequence[str] = (),
        terminate_on_collision: bool = True,
        retry: RetryPolicy | None = None,
        timeout: float = 120.0,
        device: torch.device | str = "cpu",
    ) -> None:
        super().__init__(device=device, batch_size=torch.Size([num_envs]))
        if max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {max_steps}")
        self.endpoint = endpoint
        self.num_envs = num_envs
        self.max_steps = max_steps
        self.all_frames = all_frames
        self.chunk_actions = chunk_actions
        self.terminate_on_collision = terminate_on_collision
        self.timeout = timeout
        self.retry = retry
        self._tls = tls
        self._api_key = api_key
        self._server_config = server if server is not None else ServerConfig()
        # The A2V protocol does not advertise a frame rate; the hosted model's preview uses 20.
        self.fps = self._server_config.fps if self.is_local else FPS
        self._planner = EpisodePlanner(prompts, num_envs)
        self.ground_truth = self.is_local if ground_truth is None else ground_truth
        self._reward = _resolve_reward(reward, self.ground_truth)
        self._server: LocalServer | None = None
        self._pool: SessionPool | None = None
        self._frame_size = frame_size
        cameras, advertised = self._discover_streams()
        unknown = set(depth_cameras) - set(cameras)
        if unknown:
            raise ValueError(f"depth_cameras {sorted(unknown)} are not streams of {cameras}")
        self.layout = EnvLayout(
            num_envs=num_envs,
            cameras=cameras,
            frame_size=frame_size or advertised,
            all_frames=all_frames,
            chunk_actions=chunk_actions,
            truth_fields=TRUTH_FIELDS if self.ground_truth else (),
            depth_cameras=tuple(depth_cameras),
            reward_terms=tuple(getattr(self._reward, "terms", ())),
            device=self.device,
        )
        self.observation_spec = build_observation_spec(self.layout)
        self.action_spec = build_action_spec(self.layout)
        self.reward_spec = build_reward_spec(self.layout)
        self.full_done_spec = build_done_spec(self.layout)
        self._steps = np.zeros(num_envs, dtype=np.int64)
        self._prompts = [""] * num_envs
        self._seeds = torch.zeros(num_envs, 1, dtype=torch.int64)
        self._restarts = torch.zeros(num_envs, 1, dtype=torch.int64)
        self._last_obs: TensorDictBase | None = None

    @property
    def is_local(self) -> bool:
        """Whether this env runs on its own embedded simulator server."""
        return self.endpoint == LOCAL

    @property
    def pool(self) -> SessionPool:
        """The session pool, opened on first use in the calling process."""
        if self._pool is None:
            self._pool = self._open_pool()
        return self._pool

    # -- lifecycle -------------------------------------------------------------------------

    def _discover_streams(self) -> tuple[tuple[str, ...], tuple[int, int]]:
        if self.is_local:
            cfg = self._server_config
            return CAMERAS, (cfg.height, cfg.width)
        pool = self.pool  # a remote server must be asked what it streams
        return tuple(pool.stream_names), tuple(pool.frame_size)

    def _open_pool(self) -> SessionPool:
        endpoint, api_key = self.endpoint, self._api_key
        if self.is_local:
            self._server = LocalServer(self._server_config)
            self._server.start()
            endpoint, api_key = self._server.endpoint, self._server.api_key
        pool = SessionPool(
            endpoint,
            self.num_envs,
            api_key=api_key,
            tls=self._tls,
            timeout=self.timeout,
            retry=self.retry,
            resize=self._frame_size,
            frames="all" if self.all_frames else "last",
        )
        try:
            pool.start()
        except BaseException:
            pool.close()
            self._stop_server()
            raise
        return pool

    def _stop_server(self) -> None:
        if self._server is not None:
            self._server.stop()
            self._server = None

    def close(self, *, raise_if_closed: bool = True) -> None:
        """Finish every session, close the channel and stop the embedded server."""
        try:
            if self._pool is not None:
                self._pool.close()
        finally:
            self._pool = None
            self._stop_server()
            super().close(raise_if_closed=raise_if_closed)

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_pool"] = None  # sockets and threads never cross processes; reopened lazily
        state["_server"] = None
        return state

    def _set_seed(self, seed: int | None) -> None:
        self._planner.set_seed(0 if seed is None else seed)

    # -- reset / step ----------------------------------------------------------------------

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        rows = self._rows_to_reset(tensordict)
        prompts, seeds = self._planner.next_episodes(rows)
        step = self.pool.reset(rows, prompts, seeds)
        failed = [i for i, s in enumerate(step.status) if s == SessionStatus.LOST]
        if failed:
            raise RuntimeError(
                f"could not reset env row {rows[failed[0]]}: {step.errors[failed[0]]}"
            ) from step.errors[failed[0]]
        self._steps[rows] = 0
        for row, prompt, seed in zip(rows, prompts, seeds, strict=True):
            self._prompts[row] = prompt
            self._seeds[row] = seed
        mask = torch.zeros(self.num_envs, dtype=torch.bool)
        mask[rows] = True
        self._reward.reset(mask)
        obs = self._observation(step, rows, torch.zeros(len(rows), 2))
        out = obs.update(_flags(self.num_envs, self.device))
        self._last_obs = obs
        return out

    def _rows_to_reset(self, tensordict: TensorDictBase | None) -> list[int]:
        reset = None if tensordict is None else tensordict.get("_reset", None)
        if reset is None or self._last_obs is None:
            return list(range(self.num_envs))
        return reset.reshape(self.num_envs).nonzero().flatten().tolist()

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get("action")
        chunk = self._action_chunk(action)
        step = self.pool.infer(chunk.numpy())
        rows = list(range(self.num_envs))
        self._steps += 1
        restarted = torch.as_tensor(step.status != SessionStatus.OK).unsqueeze(-1)
        self._restarts += restarted.long()
        for i in restarted.flatten().nonzero().flatten().tolist():
            logger.warning("env row %d lost its session and was re-opened: %s", i, step.errors[i])
        if restarted.any():  # a re-opened session starts a new clip: per-row reward state too
            self._reward.reset(restarted.flatten())
        obs = self._observation(step, rows, chunk[:, -1])
        scored = self._reward(obs.clone(False).set("action", chunk.to(self.device)))
        terminated = scored.get("terminated", torch.zeros(self.num_envs, 1, dtype=torch.bool))
        if self.terminate_on_collision and "truth" in obs.keys():
            terminated = terminated | (obs["truth", "collided"][:, -1:] > 0.5)
        truncated = torch.as_tensor(self._steps >= self.max_steps).unsqueeze(-1) | restarted
        truncated = truncated & ~terminated.cpu()
        for term in self.layout.reward_terms:
            obs["reward_terms", term] = scored["reward_terms", term].to(torch.float32)
        self._last_obs = obs.clone(False)
        obs.set("reward", scored["reward"].to(torch.float32))
        return obs.update(_flags(self.num_envs, self.device, terminated, truncated))

    def _action_chunk(self, action: torch.Tensor) -> torch.Tensor:
        """Validate the action before any request and expand it to ``[N, 4, 2]``."""
        expected = tuple(self.action_spec.shape)
        if tuple(action.shape) != expected:
            raise ValueError(f"action must have shape {expected}, got {tuple(action.shape)}")
        action = action.detach().to("cpu", torch.float32)
        bad_rows = (~torch.isfinite(action)).flatten(1).any(-1)
        if bad_rows.any():
            raise ValueError(f"action of env row {bad_rows.nonzero()[0].item()} is not finite")
        outside = (action.abs() > 1.0).flatten(1).any(-1)
        if outside.any():
            row = outside.nonzero()[0].item()
            raise ValueError(f"action of env row {row} is outside [-1, 1]: {action[row].tolist()}")
        if not self.chunk_actions:
            action = action.unsqueeze(1).expand(-1, CHUNK, -1)
        return action.contiguous()

    # -- observations ----------------------------------------------------------------------

    def _observation(
        self, step: PoolStep, rows: list[int], prev_action: torch.Tensor
    ) -> TensorDictBase:
        """Build the full ``[N]`` observation; rows not in ``rows`` keep their last values."""
        fresh = TensorDict(batch_size=[len(rows)])
        for camera in self.layout.cameras:
            frames = torch.from_numpy(step.frames[camera])
            fresh["pixels", camera] = frames if self.all_frames else frames[:, -1].contiguous()
        fresh["state"] = prev_action.to(torch.float32)
        fresh["prompt"] = NonTensorStack(*(self._prompts[row] for row in rows))
        fresh["episode_seed"] = self._seeds[rows]
        if self.layout.truth_fields:
            truth = torch.from_numpy(_truth_or_nan(step, len(rows))).to(torch.float32)
            for k, name in enumerate(self.layout.truth_fields):
                fresh["truth", name] = truth[..., k]
            fresh["expert_action"] = torch.from_numpy(step.expert)
        if self.layout.depth_cameras:
            depth = self.pool.depth(rows)
            for camera in self.layout.depth_cameras:
                fresh["depth", camera] = torch.from_numpy(depth[camera])
        for term in self.layout.reward_terms:
            fresh["reward_terms", term] = torch.zeros(len(rows), 1)
        fresh["info", "session_restarts"] = self._restarts[rows]
        if len(rows) == self.num_envs:
            return fresh.to(self.device)
        full = self._last_obs.clone()
        full[torch.as_tensor(rows)] = fresh
        return full.to(self.device)


def _truth_or_nan(step: PoolStep, n: int) -> np.ndarray:
    if step.truth is None:
        return np.full((n, CHUNK, len(TRUTH_FIELDS)), np.nan)
    return step.truth


def _flags(
    n: int,
    device: torch.device,
    terminated: torch.Tensor | None = None,
    truncated: torch.Tensor | None = None,
) -> TensorDict:
    zeros = torch.zeros(n, 1, dtype=torch.bool)
    terminated = zeros if terminated is None else terminated.cpu()
    truncated = zeros if truncated is None else truncated.cpu()
    return TensorDict(
        done=terminated | truncated, terminated=terminated, truncated=truncated, batch_size=[n]
    ).to(device)


def _resolve_reward(reward: Any, ground_truth: bool) -> RewardModule:
    if reward is None:
        return GroundTruthReward() if ground_truth else as_reward_module(_zero_reward)
    if hasattr(reward, "reset"):
        return reward
    return as_reward_module(reward)


def _zero_reward(td: TensorDictBase) -> torch.Tensor:
    return torch.zeros(td.batch_size[0], 1)
