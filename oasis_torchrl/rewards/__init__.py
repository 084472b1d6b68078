"""Batched reward modules for the Oasis TorchRL env (pure torch / TensorDict).

>>> from oasis_torchrl.rewards import DepthCollisionReward, GroundTruthDepth
>>> reward = DepthCollisionReward(GroundTruthDepth("front"))
"""

from oasis_torchrl.rewards.base import (
    CallableReward,
    NoReward,
    RewardFn,
    RewardModule,
    RowState,
    as_reward_module,
    reward_output,
)
from oasis_torchrl.rewards.depth_collision import (
    DepthCollisionConfig,
    DepthCollisionReward,
    collision_risk,
    forward_reward,
    normalize_per_image,
    straightness_penalty,
)
from oasis_torchrl.rewards.depth_models import NamedDepth
from oasis_torchrl.rewards.depth_net import SMALL_DEPTH_MODEL
from oasis_torchrl.rewards.depth_sources import (
    DEFAULT_DEPTH_MODEL,
    CallableDepth,
    DepthPreprocess,
    DepthSource,
    GroundTruthDepth,
    MonocularDepth,
)
from oasis_torchrl.rewards.ground_truth import GroundTruthReward
from oasis_torchrl.rewards.motion import MotionReward, MotionRewardConfig
from oasis_torchrl.rewards.motion_net import SMALL_MOTION_MODEL, MotionModelError, load_motion_net
from oasis_torchrl.rewards.shaping import ClearanceShaping

__all__ = [
    "DEFAULT_DEPTH_MODEL",
    "SMALL_DEPTH_MODEL",
    "SMALL_MOTION_MODEL",
    "CallableDepth",
    "CallableReward",
    "ClearanceShaping",
    "DepthCollisionConfig",
    "DepthCollisionReward",
    "DepthPreprocess",
    "DepthSource",
    "GroundTruthDepth",
    "GroundTruthReward",
    "MonocularDepth",
    "MotionModelError",
    "MotionReward",
    "MotionRewardConfig",
    "NamedDepth",
    "NoReward",
    "RewardFn",
    "RewardModule",
    "RowState",
    "as_reward_module",
    "collision_risk",
    "forward_reward",
    "load_motion_net",
    "normalize_per_image",
    "reward_output",
    "straightness_penalty",
]
