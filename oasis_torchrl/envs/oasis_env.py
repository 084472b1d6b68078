"""``OasisEnv``: N world-model sessions as one batched TorchRL environment.

Two classes, as TorchRL's own library wrappers do: :class:`OasisWrapper` wraps a built
:class:`~oasis_torchrl.client.SessionPool` (N sessions on one channel; a step sends the N Infer
calls concurrently and returns the decoded frames as uint8 tensors, layout in
:mod:`oasis_torchrl.envs.specs`), and :class:`OasisEnv` builds that pool from an endpoint (and,
for ``endpoint="local"``, the embedded server it runs on) and wraps it.

Episodes. A reset of a row (all rows, or those set in the ``"_reset"`` mask) re-prompts that
session with its next prompt and seed (:class:`~oasis_torchrl.envs.episodes.EpisodePlanner`) and
sends one all-zero action chunk, as the reference Gymnasium env does: the reset observation is
the world after standing still for 4 frames. ``truncated`` is set at ``max_steps`` steps (chunks)
and when a row's session was lost and re-opened mid-episode (counted in
``("info", "session_restarts")``); ``terminated`` comes from the reward module and, where the
server reports ground truth, from a collision (the car cannot move again).

Processes. Constructing an env opens nothing: the specs come from the stream layout (given, or
known without asking: the embedded server's settings, the hosted model's cameras and size, the
decode-time ``frame_size``), and the channel, the sessions and an embedded server open in the
process that first resets or steps the env, where the first Initialize checks the layout. The
env pickles at any time (a copy arrives unopened), so ``ParallelEnv`` and multi-process
collectors each get their own sessions.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import torch
from tensordict import NonTensorStack, TensorDict, TensorDictBase
from torchrl.envs.common import _EnvWrapper

from oasis_torchrl.client import (
    TRUTH_FIELDS,
    PoolStep,
    RetryPolicy,
    SceneSource,
    SessionPool,
    SessionStatus,
)
from oasis_torchrl.envs.embedded import embedded_server, render_size
from oasis_torchrl.envs.episodes import EpisodePlanner, Prompts
from oasis_torchrl.envs.specs import (
    EnvLayout,
    StreamLayout,
    build_action_spec,
    build_done_spec,
    build_observation_spec,
    build_reward_spec,
)
from oasis_torchrl.protocol import (
    CAMERAS,
    CHUNK,
    FORMAT_NAMES,
    FPS,
    HOSTED_FRAME_SIZE,
    with_front_crop,
)
from oasis_torchrl.rewards import (
    GroundTruthReward,
    MotionReward,
    RewardModule,
    as_reward_module,
)
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.launcher import LocalServer, ServerProcess

logger = logging.getLogger(__name__)

LOCAL = "local"
Reward = RewardModule | Callable[[TensorDictBase], torch.Tensor]


class OasisWrapper(_EnvWrapper):
    """A batched TorchRL env over a :class:`~oasis_torchrl.client.SessionPool`, one row per
    session; the pool opens in the process that first resets or steps the env.

    Args:
        env: the pool (its ``resize`` and ``frames`` set the frame size and whether all 4
            frames of a chunk are returned; with its ``expert`` the env exposes the embedded
            server's expert's next chunk as ``"expert_action"``, what
            :class:`~oasis_torchrl.drivers.Autopilot` drives with).
        streams: the layout the server streams; default: the pool's ``required_streams`` at its
            ``resize`` or, without one, the hosted model's size (checked at the first reset).
        prompts: one prompt, one per row, or a sampler ``sampler(row, rng) -> str`` called at
            every reset of a row.
        chunk_actions: actions are ``[N, 4, 2]`` chunks (default) or ``[N, 2]`` repeated 4 times.
        max_steps: steps (chunks) before an episode is truncated.
        reward: a :class:`~oasis_torchrl.rewards.RewardModule` or a callable ``fn(td) -> Tensor``;
            default: :class:`~oasis_torchrl.rewards.GroundTruthReward` with ground truth,
            :class:`~oasis_torchrl.rewards.MotionReward` on frames alone (the shipped motion
            network); :class:`~oasis_torchrl.rewards.NoReward` for none.
        ground_truth: expose the embedded simulator's ground truth as ``("truth", field)``; a
            server that sends none yields NaN.
        depth_cameras: cameras whose ground-truth depth is fetched after each step (embedded
            server only), e.g. ``("front",)`` for ``GroundTruthDepth``.
        terminate_on_collision: end the episode when the ground truth reports a collision.
        fps: the world's frame rate (the protocol does not say; the hosted preview uses 20).
        observe_all_frames: observe all 4 frames of each chunk (default: whatever the pool
            returns); False with a pool of ``frames="all"`` observes the last frame while the
            reward still reads all 4 (a reward that ``reads_chunk_frames``).
        device: device of the returned tensors.

    Example:
        >>> import pickle
        >>> from oasis_torchrl.client import SessionPool
        >>> env = OasisWrapper(SessionPool("http://127.0.0.1:1", 2, api_key="k", resize=(64, 96)))
        >>> env.observation_spec["pixels", "front"].shape
        torch.Size([2, 4, 64, 96, 3])
        >>> pickle.loads(pickle.dumps(env)).batch_size  # nothing was opened
        torch.Size([2])
    """

    libname = "oasis_torchrl"
    batch_locked = True

    def __init__(
        self,
        env: SessionPool | None = None,
        *,
        streams: StreamLayout | None = None,
        prompts: Prompts = "urban street",
        chunk_actions: bool = True,
        max_steps: int = 512,
        reward: Reward | None = None,
        ground_truth: bool = False,
        depth_cameras: Sequence[str] = (),
        terminate_on_collision: bool = True,
        fps: float = FPS,
        observe_all_frames: bool | None = None,
        device: torch.device | str = "cpu",
    ) -> None:
        if env is None:
            raise TypeError("OasisWrapper wraps a SessionPool; build one with OasisEnv(endpoint)")
        if max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {max_steps}")
        num_envs = env.num_sessions
        self.num_envs = num_envs
        self.max_steps = max_steps
        self.all_frames = env.frames == "all" if observe_all_frames is None else observe_all_frames
        if self.all_frames and env.frames != "all":
            raise ValueError("observe_all_frames needs a pool built with frames='all'")
        self.chunk_actions = chunk_actions
        self.terminate_on_collision = terminate_on_collision
        self.ground_truth = ground_truth
        self.fps = fps
        self.streams = streams or StreamLayout(
            tuple(env.required_streams), env.resize or HOSTED_FRAME_SIZE
        )
        self._planner = EpisodePlanner(prompts, num_envs)
        self._reward = _resolve_reward(reward, ground_truth)
        self._depth_cameras = tuple(depth_cameras)
        super().__init__(env=env, device=device, batch_size=torch.Size([num_envs]))
        self._steps = np.zeros(num_envs, dtype=np.int64)
        self._prompts = [""] * num_envs
        self._seeds = torch.zeros(num_envs, 1, dtype=torch.int64)
        self._restarts = torch.zeros(num_envs, 1, dtype=torch.int64)
        self._last_obs: TensorDictBase | None = None

    # -- the _EnvWrapper hooks -------------------------------------------------------------

    def _check_kwargs(self, kwargs: dict[str, Any]) -> None:
        if not isinstance(kwargs.get("env"), SessionPool):
            raise TypeError(f"env must be a SessionPool, got {type(kwargs.get('env')).__name__}")

    def _build_env(self, env: SessionPool) -> SessionPool:
        unknown = set(self._depth_cameras) - set(self.streams.cameras)
        if unknown:
            raise ValueError(
                f"depth_cameras {sorted(unknown)} are not streams of {self.streams.cameras}"
            )
        return env

    def _make_specs(self, env: SessionPool) -> None:
        self.layout = EnvLayout(
            num_envs=self.num_envs,
            cameras=with_front_crop(self.streams.cameras, env.front_crop),
            frame_size=self.streams.frame_size,
            all_frames=self.all_frames,
            chunk_actions=self.chunk_actions,
            truth_fields=TRUTH_FIELDS if self.ground_truth else (),
            expert=env.expert,
            depth_cameras=self._depth_cameras,
            reward_terms=tuple(getattr(self._reward, "terms", ())),
            device=self.device,
        )
        self.observation_spec = build_observation_spec(self.layout)
        self.action_spec = build_action_spec(self.layout)
        self.reward_spec = build_reward_spec(self.layout)
        self.full_done_spec = build_done_spec(self.layout)

    def _init_env(self) -> None:
        return None

    # -- lifecycle -------------------------------------------------------------------------

    @property
    def pool(self) -> SessionPool:
        """The session pool, started (and its layout checked) on first use in this process."""
        pool: SessionPool = self._env
        if not pool.streams:
            pool.start()
            try:
                self.streams.check(pool)
            except ValueError:
                pool.close()
                raise
        return pool

    @property
    def reward_module(self) -> RewardModule:
        """The module that scores every step (the ``reward`` given, or the default)."""
        return self._reward

    def scene_source(self) -> SceneSource:
        """The layouts of this env's scenes, asked of its server through the protocol
        (``SimService/GetScene``, embedded servers only): ``source(prompt, seed)``, for
        top-down views (``RolloutLogger(..., scenes=env.scene_source())``; a ``RerunTransform``
        takes it by itself). It reads the server's address when asked, so it may be made
        before the env starts its server.

        Example:
            >>> from oasis_torchrl.sim.config import ServerConfig
            >>> env = OasisEnv("local", 1, server=ServerConfig(width=64, height=48))
            >>> _ = env.reset()
            >>> env.scene_source()("urban street", 0).lanes > 0
            True
            >>> env.close()
        """
        return SceneSource(self._env)

    def close(self, *, raise_if_closed: bool = True) -> None:
        """Finish every session, close the channel and stop the pool's server, if it has one."""
        try:
            self._env.close()
        finally:
            self.is_closed = True

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
        scored = self._reward(self._reward_input(obs, step, chunk))
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

    def _reward_input(
        self, obs: TensorDictBase, step: PoolStep, chunk: torch.Tensor
    ) -> TensorDictBase:
        """What the reward module reads: the observation, the action chunk and, where the pool
        returns them, all 4 frames of every camera (the observation may keep the last alone)."""
        scored = obs.clone(False).set("action", chunk.to(self.device))
        if self._env.frames == "all" and not self.all_frames:
            for camera in self.layout.cameras:
                scored["pixels", camera] = torch.from_numpy(step.frames[camera]).to(self.device)
        return scored

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
        if self.layout.expert:
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


