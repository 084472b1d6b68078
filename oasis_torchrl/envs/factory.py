"""One env factory: the transformed :class:`~oasis_torchrl.envs.OasisEnv` of an ``env`` settings
section (:class:`~oasis_torchrl.config.EnvConfig`), shared by training, evaluation, recording
and Ray workers.

The env decodes frames straight to ``env.image_size`` (the policy's input size; ``null``: the
server's) and by default returns all 4 frames of each chunk as uint8 ``("pixels", <camera>)``
``[N, 4, H, W, 3]``, so recorded episodes get one row per frame (``all_frames=False``: the
chunk's last frame, which is all a policy reads). Every env also carries the policies' frame
stack, ``("frame_stack", <camera>)`` ``[N, frame_stack, H, W, 3]``: the last frame of each of
the last chunks (:class:`~oasis_torchrl.envs.transforms.ChunkFrameStack`); the policy modules
convert the frames they use (:mod:`oasis_torchrl.models.actor_critic`), so collector batches
stay compact uint8. A reward sum (``"episode_reward"``) and a step count are added, and on
request :class:`~oasis_torchrl.envs.transforms.PrivilegedState` (``"critic_inputs"``: ground
truth for an asymmetric critic).

What the endpoint sends beyond frames is found, not configured
(:mod:`~oasis_torchrl.envs.capabilities`): ground truth reaches the env where the endpoint sends
it, and ``env.reward.kind: auto`` follows it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from omegaconf import DictConfig
from torchrl.envs import Compose, RewardSum, StepCounter, TransformedEnv

from oasis_torchrl.config.env import REWARD_KINDS, EnvConfig, RewardConfig
from oasis_torchrl.envs.capabilities import Capabilities, env_capabilities, resolve_reward_kind
from oasis_torchrl.envs.episodes import Prompts, episode_prompts
from oasis_torchrl.envs.oasis_env import OasisEnv
from oasis_torchrl.envs.transforms import ChunkFrameStack, PrivilegedState
from oasis_torchrl.models.config import POLICY_FRAMES
from oasis_torchrl.rewards import (
    ClearanceShaping,
    DepthCollisionReward,
    GroundTruthReward,
    MotionReward,
    MotionRewardConfig,
    NamedDepth,
    RewardModule,
    load_motion_net,
)
from oasis_torchrl.sim.config import ServerConfig

Settings = EnvConfig | DictConfig


def make_reward(cfg: RewardConfig | DictConfig, capabilities: Capabilities) -> RewardModule:
    """The reward module of ``env.reward`` on an endpoint that sends what ``capabilities`` says
    (``kind: auto`` is the ground-truth reward where it sends ground truth, else the motion
    reward on the frames).

    Example:
        >>> embedded = Capabilities("the embedded server", ground_truth=True)
        >>> type(make_reward(RewardConfig(), embedded)).__name__
        'GroundTruthReward'
        >>> type(make_reward(RewardConfig(clearance_weight=0.2), embedded)).__name__
        'ClearanceShaping'
        >>> type(make_reward(RewardConfig(), Capabilities("hosted", ground_truth=False))).__name__
        'MotionReward'
    """
    if cfg.kind not in REWARD_KINDS:
        raise ValueError(f"env.reward.kind must be one of {REWARD_KINDS}, got {cfg.kind!r}")
    kind = resolve_reward_kind(cfg.kind, capabilities)
    if kind != "ground_truth":
        return make_frames_reward(cfg, kind)
    reward = GroundTruthReward(
        progress_scale=cfg.progress_scale,
        collision_penalty=cfg.collision_penalty,
        lane_penalty=cfg.lane_penalty,
    )
    if not cfg.clearance_weight:
        return reward
    return ClearanceShaping(reward, cfg.clearance_weight, cfg.clearance_horizon)


def make_frames_reward(cfg: RewardConfig | DictConfig, kind: str = "motion") -> RewardModule:
    """The frames-only reward ``kind`` names (``motion`` or the reference's ``depth``), with the
    settings of ``env.reward``: what an endpoint without ground truth is scored with, and what
    an evaluation scores beside the ground truth.

    Example:
        >>> type(make_frames_reward(RewardConfig(), "depth")).__name__
        'DepthCollisionReward'
    """
    if kind == "depth":
        return DepthCollisionReward(NamedDepth(cfg.depth_model))
    if kind != "motion":
        raise ValueError(f"{kind!r} is not a frames-only reward: motion or depth")
    constants = MotionRewardConfig(
        progress_scale=cfg.progress_scale,
        collision_penalty=cfg.collision_penalty,
        swing_weight=cfg.swing_weight,
    )
    return MotionReward(load_motion_net(cfg.motion_model), constants)


def env_front_crop(cfg: Settings, required: float | None) -> float | None:
    """The front crop of the env: ``required`` (a policy's), else ``env.front_crop``.

    Example:
        >>> env_front_crop(EnvConfig(), 0.25), env_front_crop(EnvConfig(front_crop=0.5), None)
        (0.25, 0.5)
        >>> env_front_crop(EnvConfig(front_crop=0.5), 0.25)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: the policy reads a front crop of 0.25 ..., env.front_crop is 0.5: set ...
    """
    configured = cfg.front_crop
    if required is None or configured is None or float(configured) == float(required):
        return required if required is not None else configured
    raise ValueError(
        f"the policy reads a front crop of {required} of the front frame, env.front_crop is "
        f"{configured}: set env.front_crop={required} or null"
    )


def make_env(
    cfg: Settings,
    *,
    num_envs: int | None = None,
    prompts: Prompts | None = None,
    max_steps: int | None = None,
    image_size: Sequence[int] | None = None,
    all_frames: bool = True,
    frame_stack: int | None = POLICY_FRAMES,
    privileged: bool = False,
    front_crop: float | None = None,
    reward: RewardModule | None = None,
    **env_kwargs: Any,
) -> TransformedEnv:
    """The :class:`~oasis_torchrl.envs.OasisEnv` of an ``env`` settings section, transformed.

    Args:
        cfg: the ``env`` section.
        num_envs: replaces the section's value (evaluation uses one row per episode).
        prompts: replaces the section's value (evaluation fixes the prompt of each row).
        max_steps: replaces the section's value.
        image_size: replaces the section's value (evaluation uses the policy's image size).
        all_frames: all 4 frames of each chunk (one dataset row per frame), or the last.
        frame_stack: depth of the policies' frame stack (the network's ``frames``); None:
            no stack (append a :class:`ChunkFrameStack` later, e.g. once the network is known).
        privileged: add :class:`~oasis_torchrl.envs.transforms.PrivilegedState` (needs ground
            truth: an error on an endpoint that sends frames only).
        front_crop: the front crop a policy reads (its fraction): the env gets it whatever
            ``env.front_crop`` says (another fraction there is an error); None: the section's.
        reward: the reward module; None: ``env.reward``'s (:func:`make_reward`).
        **env_kwargs: further :class:`~oasis_torchrl.envs.OasisEnv` arguments.

    Example:
        >>> env = make_env(EnvConfig(num_envs=2, max_steps=3))
        >>> td = env.rollout(3)
        >>> env.close()
        >>> td["next", "pixels", "front"].shape, td["next", "step_count"][0, -1].item()
        (torch.Size([2, 3, 4, 64, 96, 3]), 3)
        >>> td["next", "frame_stack", "front"].shape
        torch.Size([2, 3, 2, 64, 96, 3])
    """
    capabilities = env_capabilities(cfg)
    if privileged:
        capabilities.require(
            "privileged state (privileged_critic, loss.aux_coeff)",
            "leave privileged_critic and loss.aux_coeff unset (found from the endpoint) or set "
            "privileged_critic=false loss.aux_coeff=0",
        )
    if env_kwargs.get("expert"):
        capabilities.require(
            "the expert (the autopilot and its labels)",
            "take demonstrations from a person, a recordings folder or a policy",
        )
    size = image_size if image_size is not None else cfg.image_size
    frame_size = None if size is None else (int(size[0]), int(size[1]))
    crop = env_front_crop(cfg, front_crop)
    server = cfg.server
    env_kwargs.setdefault("ground_truth", capabilities.ground_truth)
    env = OasisEnv(
        cfg.endpoint,
        num_envs or cfg.num_envs,
        prompts if prompts is not None else episode_prompts(cfg.prompts),
        server=ServerConfig(
            width=server.width, height=server.height, fps=float(server.fps), hosted=server.hosted
        ),
        frame_size=frame_size,
        front_crop=crop,
        all_frames=all_frames,
        max_steps=max_steps or cfg.max_steps,
        reward=make_reward(cfg.reward, capabilities) if reward is None else reward,
        **env_kwargs,
    )
    transforms = [RewardSum(), StepCounter()]
    if frame_stack is not None:
        transforms.insert(0, ChunkFrameStack(env.layout.cameras, depth=frame_stack))
    if privileged:
        transforms.append(PrivilegedState())
    return TransformedEnv(env, Compose(*transforms))
