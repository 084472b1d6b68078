"""The training env of a config's ``env`` section (shared by PPO, evaluation and the pipeline).

The env returns all 4 frames of each chunk (``all_frames=True``), decoded straight to the policy
size and kept as uint8 ``("pixels", <camera>)`` ``[N, 4, H, W, 3]``: the policy modules convert
the frames they use (:mod:`oasis_torchrl.models.actor_critic`), so collector batches stay
compact, and evaluation episodes recorded to LeRobot get one row per frame, as BC data does.
A reward sum (``"episode_reward"``) and a step count are added, and on request
:class:`PrivilegedState` (``"critic_inputs"``: ground truth for an asymmetric critic).

``env`` keys: ``endpoint`` (``local`` or an A2V URL), ``prompts`` (a list; one prompt is used
for every episode, several are drawn from per episode), ``num_envs``, ``max_steps`` (chunks per
episode), ``image_size`` ``[height, width]`` of the policy images, ``server`` (``width``,
``height`` of the embedded server's frames) and ``reward`` (``kind: ground_truth`` with
``progress_scale``, ``collision_penalty``, ``lane_penalty`` and the optional
:class:`~oasis_torchrl.train.shaping.ClearanceShaping` ``clearance_weight`` (0: off) and
``clearance_horizon``; or ``kind: depth``, the reference SDK's depth-collision reward, for remote
endpoints).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from omegaconf import DictConfig
from tensordict import TensorDictBase
from torchrl.data import Composite, Unbounded
from torchrl.envs import Compose, RewardSum, StepCounter, Transform, TransformedEnv

from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.envs.episodes import Prompts, episode_prompts
from oasis_torchrl.envs.oasis_env import LOCAL
from oasis_torchrl.models.actor_critic import CRITIC_INPUTS
from oasis_torchrl.rewards import DepthCollisionReward, GroundTruthReward, RewardModule
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.train.shaping import ClearanceShaping

REWARD_KINDS = ("ground_truth", "depth")
PRIVILEGED_FIELDS = (
    "speed",
    "lateral_offset",
    "heading_error",
    "obstacle_distance",
    "obstacle_distance_left",
    "obstacle_distance_right",
)
_PRIVILEGED_SCALE = torch.tensor([10.0, 4.0, 1.0, 60.0, 60.0, 60.0])
"""Rough magnitudes: m/s, m, rad, then metres (the obstacle distances are capped at 60 m, as
where no obstacle is: the critic and the auxiliary head need to know which lane is open)."""
_FIRST_DISTANCE = PRIVILEGED_FIELDS.index("obstacle_distance")


class PrivilegedState(Transform):
    """Writes ``"critic_inputs"`` ``[N, 6]``: the last frame's ground truth in
    :data:`PRIVILEGED_FIELDS` (speed, lateral offset, heading error, obstacle distances ahead,
    one lane left and one lane right), scaled to about unit size.

    For an asymmetric actor-critic on the embedded server: the critic may use the simulator's
    state, the actor (what is deployed) only sees the cameras and the previous action.

    Example:
        >>> from tensordict import TensorDict
        >>> truth = {field: torch.full((2, 4), 2.0) for field in PRIVILEGED_FIELDS}
        >>> truth["obstacle_distance_right"][0] = float("inf")
        >>> out = PrivilegedState()(TensorDict({"truth": truth}, [2]))
        >>> out["critic_inputs"][:, -1].tolist()
        [1.0, 0.03333333507180214]
    """

    def __init__(self) -> None:
        in_keys = [("truth", field) for field in PRIVILEGED_FIELDS]
        super().__init__(in_keys=in_keys, out_keys=[CRITIC_INPUTS])

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        last = torch.stack([next_tensordict.get(key)[..., -1] for key in self.in_keys], dim=-1)
        distances = last[..., _FIRST_DISTANCE:]
        distances.copy_(distances.nan_to_num(posinf=60.0).clamp(max=60.0))
        scale = _PRIVILEGED_SCALE.to(last.device)
        return next_tensordict.set(CRITIC_INPUTS, (last / scale).nan_to_num(0.0))

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Add ``"critic_inputs"`` to a TensorDict outside an env (e.g. a stored batch)."""
        return self._call(tensordict)

    def _reset(
        self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase
    ) -> TensorDictBase:
        return self._call(tensordict_reset)

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        shape = (*observation_spec.shape, len(PRIVILEGED_FIELDS))
        observation_spec[CRITIC_INPUTS] = Unbounded(shape, device=observation_spec.device)
        return observation_spec


def make_reward(cfg: DictConfig) -> RewardModule:
    """The reward module of ``env.reward``.

    Example:
        >>> from omegaconf import OmegaConf
        >>> cfg = OmegaConf.create({"kind": "ground_truth", "progress_scale": 0.1,
        ...     "collision_penalty": 10.0, "lane_penalty": 0.01, "clearance_weight": 0.0})
        >>> type(make_reward(cfg)).__name__
        'GroundTruthReward'
    """
    kind = cfg.kind
    if kind == "ground_truth":
        reward = GroundTruthReward(
            progress_scale=cfg.progress_scale,
            collision_penalty=cfg.collision_penalty,
            lane_penalty=cfg.lane_penalty,
        )
        if not cfg.get("clearance_weight"):
            return reward
        return ClearanceShaping(reward, cfg.clearance_weight, cfg.get("clearance_horizon", 25.0))
    if kind == "depth":
        return DepthCollisionReward()
    raise ValueError(f"env.reward.kind must be one of {REWARD_KINDS}, got {kind!r}")


def build_env(
    cfg: DictConfig,
    *,
    num_envs: int | None = None,
    prompts: Prompts | None = None,
    max_steps: int | None = None,
    image_size: Sequence[int] | None = None,
    privileged: bool = False,
    **env_kwargs: Any,
) -> TransformedEnv:
    """The :class:`~oasis_torchrl.envs.OasisEnv` of an ``env`` config section, transformed.

    Args:
        cfg: the ``env`` section.
        num_envs, prompts, max_steps, image_size: replace the section's values (evaluation
            uses one row per episode, fixed per-row prompts and the policy's image size).
        privileged: add :class:`PrivilegedState` (needs ground truth: the embedded server).
        **env_kwargs: further :class:`~oasis_torchrl.envs.OasisEnv` arguments.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> env = build_env(load_config("ppo").env, num_envs=1)
        >>> env.batch_size
        torch.Size([1])
        >>> env.close()
    """
    if privileged and not env_kwargs.get("ground_truth", cfg.endpoint == LOCAL):
        raise ValueError(
            "privileged state (privileged_critic, loss.aux_coeff) needs ground truth, which "
            "only the embedded server sends (endpoint 'local', or its address with "
            f"ground_truth=True); got endpoint {cfg.endpoint!r}: set privileged_critic=false "
            "loss.aux_coeff=0"
        )
    height, width = image_size if image_size is not None else cfg.image_size
    env = OasisEnv(
        cfg.endpoint,
        num_envs or cfg.num_envs,
        prompts if prompts is not None else episode_prompts(cfg.prompts),
        server=ServerConfig(width=cfg.server.width, height=cfg.server.height),
        frame_size=(int(height), int(width)),
        all_frames=True,
        max_steps=max_steps or cfg.max_steps,
        reward=make_reward(cfg.reward),
        **env_kwargs,
    )
    transforms = [RewardSum(), StepCounter()]
    if privileged:
        transforms.append(PrivilegedState())
    return TransformedEnv(env, Compose(*transforms))