class OasisEnv(OasisWrapper):
    """The batched TorchRL env over ``num_envs`` concurrent Oasis (A2V) sessions of an endpoint.

    ## Description

    Each of the N rows is one world-model session: a prompt sets a driving scene, every step
    sends a chunk of 4 ``[throttle, steering]`` actions and returns what the three cameras
    (``left_forward``, ``front``, ``right_forward``) saw. Gymnasium: ``oasis_torchrl/Oasis-v0``
    (``gymnasium.make`` one session, ``gymnasium.make_vec`` N).

    ## Action space

    | key | spec | shape | dtype |
    |---|---|---|---|
    | `"action"` | `Bounded(-1, 1)` | `[N, 4, 2]` | `float32` |

    Per row 4 actions in time order, each ``[throttle, steering]``: throttle + is forward, - is
    brake then reverse; steering - is left, + is right. ``chunk_actions=False`` takes ``[N, 2]``,
    repeated 4 times.

    ## Observation space

    | key | spec | shape | dtype |
    |---|---|---|---|
    | `("pixels", camera)` | `Bounded(0, 255)` | `[N, H, W, 3]` | `uint8` |
    | `"state"` | `Bounded(-1, 1)` | `[N, 2]` | `float32` |
    | `"episode_seed"` | `Unbounded` | `[N, 1]` | `int64` |
    | `("info", "session_restarts")` | `Unbounded` | `[N, 1]` | `int64` |
    | `("truth", field)` | `Unbounded` | `[N, 4]` | `float32` |
    | `("reward_terms", term)` | `Unbounded` | `[N, 1]` | `float32` |

    ``camera`` is each of the three cameras (and ``front_crop`` with ``front_crop`` set) and
    ``H x W`` the decoded size (the hosted model's 512 x 768 unless ``frame_size`` or the
    embedded server's size says otherwise); the pixels are
    the last frame of the chunk, all four (``[N, 4, H, W, 3]``) with ``all_frames=True``.
    ``"state"`` is the previous action (zeros after a reset); ``"prompt"`` (text) is the row's
    prompt. ``("truth", field)`` (the embedded server only: each frame's position, speed,
    progress, lane and obstacle distances, collisions) and ``"expert_action"`` (``expert=True``)
    are there where the server sends them.

    ## Rewards

    With ground truth (the embedded server) the default reward is
    :class:`~oasis_torchrl.rewards.GroundTruthReward`, per row and step:
    ``0.1 * progress_gained - 2 * collision - 0.01 * lane_offset`` (metres gained along the road,
    1 on the first collided step, mean metres from the lane's centre). On frames alone it is
    :class:`~oasis_torchrl.rewards.MotionReward`: ``0.1 * seen_progress - 2 * crash - 0.1 *
    swing``, the metres a network sees the car move in the chunk's front frames, a crash when
    the frames show one (which ends the episode), and the mean squared change of the actions.
    The reference's reward, :class:`~oasis_torchrl.rewards.DepthCollisionReward`, is there by
    name for comparison.
    ``reward=NoReward()`` scores nothing (0, never terminates).

    ## Starting state

    A reset of a row re-prompts its session with the row's next prompt and seed and sends one
    all-zero chunk: the first observation is the world after standing still for 4 frames.

    ## Episode end

    - Termination: a frame of the chunk collided (ground truth: an obstacle hit or the road
      left), or the reward module says so (the motion reward: a crash seen in the frames).
    - Truncation: ``max_steps`` steps (chunks; 512 by default), or the row's session was lost and
      re-opened mid-episode (counted in ``("info", "session_restarts")``).

    ## Version history

    - v0: the first version.

    Args:
        endpoint: ``"local"`` (the embedded simulator server, started on a free loopback port
            by the process that steps the env and stopped on close), or any A2V endpoint such
            as ``"https://oasis-grpc.decart.ai"`` or ``"http://127.0.0.1:50051"``.
        num_envs: rows of the batch, one session each.
        prompts: see :class:`OasisWrapper`.
        api_key: key for a remote endpoint (defaults to ``DECART_API_KEY``); ignored for local.
        tls: force TLS on or off (default: from the endpoint's scheme).
        server: embedded-server settings for ``endpoint="local"`` (resolution, latency, ...).
            Its ``processes`` (default: one per core) is capped at ``num_envs``;
            ``processes=0`` runs the server and the worlds inside the stepping process
            instead, which is slower but easier to debug.
        frame_size: ``(height, width)`` to resize frames to while decoding; default: the
            embedded server's size, or the hosted model's (another server's size: pass it here
            or as ``streams``).
        streams: the layout a remote server streams, when it is not the hosted model's.
        frame_format: how frames travel: ``"raw"`` (uncompressed RGB, for a server on this
            machine), ``"vp9"`` (what the hosted model sends: train on its compression
            artefacts) or ``"jpeg"``; default: raw on this machine, else VP9.
        all_frames: return all 4 frames of each chunk instead of the last one.
        ground_truth: see :class:`OasisWrapper`; default: for ``endpoint="local"`` unless its
            server is hosted-like (set it for an ``oasis-torchrl serve`` server started
            elsewhere, or let :func:`~oasis_torchrl.envs.make_env` find it).
        expert: run the embedded server's expert beside every episode and expose its next
            chunk as ``"expert_action"`` (what :class:`~oasis_torchrl.drivers.Autopilot` drives
            with, and demonstrations label with); off, the server spends nothing on it.
        front_crop: add a fourth camera, ``("pixels", "front_crop")``: the centre of the front
            camera, this fraction of its height and width, cut from the front frame decoded at
            the server's full size and resized to ``frame_size`` (a narrow forward camera; the
            detail it shows is what the server's size holds: the embedded server renders at
            least :func:`~oasis_torchrl.envs.embedded.render_size` for it, so a crop of
            ``frame_size`` pixels has detail).
        retry: transient-failure policy of the session pool.
        timeout: per-call deadline in seconds.
        **kwargs: the other :class:`OasisWrapper` arguments (``chunk_actions``, ``max_steps``,
            ``reward``, ``depth_cameras``, ``terminate_on_collision``, ``device``).

    Example:
        >>> from oasis_torchrl.envs import OasisEnv
        >>> from oasis_torchrl.sim.config import ServerConfig
        >>> env = OasisEnv("local", num_envs=2, prompts="urban street",
        ...                server=ServerConfig(width=96, height=64))
        >>> td = env.rollout(3)
        >>> td["next", "pixels", "front"].shape
        torch.Size([2, 3, 64, 96, 3])
        >>> env.action_spec.shape, env.action_spec.space.low.min().item()
        (torch.Size([2, 4, 2]), -1.0)
        >>> env.observation_spec["state"].shape, env.observation_spec["truth", "speed"].shape
        (torch.Size([2, 2]), torch.Size([2, 4]))
        >>> env.close()
    """

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
        streams: StreamLayout | None = None,
        frame_format: str | None = None,
        all_frames: bool = False,
        ground_truth: bool | None = None,
        expert: bool = False,
        front_crop: float | None = None,
        retry: RetryPolicy | None = None,
        timeout: float = 120.0,
        **kwargs: Any,
    ) -> None:
        if frame_format is not None and frame_format not in FORMAT_NAMES:
            raise ValueError(
                f"frame_format must be None or one of {sorted(FORMAT_NAMES)}, got {frame_format!r}"
            )
        self.endpoint = endpoint
        self.frame_format = frame_format
        local = endpoint == LOCAL
        if local:
            config = server if server is not None else ServerConfig()
            frame_size = frame_size or (config.height, config.width)
            height, width = render_size((config.height, config.width), frame_size, front_crop)
            config = replace(config, height=height, width=width)
            streams = StreamLayout(CAMERAS, frame_size)
            if expert and config.hosted:
                raise ValueError(
                    "the expert needs ground truth, which a hosted-like server does not send: "
                    "drive with a person, recordings or a policy"
                )
        formats = {} if frame_format is None else {"accepted_formats": [FORMAT_NAMES[frame_format]]}
        truth = (local and not config.hosted) if ground_truth is None else ground_truth
        reward = _resolve_reward(kwargs.pop("reward", None), truth)
        pool_frames = all_frames or getattr(reward, "reads_chunk_frames", False)
        pool = SessionPool(
            embedded_server(config, num_envs) if local else endpoint,
            num_envs,
            api_key=api_key,
            tls=tls,
            timeout=timeout,
            retry=retry,
            resize=frame_size,
            frames="all" if pool_frames else "last",
            expert=expert,
            front_crop=front_crop,
            **formats,
        )
        super().__init__(
            pool,
            streams=streams,
            prompts=prompts,
            reward=reward,
            ground_truth=truth,
            fps=config.fps if local else FPS,
            observe_all_frames=all_frames,
            **kwargs,
        )

    @property
    def is_local(self) -> bool:
        """Whether this env runs on its own embedded simulator server."""
        return self.endpoint == LOCAL

    @property
    def server(self) -> LocalServer | ServerProcess | None:
        """The embedded server of ``endpoint="local"`` (started with the env's sessions)."""
        return self._env.server


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
        return GroundTruthReward() if ground_truth else MotionReward()
    if hasattr(reward, "reset"):
        return reward
    return as_reward_module(reward)
