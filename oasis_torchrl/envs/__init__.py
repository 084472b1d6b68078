"""TorchRL and Gymnasium environments over Oasis world-model sessions."""

from oasis_torchrl.envs.episodes import EpisodePlanner
from oasis_torchrl.envs.factory import make_env, make_reward
from oasis_torchrl.envs.gym_adapter import OasisGymEnv
from oasis_torchrl.envs.gym_vector import OasisVectorEnv
from oasis_torchrl.envs.oasis_env import OasisEnv, OasisWrapper, StreamLayout
from oasis_torchrl.envs.transforms import PRIVILEGED_FIELDS, ChunkFrameStack, PrivilegedState

__all__ = [
    "PRIVILEGED_FIELDS",
    "ChunkFrameStack",
    "EpisodePlanner",
    "OasisEnv",
    "OasisGymEnv",
    "OasisVectorEnv",
    "OasisWrapper",
    "PrivilegedState",
    "StreamLayout",
    "make_env",
    "make_reward",
]
